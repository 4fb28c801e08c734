"""How closely the blendshape-driven tracks (paper 000 Eq. 10-11) and the simulation follow the
rig at the lips.

    python bench/tracks.py [--resolution 1 | --model FILE.npz] [--shapes mouthLowerDownLeft,mouthRollLower]

For each shape at weight 1, per lip curve: the mean distance (mm) between the rig's displacement
of the curve's vertices and the Poisson field's (``track_displacements`` carried to the skin by
the model's embedding), against the rig's mean motion there; then the simulation's surface
against the rig's at the same weight (cold solve), per lip curve and over the face, with the
solve's seconds.
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import invface

SHAPES = "mouthLowerDownLeft,mouthRollLower,mouthUpperUpLeft,jawOpen,mouthPucker,mouthSmileLeft"
CURVES = ("lip_inner_lower", "lip_inner_upper", "lip_outer_lower", "lip_outer_upper")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolution", type=float, default=1.0)
    ap.add_argument("--model", help="a FaceModel bundle instead of the template at --resolution")
    ap.add_argument("--shapes", default=SHAPES)
    a = ap.parse_args()
    m = invface.FaceModel.load(a.model) if a.model else invface.template.build(resolution=a.resolution)
    E = m.embedding_matrix()
    sim = m.surface_model("simulation")
    print(f"{len(m.tets)} tets; mm, mean over each curve's vertices: field (or simulation) off the rig / the rig's motion")
    print(f"{'shape':>16} {'':>10} " + " ".join(f"{c:>18}" for c in CURVES) + f" {'face':>7} {'seconds':>7}")
    for name in a.shapes.split(","):
        k = m.blendshape_names.index(name)
        rig = m.blendshapes[k]
        field = E @ m.track_displacements[k]
        p = np.zeros(len(m.blendshape_names) + 6)
        p[k] = 1.0
        t = time.perf_counter()
        x_sim = sim.surface_of(sim.solve(p, warm=None)) - m.neutral
        seconds = time.perf_counter() - t
        x_rig = m.surface_model("blendshape").surface(p) - m.neutral
        for label, d, r in (("field", field, rig), ("simulation", x_sim, x_rig)):
            cells = []
            for c in CURVES:
                i = np.asarray(m.curves[c])
                cells.append(f"{1e3 * np.linalg.norm(d[i] - r[i], axis=1).mean():7.2f} / {1e3 * np.linalg.norm(r[i], axis=1).mean():5.2f}")
            face = 1e3 * np.linalg.norm(d - r, axis=1).mean()
            tail = f" {seconds:7.1f}" if label == "simulation" else ""
            print(f"{name if label == 'field' else '':>16} {label:>10} " + " ".join(f"{c:>18}" for c in cells) + f" {face:7.3f}{tail}", flush=True)


if __name__ == "__main__":
    main()
