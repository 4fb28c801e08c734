"""The builder's landmarks on variants of the real scans (issue 62's report set): each scan in
../shared/data/real/scans/ in another unit, turned, noisy, with holes, decimated, with its chin
cut off and with shoulders added, scored against the landmarks annotated on its original.

    python bench/scan_variants.py [--scans NAME,...] [--annotate] [--json FILE] [--out DIR]

The annotations (``bench/figures/real_scan_landmarks.json``: per scan, the file's triangle and
barycentric weights of each of the builder's landmarks) are the builder's own landmarks on the
original scan, checked by eye on ``DIR/annotations.png`` (``--annotate`` writes both). They follow the builder's conventions (DESIGN.md): an eye corner is the canthus,
a mouth corner the lip commissure, the nose tip the most forward point of the nose, the
subnasale the vertex of the nasolabial angle, the chin the gnathion (the 45-degree support).
So a variant's error is how far the landmarks move when the same head comes in another form,
not an error against an independent annotator (ICT-FaceKit's identity mixes are that source:
``bench/ict_landmarks.py``).

Only the orient and landmark stages of ``build-model`` run. Per variant: the landmarks that
fell back, and the error (mm) of each landmark that is on the variant. Face landmarks (the
profile's, the eye and mouth corners, the alar points) and head landmarks (top of the head,
head extremes, neck start: on flat regions, where the rules' points slide) are summarised
apart, per scan and over all.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
from _common import REPO, SHARED, add_json_option, write_json

import invface
from invface.errors import InvfaceError
from invface.io.meshes import read_mesh
from invface.mesh.closest import closest_points
from invface.morph.build import orient_target
from invface.morph.landmarks import LANDMARKS, find_landmarks
from invface.morph.synthetic import torso
from invface.morph.target import clean

SCANS = SHARED / "real" / "scans"
ANNOTATIONS = REPO / "bench" / "figures" / "real_scan_landmarks.json"
HEAD = ("top_of_head", "head_extreme_L", "head_extreme_R", "neck_start")
FACE = tuple(k for k in LANDMARKS if k not in HEAD)
ORDER = ("as_is", "in_other_unit", "turned", "noise", "holes", "decimated", "no_chin", "shoulders")


def landmarks_in_file(V, F, template, name):
    """(landmarks {name: (3,) in the file's units and frame}, fell {name: rule}, to_model,
    to_file: the maps of (k,3) points between the file and the model frame, metres per file
    unit) of the scan (V, F), through the orient and landmark stages."""
    target, al, _, _ = orient_target(clean(V, F, name=name), template)
    L, _, fell = find_landmarks(al.apply(target.vertices), target.faces, template)

    def to_model(P):
        return al.apply(np.asarray(P, float) * target.scale)

    def to_file(P):
        return (np.asarray(P, float) - al.t) @ al.R / target.scale
    return {k: to_file(v[None])[0] for k, v in L.items()}, fell, to_model, to_file, target.scale


def variant(kind, V, F, truth, metres, to_model, to_file, rng):
    """(vertices, faces, truth points (k,3) in the variant's file frame) of one variant of the
    scan (V, F) whose annotated points are ``truth`` (k,3); ``metres``: metres per file unit;
    ``to_model``, ``to_file``: the original's maps between its file frame and the model frame."""
    if kind == "as_is":
        return V, F, truth
    if kind == "in_other_unit":          # mm <-> m, a unitless scan in millimetres
        f = 0.001 if metres < 0.01 else 1000.0
        return V * f, F, truth * f
    if kind == "turned":                 # any orientation, anywhere
        R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        R *= np.sign(np.linalg.det(R))
        t = rng.normal(size=3) * 0.5 / metres
        return V @ R.T + t, F, truth @ R.T + t
    if kind == "noise":                  # 0.3 mm of scanner noise on every vertex
        return V + rng.normal(size=V.shape) * 0.0003 / metres, F, truth
    if kind == "holes":                  # twenty holes 8 mm across, anywhere on the scan
        c = V[F].mean(1)
        centres = V[rng.choice(len(V), 20, replace=False)]
        near = np.min(np.linalg.norm(c[:, None] - centres[None], axis=2), axis=1) < 0.004 / metres
        return V, F[~near], truth
    if kind == "decimated":              # vertices clustered into 5 mm cells
        _, inv = np.unique(np.floor(V / (0.005 / metres)).astype(np.int64), axis=0, return_inverse=True)
        inv = inv.ravel()
        W = np.zeros((inv.max() + 1, 3))
        np.add.at(W, inv, V)
        W /= np.bincount(inv)[:, None]
        G = inv[F]
        G = G[(G[:, 0] != G[:, 1]) & (G[:, 1] != G[:, 2]) & (G[:, 0] != G[:, 2])]
        _, keep = np.unique(np.sort(G, axis=1), axis=0, return_index=True)
        return W, G[np.sort(keep)], truth
    if kind == "no_chin":                # cut 3 mm below the lower lip
        lip = to_model(truth[LANDMARKS.index("lip_lower")][None])[0]
        keep = to_model(V[F].mean(1))[:, 1] > lip[1] - 0.003
        return V, F[keep], truth
    if kind == "shoulders":              # a torso (an ellipsoid 46 x 26 x 30 cm) whose top meets the neck
        M = to_model(V)
        B, G = torso(M[np.argmin(M[:, 1])])
        return np.concatenate([V, to_file(B)]), np.concatenate([F, G + len(V)]), truth
    raise ValueError(kind)


def annotate(names, template, out):
    """Write the annotations (the builder's landmarks on each original, at its nearest vertex)
    and a picture of them (front and 3/4) to check by eye."""
    from invface.report.morph import GREY, marked_meshes, render_row
    ann, rows = {}, []
    for name in names:
        V, F = read_mesh(SCANS / f"{name}.obj")[:2]
        L, fell, to_model, _, _ = landmarks_in_file(V, F, template, name)
        tri, w, _ = closest_points(np.array([L[k] for k in LANDMARKS]), np.asarray(V, float), np.asarray(F))
        ann[name] = {k: {"triangle": int(i), "weights": [round(float(x), 6) for x in b]}
                     for k, i, b in zip(LANDMARKS, tri, w)}
        if fell:
            print(f"{name}: fell back {sorted(fell)}: check these by eye", flush=True)
        rows.append((name, render_row(marked_meshes(to_model(V), F, dict(zip(LANDMARKS, to_model(
            _points(V, F, ann[name])))), {}, GREY), 400, 8)))
    record = {"convention": "the builder's landmarks on the original scan (bench/scan_variants.py --annotate): "
                            "per landmark, the file's triangle (0-based) and barycentric weights; checked by eye",
              "scans": ann}
    tmp = ANNOTATIONS.with_suffix(".tmp")
    tmp.write_text(json.dumps(record, indent=1))
    os.replace(tmp, ANNOTATIONS)
    import matplotlib.pyplot as plt
    fig, axes = plt.subplots(len(rows), 1, figsize=(8, 4 * len(rows)), squeeze=False)
    for ax, (name, img) in zip(axes[:, 0], rows):
        ax.imshow(img)
        ax.set_axis_off()
        ax.set_title(f"{name}: the annotated landmarks (front, 3/4)", fontsize=9)
    fig.tight_layout()
    out.mkdir(parents=True, exist_ok=True)
    fig.savefig(out / "annotations.tmp.png", dpi=100)
    os.replace(out / "annotations.tmp.png", out / "annotations.png")
    print(f"wrote {ANNOTATIONS} and {out / 'annotations.png'}")


def _points(V, F, ann):
    """The annotated points (k,3) in LANDMARKS order, from {landmark: {triangle, weights}}."""
    V, F = np.asarray(V, float), np.asarray(F)
    return np.array([np.asarray(ann[k]["weights"]) @ V[F[ann[k]["triangle"]]] for k in LANDMARKS])


def score(name, ann, template, seed=0):
    """Rows {scan, variant, errors {landmark: mm}, fell, vertices, seconds} for each variant of
    ``name`` (``ann``: its annotations)."""
    V, F = read_mesh(SCANS / f"{name}.obj")[:2]
    V = np.asarray(V, float)
    truth = _points(V, F, ann)
    t0 = time.perf_counter()
    original = landmarks_in_file(V, F, template, name)       # also the "as_is" variant's landmarks
    original_seconds = time.perf_counter() - t0
    _, _, to_model, to_file, metres = original
    rows = []
    for kind in ORDER:
        rng = np.random.default_rng([seed, ORDER.index(kind)])
        Vv, Fv, T = variant(kind, V, F, truth, metres, to_model, to_file, rng)
        t0 = time.perf_counter() - (original_seconds if kind == "as_is" else 0.0)
        row = {"scan": name, "variant": kind}
        try:
            L, fell, vmodel, _, _ = original if kind == "as_is" else landmarks_in_file(Vv, Fv, template, name)
        except InvfaceError as e:
            rows.append({**row, "error": str(e)})
            print(f"{name} {kind}: {e}", flush=True)
            continue
        # a landmark counts where its annotated point is still on the variant (not cut away)
        on = _on_surface(Vv, Fv, T, 0.002 / metres)
        err = {k: float(np.linalg.norm(vmodel(L[k][None]) - vmodel(T[i][None])) * 1000)
               for i, k in enumerate(LANDMARKS) if on[i]}
        row.update(errors={k: round(v, 2) for k, v in err.items()}, fell=sorted(fell), vertices=len(Vv),
                   seconds=round(time.perf_counter() - t0, 1))
        rows.append(row)
        face = [err[k] for k in FACE if k in err]
        print(f"{name:16s} {kind:14s} face median {np.median(face):5.2f} max {max(face):5.2f} mm "
              f"({max((k for k in FACE if k in err), key=err.get)}), fell back {sorted(fell) or '-'}", flush=True)
    return rows


def _on_surface(V, F, P, tol):
    """Boolean (k,) of the points P (k,3) within ``tol`` of the mesh (V, F)."""
    return closest_points(np.asarray(P, float), np.asarray(V, float), np.asarray(F))[2] < tol


def summary(rows):
    """{face: {median, max}, head: {median, max}} mm over the rows' landmarks, and fallbacks."""
    out = {}
    for group, landmarks in (("face", FACE), ("head", HEAD)):
        e = [v for r in rows if "errors" in r for k, v in r["errors"].items() if k in landmarks]
        out[group] = {"median_mm": float(np.median(e)) if e else None, "max_mm": float(max(e)) if e else None}
    out["fallbacks"] = sum(len(r.get("fell", [])) for r in rows)
    out["failed"] = [f"{r['scan']} {r['variant']}" for r in rows if "error" in r]
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scans", default="fran_cut,lee_perry_smith,demosthenes,nefertiti")
    ap.add_argument("--annotate", action="store_true", help="write the annotations from the originals first")
    ap.add_argument("--out", default="reports/scan-variants")
    add_json_option(ap)
    a = ap.parse_args()
    names = [n for n in a.scans.split(",") if n]
    if not all((SCANS / f"{n}.obj").exists() for n in names):
        sys.exit(f"{SCANS}: the real scans are not there; this bench needs them")
    template = invface.template.build(1.0, expressions=False)
    if a.annotate:
        annotate(names, template, Path(a.out))
    ann = json.loads(ANNOTATIONS.read_text())["scans"]
    rows = [r for n in names for r in score(n, ann[n], template)]
    out = {"rows": rows, "per_scan": {n: summary([r for r in rows if r["scan"] == n]) for n in names},
           "all": summary(rows)}
    print("\n| scan | face landmarks median / max mm | head landmarks median / max mm | fallbacks | failed |")
    print("|---|---|---|---|---|")
    for n, s in [*out["per_scan"].items(), ("all", out["all"])]:
        print(f"| {n} | {s['face']['median_mm']:.2f} / {s['face']['max_mm']:.2f} | "
              f"{s['head']['median_mm']:.2f} / {s['head']['max_mm']:.2f} | {s['fallbacks']} | {', '.join(s['failed']) or '-'} |")
    write_json(a.json, out)


if __name__ == "__main__":
    main()
