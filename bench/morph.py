"""Model-builder benchmark (paper 001): seconds per stage of build_model for a ~50k-vertex
target (the default template skin, subdivided once, deformed into a new identity, randomly
rotated and written in millimetres), with the template's expressions re-simulated on the
new anatomy. Also prints the round-trip accuracy: landmark errors against the template's
landmarks carried by the known deformation, and the vertex correspondence error.

    python bench/morph.py [--expressions simulate|copy|none] [--seed 1] [--resolution 1.0]
    python bench/morph.py --scan ../shared/data/ict-facekit/neutral.obj --expressions none

With --scan, a real neutral scan is built instead (no ground truth: stage seconds, the
landmarks and the mesh quality are printed).
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np
import trimesh

import invface
from invface.mesh.closest import closest_points
from invface.morph.build import build_model
from invface.morph.landmarks import template_landmarks
from invface.morph.synthetic import random_identity, random_pose


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--expressions", default="simulate", choices=["simulate", "copy", "none"])
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--resolution", type=float, default=1.0, help="template size factor")
    ap.add_argument("--scan", help="a real neutral scan (OBJ/PLY) instead of the synthetic target")
    args = ap.parse_args()
    tpl = invface.template.build(resolution=args.resolution)
    if args.scan:
        t0 = time.perf_counter()
        model, res = build_model(args.scan, template=tpl, expressions=args.expressions)
        _print_stages(res, time.perf_counter() - t0)
        print("landmarks (mm, model frame): " + ", ".join(
            f"{k} ({', '.join(f'{c * 1000:.1f}' for c in p)})" for k, p in res.landmarks.items()))
        _print_stats(res.stats, len(res.target.vertices))
        return
    V, F = trimesh.remesh.subdivide(tpl.neutral, tpl.triangles)
    X = random_identity(V, args.seed)
    Y, R, t = random_pose(X, args.seed)
    print(f"target: {len(Y)} vertices, {len(F)} triangles (mm, random pose)")
    t0 = time.perf_counter()
    model, res = build_model((Y, F), template=tpl, expressions=args.expressions)
    _print_stages(res, time.perf_counter() - t0)
    # truth: the template's landmarks and vertices carried by the known deformation, model frame
    A = model.scan_transform
    truth = Y @ A[:3, :3].T + A[:3, 3]                     # subdivided skin, first len(tpl) = template
    tl = template_landmarks(tpl)
    tri, w, _ = closest_points(np.array(list(tl.values())), tpl.neutral, tpl.triangles)
    known = np.einsum("nk,nkj->nj", w, truth[tpl.triangles[tri]])
    err = {k: float(np.linalg.norm(res.landmarks[k] - p) * 1000) for k, p in zip(tl, known)}
    print("landmark error (mm): " + ", ".join(f"{k} {v:.1f}" for k, v in err.items()))
    corr = np.linalg.norm(model.neutral - truth[: len(tpl.neutral)], axis=1) * 1000
    print(f"vertex correspondence error: mean {corr.mean():.2f} mm, median {np.median(corr):.2f} mm")
    _print_stats(res.stats, len(Y))


def _print_stages(res, total):
    for k, v in res.seconds.items():
        print(f"  {k:12s} {v:7.1f} s")
    print(f"  {'total':12s} {total:7.1f} s")


def _print_stats(st, n_target):
    print(json.dumps({"alignment_residual_mm": round(st["alignment_residual_mm"], 3),
                      "skin_to_target_mean_mm": round(st["surface_to_target_mm"]["mean"], 4),
                      "snapped_fraction": round(st["snapped_fraction"], 3),
                      "inverted_tets": st["quality"]["inverted"],
                      "min_radius_ratio": round(st["quality"]["min_radius_ratio"], 4),
                      "target_vertices": n_target}))


if __name__ == "__main__":
    main()
