"""Soft-tissue depths of the built-in head against the forensic table it follows.

    python bench/tissue_depth.py [--resolution 1]

For every site of ``template.shape.DEPTH_SITES`` (Rhine & Moore 1984, normal-build adult
White males, plus the model's own interpolation sites): the skin point, the table's depth,
the model's skin-to-bone distance (to the skull and mandible, or to the teeth where they are
nearer: the lips' sites measure to the incisors) and the relative error; then the depth of
the simulated flesh (the ray from the skin to the tet mesh's inner layer) at the same sites.
"""
from __future__ import annotations

import argparse

import numpy as np

import invface
from invface.template.shape import DEPTH_SITES, depth_site_points
from invface.template.skull import tissue_depths


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--resolution", type=float, default=1.0)
    args = ap.parse_args()
    m = invface.template.build(resolution=args.resolution, expressions=False)
    bone = [m.cranium_mesh, m.jaw_mesh, m.parts.mesh("upper_teeth"), m.parts.mesh("lower_teeth")]
    pts = depth_site_points()
    names = list(DEPTH_SITES)
    P = np.array([pts[n] for n in names])
    d = tissue_depths(P, bone)
    # the flesh's own depth: the skin point's nearest inner-layer vertex along the same ray
    X = m.rest_positions
    n_layers = int(m.meta["layers"])
    Ns = len(X) // (n_layers + 1)
    inner = X[n_layers * Ns:]
    skin = X[:Ns]
    k = np.argmin(np.linalg.norm(skin[None] - P[:, None], axis=2), axis=1)
    flesh = np.linalg.norm(skin[k] - inner[k], axis=1)
    print(f"{'site':18s} {'skin point (mm)':>24s} {'table':>6s} {'skull':>6s} {'error':>6s} {'flesh':>6s}")
    for n, p, dd, ff in zip(names, P, d, flesh):
        t = DEPTH_SITES[n][3]
        mark = "" if DEPTH_SITES[n][4] else "  (not in the table)"
        at = "(" + ", ".join(f"{v:.1f}" for v in p * 1000 + 0.0) + ")"
        print(f"{n:18s} {at:>24s} {t * 1000:6.2f} "
              f"{dd * 1000:6.2f} {dd / t - 1:+6.0%} {ff * 1000:6.2f}{mark}")


if __name__ == "__main__":
    main()
