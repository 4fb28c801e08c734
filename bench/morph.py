"""Model-builder benchmark (paper 001): seconds per stage of build_model for a ~50k-vertex
target (the default template skin, subdivided once, deformed into a new identity, randomly
rotated and written in millimetres), with the template's expressions re-simulated on the
new anatomy.

    python bench/morph.py [--expressions simulate|copy] [--seed 1]
"""
from __future__ import annotations

import argparse
import json
import time

import trimesh

import invface
from invface.morph.build import build_model
from invface.morph.synthetic import random_identity, random_pose


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--expressions", default="simulate", choices=["simulate", "copy", "none"])
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    tpl = invface.template.build()
    V, F = trimesh.remesh.subdivide(tpl.neutral, tpl.triangles)
    X = random_identity(V, args.seed)
    Y, R, t = random_pose(X, args.seed)
    print(f"target: {len(Y)} vertices, {len(F)} triangles (mm, random pose)")
    t0 = time.perf_counter()
    model, res = build_model((Y, F), template=tpl, expressions=args.expressions)
    total = time.perf_counter() - t0
    for k, v in res.seconds.items():
        print(f"  {k:12s} {v:7.1f} s")
    print(f"  {'total':12s} {total:7.1f} s")
    st = res.stats
    print(json.dumps({"alignment_residual_mm": round(st["alignment_residual_mm"], 3),
                      "skin_to_target_mean_mm": round(st["surface_to_target_mm"]["mean"], 4),
                      "inverted_tets": st["quality"]["inverted"],
                      "min_radius_ratio": round(st["quality"]["min_radius_ratio"], 4),
                      "target_vertices": len(Y)}))


if __name__ == "__main__":
    main()
