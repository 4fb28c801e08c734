"""Partial-scan benchmark (paper 001 sec. 8.1): build a model from the front of a head only.

    python bench/partial_scan.py [--resolution 0.3] [--cut 0.02] [--seed 3]

The target is a new identity of the template (``morph.synthetic.random_identity``) cut to
the triangles in front of the plane z = cut (m, the template frame: forehead to chin, no
back of the head, no ears), randomly posed and written in millimetres. Prints the seconds
of the build, the landmarks marked off the scan, and the vertex correspondence error
against the whole identity (mapped into the model frame by the similarity of its scanned
part): on the scan and off it (the completed head).
"""
from __future__ import annotations

import argparse
import time

import numpy as np

import invface
from invface.morph.build import build_model
from invface.morph.synthetic import front_part, onto_part, random_identity, random_pose


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolution", type=float, default=0.3, help="template size factor")
    ap.add_argument("--cut", type=float, default=0.02, help="keep the triangles in front of z = CUT (m)")
    ap.add_argument("--seed", type=int, default=3)
    a = ap.parse_args()
    tpl = invface.template.build(resolution=a.resolution)
    X = random_identity(tpl.neutral, a.seed, amplitude=0.003)
    used, faces = front_part(X, tpl.triangles, a.cut)
    Y, _, _ = random_pose(X[used], a.seed, unit=0.001)
    print(f"target: {len(used)} of {len(X)} vertices of the identity (z > {a.cut} m)")
    t0 = time.perf_counter()
    model, res = build_model((Y, faces), template=tpl, expressions="copy")
    sec = time.perf_counter() - t0
    A = model.scan_transform
    truth = onto_part(X, used, Y @ A[:3, :3].T + A[:3, 3])
    err = np.linalg.norm(model.neutral - truth, axis=1) * 1000
    on = np.zeros(len(X), bool)
    on[used] = True
    q = res.stats["quality"]
    print(f"built in {sec:.1f} s; off the scan: {', '.join(res.stats['off_scan_landmarks']) or 'none'}")
    print(f"correspondence error: on the scan mean {err[on].mean():.2f} mm, off it mean {err[~on].mean():.2f} "
          f"/ median {np.median(err[~on]):.2f} / max {err[~on].max():.2f} mm")
    print(f"flesh: {q['inverted']} inverted tets, volume {q['volume_m3'] * 1e6:.1f} cm^3, "
          f"min radius ratio {q['min_radius_ratio']:.4f}")


if __name__ == "__main__":
    main()
