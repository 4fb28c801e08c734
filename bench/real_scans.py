"""Real scans in (issue 27): build a model from every scan in ../shared/data/real/scans/ and
from ICT-FaceKit's neutral (and identity mixes of it), with only the neutral given, as
`invface build-model --neutral FILE` does.

    python bench/real_scans.py [--expressions simulate|copy|none] [--identities 3] [--out reports/real-scans]

Per scan: the unit found, seconds per stage, the share of the template skin snapped onto the
scan, the skin-to-scan distance on the face (median / 95th percentile / max, mm: every skin
vertex of the face region, snapped or filled), inverted tets, the minimum radius ratio, and,
for ICT-FaceKit (68 annotated landmark vertices), the errors of the eye corners, mouth corners,
nose tip, subnasale and chin, and the landmarks whose rule found nothing (issue 62: they fall
back to the template's). Writes one contact sheet of all builds (the scan with its
landmarks and curves, the neutral, front and 3/4) to OUT/contact_sheet.png.
"""
from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np
from _common import SHARED

import invface
from invface.errors import InvfaceError
from invface.io.meshes import read_mesh
from invface.morph.build import build_model

SCANS = SHARED / "real" / "scans"
ICT = SHARED / "ict-facekit"
# our landmark -> ICT-FaceKit's Multi-PIE 68-point index (+X is the actor's left in both)
ICT_POINTS = {"eye_outer_R": 36, "eye_inner_R": 39, "eye_inner_L": 42, "eye_outer_L": 45,
              "mouth_corner_R": 48, "mouth_corner_L": 54, "nose_tip": 30, "subnasale": 33, "chin": 8}


def ict_targets(n_identities, seed=0):
    """[(name, vertices (n,3) cm, faces, annotated vertex ids {name: id})]: the neutral and
    ``n_identities`` random mixes of its 20 identity shapes (coefficients ~ N(0, 1.5))."""
    V, F = read_mesh(ICT / "neutral.obj")[:2]
    lm = json.load(open(ICT / "landmarks.json"))["landmarks_68_multipie"]
    ids = {k: int(lm[i]) for k, i in ICT_POINTS.items()}
    D = np.load(ICT / "identities.npz")["deltas"].astype(float)
    rng = np.random.default_rng(seed)
    out = [("ict_neutral", V, F, ids)]
    for k in range(n_identities):
        c = rng.normal(0, 1.5, len(D))
        out.append((f"ict_identity_{k}", V + np.einsum("k,kvj->vj", c, D), F, ids))
    return out


def run(name, source, template, expressions, annotated=None):
    t0 = time.perf_counter()
    try:
        model, res = build_model(source, template=template, expressions=expressions)
    except InvfaceError as e:
        return {"scan": name, "error": str(e), "seconds": round(time.perf_counter() - t0, 1)}, None, None
    st = res.stats
    f = st["face_to_scan_mm"]
    row = {"scan": name, "unit": st["unit"], "unit_summary": st["unit_summary"],
           "seconds": round(time.perf_counter() - t0, 1), "stages": res.seconds,
           "snapped": round(st["snapped_fraction"], 3),
           "face_to_scan_mm": [round(f["median"], 2), round(f["p95"], 2), round(f["max"], 2)],
           "inverted_tets": st["quality"]["inverted"], "min_radius_ratio": round(st["quality"]["min_radius_ratio"], 4),
           "off_scan": st["off_scan_landmarks"], "openings_mapped": st["openings_mapped"],
           "fallbacks": {f["landmark"]: f["rule"] for f in st.get("landmark_fallbacks", [])},
           "cleaning": st["cleaning"]}
    if annotated is not None:
        V = np.asarray(source[0], float)
        A = model.scan_transform
        err = {k: float(np.linalg.norm(res.landmarks[k] - (A[:3, :3] @ V[i] + A[:3, 3])) * 1000)
               for k, i in annotated.items()}
        row["landmark_mm"] = {k: round(v, 2) for k, v in err.items()}
    return row, model, res


def contact_sheet(built, path, size=300):
    """One row per build: the scan with its landmarks and curves, the neutral; front and 3/4."""
    import matplotlib.pyplot as plt
    from invface.report.morph import GREY, marked_meshes, render_row
    from invface.report.preview import scenes
    rows = [np.concatenate([render_row(marked_meshes(res.aligned, res.target.faces, res.landmarks, res.curves, GREY), size, 8),
                            render_row(scenes(model)["skin"], size, 8)], 1)
            for _, model, res in built]
    fig_h = len(rows) * size / 100
    fig, axes = plt.subplots(len(rows), 1, figsize=(4 * size / 100, fig_h), squeeze=False)
    for ax, row, (name, _, _) in zip(axes[:, 0], rows, built):
        ax.imshow(row)
        ax.set_axis_off()
        ax.set_title(f"{name}: scan with landmarks and curves (front, 3/4) | the built neutral (front, 3/4)", fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=100)
    os.replace(tmp, path)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--expressions", default="simulate", choices=["simulate", "copy", "none"])
    ap.add_argument("--identities", type=int, default=3, help="ICT identity mixes besides its neutral")
    ap.add_argument("--only", nargs="*", help="scan names to run (default: all)")
    ap.add_argument("--out", default="reports/real-scans")
    args = ap.parse_args()
    template = invface.template.build()
    jobs = [(p.stem, str(p), None) for p in sorted(SCANS.glob("*.obj"))]
    if ICT.exists():
        jobs += [(n, (V, F), ids) for n, V, F, ids in ict_targets(args.identities)]
    if args.only:
        jobs = [j for j in jobs if j[0] in args.only]
    rows, built = [], []
    for name, source, ids in jobs:
        row, model, res = run(name, source, template, args.expressions, ids)
        rows.append(row)
        print(json.dumps(row), flush=True)
        if model is not None:
            built.append((name, model, res))
    print("\n| scan | unit | seconds | snapped | face to scan mm (median / 95th / max) | inverted | min radius ratio | landmarks mm (median / max) | rules fallen back |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        if "error" in r:
            print(f"| {r['scan']} | failed: {r['error']} | {r['seconds']} | | | | | | |")
            continue
        lm = r.get("landmark_mm")
        lms = f"{np.median(list(lm.values())):.1f} / {max(lm.values()):.1f}" if lm else "-"
        print(f"| {r['scan']} | {r['unit']} | {r['seconds']} | {r['snapped']:.0%} | "
              f"{' / '.join(str(x) for x in r['face_to_scan_mm'])} | {r['inverted_tets']} | {r['min_radius_ratio']} | {lms} | "
              f"{', '.join(r['fallbacks']) or 'none'} |")
    lms = [v for r in rows for v in r.get("landmark_mm", {}).values()]
    if lms:
        print(f"ICT landmarks over {len(lms)} points: median {np.median(lms):.2f} mm, max {max(lms):.2f} mm")
    if built:
        path = Path(args.out) / "contact_sheet.png"
        contact_sheet(built, path)
        print(f"wrote {path}")


if __name__ == "__main__":
    main()
