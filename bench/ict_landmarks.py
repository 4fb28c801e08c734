"""The builder's landmarks on faces of ICT-FaceKit's identity space against its annotated points
(issue 62): the orient and landmark stages of ``build-model`` alone.

    python bench/ict_landmarks.py [--seeds 0:25] [--tune 15,18] [--json FILE]

Each face is ICT-FaceKit's neutral plus its 20 identity shapes at coefficients ~ N(0, 1.5^2)
(seeded as ``bench/identity_3d.py``), cleaned, oriented and aligned to the built-in head
(``morph.build.orient_target``), then ``morph.landmarks.find_landmarks`` (the default head at
resolution 1, no expressions). Nine of ICT's annotated Multi-PIE points are scored: the eye and
mouth corners, the nose tip, the subnasale and the chin (mm). Prints per face its largest and
median error and the landmarks that fell back, then, for the tuned faces and the held-out ones,
the median of the faces' medians and the faces with a landmark over 10 mm.
"""
from __future__ import annotations

import argparse
import json
import sys
import time

import numpy as np
from _common import SHARED, add_json_option, write_json
from identity_3d import parse_range
from real_scans import ICT_POINTS

import invface
from invface.errors import InvfaceError
from invface.io.meshes import read_mesh
from invface.morph.build import orient_target
from invface.morph.landmarks import find_landmarks
from invface.morph.target import clean

ICT = SHARED / "ict-facekit"


def one_face(V, F, S, annotated, seed, template):
    """{seed, errors {name: mm}, fell [names], seconds} of face ``seed``, or with "error"."""
    t0 = time.perf_counter()
    mix = V + np.tensordot(np.random.default_rng(seed).normal(0, 1.5, len(S)), S, axes=1)
    try:
        target, al, _, _ = orient_target(clean(mix, F, unit="cm"), template, "cm")
        L, _, fell = find_landmarks(al.apply(target.vertices), target.faces, template)
    except InvfaceError as e:
        return {"seed": seed, "error": str(e), "seconds": round(time.perf_counter() - t0, 1)}
    err = {k: float(np.linalg.norm(L[k] - al.apply(mix[annotated[i]] * 0.01)) * 1000) for k, i in ICT_POINTS.items()}
    return {"seed": seed, "errors": {k: round(v, 2) for k, v in err.items()}, "fell": sorted(fell),
            "seconds": round(time.perf_counter() - t0, 1)}


def summary(rows):
    ok = [r for r in rows if "errors" in r]
    return {"faces": len(rows), "built": len(ok),
            "median_mm": float(np.median([np.median(list(r["errors"].values())) for r in ok])) if ok else None,
            "over_10mm": [r["seed"] for r in ok if max(r["errors"].values()) > 10.0]}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seeds", default="0:25")
    ap.add_argument("--tune", default="15,18", help="faces tuned on (comma-separated seeds)")
    add_json_option(ap)
    a = ap.parse_args()
    if not (ICT / "identities.npz").exists():
        sys.exit(f"{ICT}: ICT-FaceKit not found; this bench needs it")
    V, F = read_mesh(ICT / "neutral.obj")[:2]
    S = np.load(ICT / "identities.npz")["deltas"].astype(float)
    annotated = json.load(open(ICT / "landmarks.json"))["landmarks_68_multipie"]
    template = invface.template.build(1.0, expressions=False)
    tune = {int(s) for s in a.tune.split(",") if s}
    rows = []
    for seed in parse_range(a.seeds):
        r = one_face(V, F, S, annotated, seed, template)
        rows.append(r)
        if "error" in r:
            print(f"face {seed:2d}: {r['error']}", flush=True)
            continue
        worst = max(r["errors"], key=r["errors"].get)
        print(f"face {seed:2d}: median {np.median(list(r['errors'].values())):.2f} mm, worst {worst} "
              f"{r['errors'][worst]:.1f} mm, fell back {r['fell'] or '-'}, {r['seconds']} s", flush=True)
    out = {"rows": rows, "tuned": summary([r for r in rows if r["seed"] in tune]),
           "held_out": summary([r for r in rows if r["seed"] not in tune])}
    for k in ("tuned", "held_out"):
        s = out[k]
        print(f"{k}: {s['built']} of {s['faces']} faces, median landmark error {s['median_mm']:.2f} mm, "
              f"a landmark over 10 mm on faces {s['over_10mm']}")
    write_json(a.json, out)


if __name__ == "__main__":
    main()
