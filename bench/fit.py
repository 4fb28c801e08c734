"""Fitting benchmark: seconds per 3D scan fit (Eq. 13) for both model kinds.

    python bench/fit.py [--resolution 1]

A synthetic scan is made by the model itself (random controls, 30 % of the weights active,
jaw 0.08 rad, rotation ~0.1 rad, a few mm of translation) and fitted from the neutral start
with lambda = 1e-8 (noise-free scan) and the paper's 1e-6. Prints seconds, dogleg
iterations, the largest control error and the surface error.
(Plate fitting, Eq. 15-16, is issue 6's remaining work.)
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import invface
from invface.fit.scan import fit_scan
from invface.model.rig import euler_xyz


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolution", type=float, default=1.0)
    a = ap.parse_args()
    model = invface.template.build(resolution=a.resolution)
    K = len(model.blendshape_names)
    rng = np.random.default_rng(0)
    p = np.r_[np.where(rng.random(K) < 0.3, rng.uniform(0.2, 0.8, K), 0), [0.08, 0, 0, 0, 0, 0]]
    rot, tr = np.array([0.05, -0.1, 0.02]), np.array([0.003, -0.002, 0.005])
    print(f"head: {len(model.neutral)} vertices, {len(model.tets)} tets, K = {K}")
    print(f"{'model':>11} {'lambda':>7} {'seconds':>8} {'its':>4} {'max |dp|':>9} {'max err mm':>10}")
    for kind in ("blendshape", "simulation"):
        scan = model.surface_model(kind).surface(p) @ euler_xyz(rot).T + tr
        for lam in (1e-8, 1e-6):
            model._surface_models.clear()          # cold: no warm start from the scan's solve
            t0 = time.perf_counter()
            fit = fit_scan(model, scan, kind=kind, lam=lam)
            sec = time.perf_counter() - t0
            print(f"{kind:>11} {lam:7.0e} {sec:8.2f} {len(fit.history):4d} {np.abs(fit.p - p).max():9.2e} "
                  f"{fit.error.max() * 1000:10.4f}", flush=True)
    # path dependence: the true controls solved warm (from the last fit's state) vs cold
    warm = model.surface_model("simulation").surface(p)
    cold = (scan - tr) @ euler_xyz(rot)
    d = np.linalg.norm(warm - cold, axis=1) * 1000
    print(f"simulation at the true controls, warm vs cold start: max {d.max():.3f} mm "
          f"(vertex {int(d.argmax())}), median {np.median(d):.4f} mm")


if __name__ == "__main__":
    main()
