"""Eq. 14 with a hand over the mouth (issue 61 item 3): a rendered neutral plate with a
skin-toned striped occluder over the mouth, calibrated plainly and with ``robust`` reweighted
solves (``fit.calibrate.robust_weights``, ``calibrate --robust``); the mean albedo error of the
front vertices under the occluder and over the face, against the true albedo.

    python bench/occluded_albedo.py [--resolution 0.3] [--json bench/figures/occluded_albedo.json]
"""
import argparse
import time
from pathlib import Path

import numpy as np

import invface
from invface.fit.calibrate import ROBUST_ROUNDS, calibrate
from invface.fit.curves import curve_points, projection_jacobian
from invface.render import shading
from invface.render.camera import Camera
from invface.render.synthetic import render_plate, skin_albedo, studio_light

from _common import write_json


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolution", type=float, default=0.3)
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    m = invface.template.build(resolution=a.resolution)
    cam = Camera.front_view(320, 240)
    g, albedo = studio_light(), skin_albedo(m)
    clean, _ = render_plate(m, m.neutral, cam, g, albedo, spp=16)
    lips = np.concatenate([projection_jacobian(cam, curve_points(m, n, m.neutral))[0]
                           for n in ("lip_outer_upper", "lip_outer_lower")])
    lo, hi = lips.min(0) - [12, 10], lips.max(0) + [12, 14]
    yy, xx = np.mgrid[:240, :320]
    box = (xx >= lo[0]) & (xx <= hi[0]) & (yy >= lo[1]) & (yy <= hi[1])
    stripes = np.sin(xx / 3.0)
    hand = np.stack([0.42 + 0.08 * stripes, 0.28 + 0.05 * stripes, 0.22 + 0.04 * stripes], -1)
    occluded = clean.copy()
    occluded[box] = hand[box]
    uv = cam.project(m.neutral)[0]
    front = shading.vertex_normals(m.neutral, m.triangles)[:, 2] > 0.3
    under = front & (uv[:, 0] >= lo[0]) & (uv[:, 0] <= hi[0]) & (uv[:, 1] >= lo[1]) & (uv[:, 1] <= hi[1])
    rows = []
    for name, image in (("clean", clean), ("occluded", occluded)):
        for robust in (0, ROBUST_ROUNDS):
            t = time.perf_counter()
            cal = calibrate(m.triangles, m.neutral, image, cam, lam=2500.0, robust=robust, parts=m.parts)
            err = np.abs(cal.albedo - albedo)
            rows.append({"plate": name, "robust": robust, "under_occluder": float(err[under].mean()),
                         "face": float(err[front].mean()), "seconds": time.perf_counter() - t})
            print(f"{name:8s} robust {robust}: albedo error under the occluder {rows[-1]['under_occluder']:.4f}, "
                  f"over the face {rows[-1]['face']:.4f}, {rows[-1]['seconds']:.1f} s", flush=True)
    write_json(a.json, {"resolution": a.resolution, "occluder_px": int(box.sum()), "vertices_under": int(under.sum()),
                        "solves": rows})


if __name__ == "__main__":
    main()
