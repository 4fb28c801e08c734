"""The smooth skin embedding of a morphed actor: its size and what it costs.

    python bench/embedding.py [--resolution 0.3]

Builds an actor from the ICT-FaceKit neutral (../shared/data/ict-facekit; without it the
script says so and stops) and prints, for the barycentric and the moving-least-squares
embedding (with and without the nodal correction): weights per skin vertex, seconds to make
it (as on every load of a bundle), and seconds for the surface Jacobian's product W dX/dp
(P parameters), as P separate products and as one; for scale, one simulation solve and its
tangent solves.
"""
from __future__ import annotations

import argparse

import numpy as np
from _common import SHARED, timed

import invface
from invface.mesh.embedding import MLS, barycentric_matrix, moving_least_squares
from invface.morph.build import build_model
from invface.sim.driven import DrivenSimulation

ICT = SHARED / "ict-facekit"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolution", type=float, default=0.3, help="template size factor")
    a = ap.parse_args()
    if not (ICT / "neutral.obj").exists():
        raise SystemExit(f"{ICT}: ICT-FaceKit data not found")
    tpl = invface.template.build(resolution=a.resolution)
    model, _ = build_model(ICT / "neutral.obj", template=tpl, expressions="copy")
    X0, T, V = model.rest_positions, model.tets, len(model.neutral)
    args = (X0, T, model.neutral, model.embed_tets, model.embed_weights, MLS["rings"], MLS["radius"])
    ds = DrivenSimulation(model)
    p = model.parameters({"weights": {"mouthSmileLeft": 0.6, "jawOpen": 0.5},
                          "jaw": np.array(model.meta["blendshape_jaw"]["jawOpen"]) * 0.5})
    _, solve = timed(lambda: ds.solve(p, warm=None))
    dX, tangent = timed(lambda: ds.sensitivity(p).tangent())
    P, N = dX.shape[:2]
    print(f"actor at resolution {a.resolution:g}: {V} skin vertices, {N} tet vertices, {len(T)} tets; "
          f"P = {P} parameters; one solve {solve:.2f} s, its tangent solves {tangent:.2f} s")
    for name, make in (("barycentric", lambda: barycentric_matrix(T, model.embed_tets, model.embed_weights, len(X0))),
                       ("MLS", lambda: moving_least_squares(*args, correct=False)),
                       ("MLS + nodal correction", lambda: moving_least_squares(*args, correct=True))):
        W, made = timed(make)
        _, each = timed(lambda: np.stack([W @ d for d in dX]), repeat=5)
        _, once = timed(lambda: W @ dX.transpose(1, 0, 2).reshape(N, 3 * P), repeat=5)
        print(f"{name:24s} {W.nnz / V:6.1f} weights per skin vertex, made in {made:.2f} s; "
              f"W dX/dp: {each:.3f} s as {P} products, {once:.3f} s as one")


if __name__ == "__main__":
    main()
