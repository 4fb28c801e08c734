"""The model builder on a large scan (issue 27: "whole build under 10 minutes on 2 cores for a
50k-vertex scan"): a real scan subdivided (each triangle into four, midpoints on the flat
triangles) until it has at least ``--vertices`` vertices, then built with only the neutral
as `invface build-model --neutral FILE` does (expressions simulated, the CLI's default).

    python bench/build_large.py [--scan PATH] [--vertices 50000] [--expressions simulate]

Prints the scan's size, seconds per stage, the whole build's seconds and the peak resident
memory.
"""
from __future__ import annotations

import argparse
import resource
import time
from pathlib import Path

import numpy as np
from _common import SHARED
import trimesh

import invface
from invface.io.meshes import read_mesh
from invface.morph.build import build_model

SCAN = SHARED / "real" / "scans" / "lee_perry_smith.obj"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scan", default=str(SCAN))
    ap.add_argument("--vertices", type=int, default=50000)
    ap.add_argument("--expressions", default="simulate", choices=["simulate", "copy", "none"])
    args = ap.parse_args()
    V, F = (np.asarray(a) for a in read_mesh(args.scan)[:2])
    while len(V) < args.vertices:
        V, F = trimesh.remesh.subdivide(V, F)
    print(f"{Path(args.scan).name}: {len(V)} vertices, {len(F)} triangles")
    template = invface.template.build()
    t0 = time.perf_counter()
    model, res = build_model((V, F), template=template, expressions=args.expressions)
    total = time.perf_counter() - t0
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print("stages (s):", ", ".join(f"{k} {v:.1f}" for k, v in res.seconds.items()))
    print(f"whole build: {total:.1f} s, peak memory {peak:.0f} MB, unit {res.stats['unit']}, "
          f"inverted tets {res.stats['quality']['inverted']}")


if __name__ == "__main__":
    main()
