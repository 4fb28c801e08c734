"""Lighting/albedo calibration (Eq. 14) benchmark: seconds, iterations and recovery error.

    python bench/calibrate.py [--sizes 360x270 720x540] [--lams 2500]

A synthetic neutral plate of the built-in head (``render.synthetic``: studio light, skin
albedo with lips, brows and mottling, pose rotated 0.12 rad, noise 0.005) is calibrated from
the default start. Errors against the truth, on the vertices the plate sees: the irradiance
(what the plate determines of gamma), the SH coefficients, and the albedo, in the gauge that
best aligns the irradiance (per channel, least squares: only the product of albedo and light
is observed, so the solver's own gauge choice does not enter the errors).
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import invface
from invface.fit.calibrate import calibrate
from invface.model.rig import euler_xyz
from invface.render.camera import Camera
from invface.render.renderer import FaceRenderer
from invface.render.shading import irradiance, vertex_normals
from invface.render.synthetic import render_plate, skin_albedo, studio_light


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", nargs="+", default=["360x270", "720x540"])
    ap.add_argument("--lams", nargs="+", type=float, default=[2500.0])
    a = ap.parse_args()
    model = invface.template.build()
    V, F = model.neutral, model.triangles
    rot, tr = np.array([0.03, -0.12, 0.0]), np.zeros(3)
    gamma, albedo = studio_light(), skin_albedo(model)
    print(f"head: {len(V)} vertices")
    print(f"{'size':>8} {'lambda':>7} {'its':>4} {'seconds':>8} {'irradiance':>10} {'SH coeffs':>9} {'albedo':>7}")
    for sz in a.sizes:
        w, h = (int(v) for v in sz.split("x"))
        cam = Camera.front_view(w, h)
        plate, mask = render_plate(model, V, cam, gamma, albedo, rot, tr)
        _, W = FaceRenderer(F, cam).coverage(V, rot, tr)
        seen = np.asarray(W.sum(0)).ravel() > 1e-3
        for lam in a.lams:
            t0 = time.perf_counter()
            cal = calibrate(F, V, plate, cam, rot, tr, lam=lam)
            sec = time.perf_counter() - t0
            n = vertex_normals(V @ euler_xyz(rot).T + tr, F)[seen]
            E0, Ef = irradiance(n, gamma), irradiance(n, cal.gamma)
            k = np.sum(E0 * E0, 0) / np.sum(E0 * Ef, 0)       # the gauge that best aligns the irradiance
            g_true, a_true = gamma / k, albedo / k
            E = E0 / k
            e_irr = np.sqrt(np.mean((E - Ef) ** 2) / np.mean(E ** 2))
            e_g = np.linalg.norm(cal.gamma - g_true) / np.linalg.norm(g_true)
            e_a = np.sqrt(np.mean((cal.albedo[seen] - a_true[seen]) ** 2) / np.mean(a_true[seen] ** 2))
            print(f"{sz:>8} {lam:7.0f} {len(cal.history):4d} {sec:8.2f} {100 * e_irr:9.2f}% "
                  f"{100 * e_g:8.2f}% {100 * e_a:6.2f}%", flush=True)


if __name__ == "__main__":
    main()
