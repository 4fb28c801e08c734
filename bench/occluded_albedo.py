"""Eq. 14 with a hand over the mouth (issue 61 item 3): a rendered neutral plate with a
skin-toned striped occluder over the mouth, calibrated plainly and with ``robust`` reweighted
solves (``fit.calibrate.robust_weights``, ``calibrate --robust``); the mean albedo error of the
front vertices under the occluder and over the face, against the true albedo.

    python bench/occluded_albedo.py [--resolution 0.3] [--json bench/figures/occluded_albedo.json]
"""
import argparse
import time

import numpy as np

import invface
from invface.fit.calibrate import ROBUST_ROUNDS, calibrate
from invface.fit.samples import occluded_mouth_plate

from _common import add_json_option, write_json


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolution", type=float, default=0.3)
    add_json_option(ap)
    a = ap.parse_args()
    m = invface.template.build(resolution=a.resolution)
    o = occluded_mouth_plate(m)
    cam, albedo, under, front = o["camera"], o["albedo"], o["under"], o["front"]
    rows = []
    for name in ("clean", "occluded"):
        for robust in (0, ROBUST_ROUNDS):
            t = time.perf_counter()
            cal = calibrate(m.triangles, m.neutral, o[name], cam, lam=2500.0, robust=robust, parts=m.parts)
            err = np.abs(cal.albedo - albedo)
            rows.append({"plate": name, "robust": robust, "under_occluder": float(err[under].mean()),
                         "face": float(err[front].mean()), "seconds": time.perf_counter() - t})
            print(f"{name:8s} robust {robust}: albedo error under the occluder {rows[-1]['under_occluder']:.4f}, "
                  f"over the face {rows[-1]['face']:.4f}, {rows[-1]['seconds']:.1f} s", flush=True)
    write_json(a.json, {"resolution": a.resolution, "occluder_px": int(o["box"].sum()), "vertices_under": int(under.sum()),
                        "solves": rows})


if __name__ == "__main__":
    main()
