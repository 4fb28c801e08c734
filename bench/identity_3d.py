"""The actor's face from one photo and from a clip, in 3D (issue 65): how close the
identity-adapted head comes to the true face.

    python bench/identity_3d.py OUT [--seeds 0:15] [--tune 0:5] [--sd 1.5] [--curves detector|truth]
                                [--clip 24] [--turn 30] [--json FILE] [--report-only]

1. Truth faces: ICT-FaceKit's neutral plus its 20 identity shapes at coefficients drawn from
   N(0, sd^2) (``--sd``, default 1.5), one face per seed, each built into an actor with
   ``build_model`` (paper 001's morph; ``expressions="none"``), kept in OUT.
2. Each actor is rendered at neutral, frontal, 720x540 (``fit.samples.write_plate``, studio
   light). Its curves come from the landmark detector on the render (``--curves detector``,
   as a user's photo) or are projected from the actor (``truth``).
3. The built-in head is posed by Eq. 15 (``pipeline.plates.pose_from_curves``) and its identity
   fitted (``fit.identity.fit_identity``): the face-shape space (``morph.identity_space``)
   with the proportions, then the field, the detector's own offsets
   (``fit.identity.detector_bias``) taken off detected curves ("space"); without the space
   (the proportions and the field alone, "no space", as ``fit-plate`` fits it by default);
   and with the space but without the detector's offsets ("space, no bias", as
   ``fit-plate --identity-space`` fits it).
   A face whose build stops (``BuildFailed``), or whose built actor has its eye or mouth
   corners, nose or chin more than 10 mm from the mix's annotated ones (ICT's Multi-PIE
   points) is a failed build, left out and counted.
   With ``--clip N`` (default 24; 0 for the photo alone), the actor is also rendered as an
   N-frame clip in which the head turns from -``--turn`` to +``--turn`` degrees (default 30)
   and nods +-6 degrees, each frame detected and posed by Eq. 15 on its own, and the identity
   fitted once, shared by the frames (``fit.identity.fit_identity_views``): "clip" with the
   detector's offsets taken off each frame, "clip_no_bias" without; and shared by the frames
   ``fit-plate --identity-space`` would share it over, the most neutral-looking and those that
   show the head from another side ("clip_fit_plate", and "clip_fit_plate_no_bias", as
   ``fit-plate`` fits it). Frames where
   the detector finds no face are left out and counted. The frames' views are kept in
   OUT/views, so a rerun only fits.
4. The error: over the true face (skin within 6 cm of its nose tip), after a similarity
   alignment on those vertices, the distance of each of them to the adapted head's surface;
   median and 90th percentile in mm, beside the unadapted template's.

Seeds in ``--tune`` are the faces the prior was tuned on; the others are reported apart. The
ICT data is not part of invface (../shared/data/ict-facekit); without it the bench stops.
"""
from __future__ import annotations

import argparse
import json
import pickle
import sys
import time
from dataclasses import replace
from pathlib import Path
from types import SimpleNamespace

import numpy as np
from _common import SHARED, add_json_option, write_json

import invface
from invface.errors import InvfaceError
from invface.fit.identity import IdentityView, detector_bias, fit_identity, fit_identity_views
from invface.fit.samples import write_plate
from invface.io.meshes import read_mesh
from invface.mesh.closest import closest_points
from invface.morph.build import build_model
from invface.morph.orient import kabsch
from invface.model.controls import FitVector
from invface.pipeline.neutral import Candidate, distinct_views, neutral_score
from invface.pipeline.plates import DETECTOR, find_curves, pose_from_curves
from invface.render.plates import load_plate
from real_scans import ICT_POINTS

ICT = SHARED / "ict-facekit"
REACH = 0.06          # m: the face measured, around the nose tip
BUILT_MM = 10.0       # a build whose eye and mouth corners, nose or chin lie further than this from the
                      # annotated ones is a failed build (the morph, issue 62): its face is left out


def _detect_curves(image_srgb):
    """The detector's curves on an sRGB image, or None where it finds no face."""
    from invface.fit.landmarks import detect_curves
    try:
        return detect_curves(image_srgb, "the model's own render")
    except InvfaceError:
        return None


def face_error_mm(truth, neutral, triangles):
    """Median and p90 (mm) of the true face's vertices to ``neutral``'s surface (same topology),
    after a similarity alignment of ``neutral`` onto ``truth`` on those vertices."""
    nose = truth.neutral[truth.landmarks["nose_tip"]]
    face = np.flatnonzero(np.linalg.norm(truth.neutral - nose, axis=1) < REACH)
    R, t = kabsch(neutral[face], truth.neutral[face], scale=True)
    d = closest_points(truth.neutral[face], neutral @ R.T + t, triangles)[2] * 1000
    return float(np.median(d)), float(np.percentile(d, 90))


def truth_actor(out, seed, sd, template):
    """The actor built from ICT's neutral plus identity coefficients ~ N(0, sd^2) (seeded), and
    {"coefficients", "landmark_mm": the built actor's landmarks from the mix's annotated ones}."""
    path = out / f"face{seed:02d}.npz"
    info_path = out / f"face{seed:02d}.json"
    V, F = read_mesh(ICT / "neutral.obj")
    S = np.load(ICT / "identities.npz")["deltas"]
    c = np.random.default_rng(seed).normal(0, sd, len(S))
    mix = V + np.tensordot(c, S, axes=1)
    if path.exists():
        actor = invface.FaceModel.load(path)
    else:
        try:
            actor, _ = build_model((mix, F), template=template, unit="cm", expressions="none")
        except InvfaceError as e:
            return None, {"coefficients": c.tolist(), "build_error": str(e)}
        actor.save(path)
    ids = json.load(open(ICT / "landmarks.json"))["landmarks_68_multipie"]
    A = actor.scan_transform
    err = {k: float(np.linalg.norm(actor.neutral[actor.landmarks[k]] - (A[:3, :3] @ mix[ids[i]] + A[:3, 3])) * 1000)
           for k, i in ICT_POINTS.items()}
    info = {"coefficients": c.tolist(), "landmark_mm": {k: round(v, 2) for k, v in err.items()}}
    info_path.write_text(json.dumps(info))
    return actor, info


NOD = np.radians(6.0)  # the clip's nod, beside its turn


def truth_plate(out, truth, seed, detector=True, name=None, rotation=(0.0, 0.0, 0.0)):
    """The path of the actor ``truth`` rendered at neutral, posed by ``rotation`` (3,) rad
    (level by default), in OUT/plates as NAME.png (default faceSS); with ``detector`` its
    curve file is set aside (PLATE.curves.truth), so the detector finds the curves, as on a
    user's photo."""
    path = write_plate(truth, out / "plates", name or f"face{seed:02d}", "blendshape", {"weights": {}, "jaw": None},
                       tuple(rotation), (0.0, 0.0, 0.0), seed=seed)
    if detector:
        side = path.with_name(path.stem + ".curves.json")
        side.rename(side.with_suffix(".truth"))
    return path


def one_face(out, seed, sd, template, curves_from, frames=0, turn=30.0):
    t0 = time.perf_counter()
    truth, info = truth_actor(out, seed, sd, template)
    t_build = time.perf_counter() - t0
    if truth is None:
        print(f"face {seed}: {info['build_error']}", flush=True)
        return {"seed": seed, **info}
    path = truth_plate(out, truth, seed, detector=curves_from == "detector")
    side = path.with_name(path.stem + ".curves.json")
    plate = load_plate(path)
    curves, _ = find_curves(template, plate, side if curves_from == "truth" else None)
    pose = pose_from_curves(template, plate, curves)
    row = {"seed": seed, "coefficients": info["coefficients"], "build_s": round(t_build, 1),
           "landmark_mm": info["landmark_mm"], "template": face_error_mm(truth, template.neutral, template.triangles)}
    bias = (detector_bias(template, plate.camera, curves, pose.p, pose.rotation, pose.translation, _detect_curves)
            if curves_from == "detector" else None)
    for label, space, b in (("space", True, bias), ("no_space", False, None), ("space_no_bias", True, None)):
        t0 = time.perf_counter()
        idf = fit_identity(template, plate.camera, curves, pose.p, pose.rotation, pose.translation, space=space,
                           bias=b)
        row[label] = face_error_mm(truth, template.neutral + idf.displacement, template.triangles)
        row[label + "_s"] = round(time.perf_counter() - t0, 1)
        row[label + "_rms_px"] = [round(idf.rms_before, 2), round(idf.rms_after, 2)]
        if space:
            row["fitted_coefficients"] = idf.coefficients.round(3).tolist()
    print(f"face {seed}: template {row['template'][0]:.2f} mm, without the space {row['no_space'][0]:.2f}, "
          f"with it {row['space'][0]:.2f} (without the detector's bias {row['space_no_bias'][0]:.2f}) (median)",
          flush=True)
    if frames:
        row.update(clip_identity(out, truth, seed, template, frames, turn))
        print(f"face {seed}: from the {row['clip_frames']}-frame clip {row['clip'][0]:.2f} mm (without the "
              f"detector's bias {row['clip_no_bias'][0]:.2f}); from the {row['clip_fit_plate_views']} frames "
              f"fit-plate shares {row['clip_fit_plate'][0]:.2f} (without the bias "
              f"{row['clip_fit_plate_no_bias'][0]:.2f}) (median)", flush=True)
    return row


def clip_views(out, truth, seed, template, frames, turn):
    """The IdentityViews of an N-frame clip of the actor ``truth`` turning from -turn to +turn
    degrees and nodding +-NOD, each frame detected, posed by Eq. 15 and with the detector's
    offsets (``detector_bias``) beside it, and the seconds they took; kept in OUT/views (a
    rerun refits from them)."""
    cache = out / "views" / f"face{seed:02d}_{frames}x{turn:g}.pkl"
    if cache.is_file():
        return pickle.loads(cache.read_bytes()), 0.0
    t0 = time.perf_counter()
    views = []
    for i, u in enumerate(np.linspace(0.0, 1.0, frames)):
        rotation = (NOD * np.sin(2 * np.pi * u), np.radians(turn) * (2 * u - 1), 0.0)
        path = truth_plate(out, truth, seed, name=f"face{seed:02d}_turn{i:02d}", rotation=rotation)
        plate = load_plate(path)
        try:
            curves, _ = find_curves(template, plate, None)
        except InvfaceError:
            continue
        pose = pose_from_curves(template, plate, curves)
        bias = detector_bias(template, plate.camera, curves, pose.p, pose.rotation, pose.translation, _detect_curves)
        views.append(IdentityView(plate.camera, curves, pose.p, pose.rotation, pose.translation, bias))
    cache.parent.mkdir(exist_ok=True)
    cache.write_bytes(pickle.dumps(views))
    return views, time.perf_counter() - t0


def fit_plate_views(template, views):
    """The views ``fit-plate --identity-space`` shares an identity over: the most neutral-looking
    frame (``neutral_score``) and the others that show the head from another side
    (``distinct_views``); as the pipeline looks at 8 frames of a clip, not all."""
    vector = FitVector.of(template)
    cands = [Candidate(None, v.curves, DETECTOR, SimpleNamespace(p=v.p, rotation=v.rotation, vector=vector))
             for v in views]
    chosen = min(cands, key=lambda c: neutral_score(c.pose)[0])
    kept = [chosen] + distinct_views(chosen, [c for c in cands if c is not chosen])
    return [views[cands.index(c)] for c in kept]


def clip_identity(out, truth, seed, template, frames, turn):
    """The identity shared by the frames of the turning clip (``clip_views``): {"clip",
    "clip_no_bias" (every frame), "clip_fit_plate", "clip_fit_plate_no_bias" (``fit_plate_views``):
    [median, p90] mm, with _s (seconds), _rms_px ([before, after]) and _views (frames used)}."""
    views, seconds = clip_views(out, truth, seed, template, frames, turn)
    row = {"clip_frames": len(views), "clip_views_s": round(seconds, 1)}
    chosen = fit_plate_views(template, views)
    for label, use, keep_bias in (("clip", views, True), ("clip_no_bias", views, False),
                                  ("clip_fit_plate", chosen, True), ("clip_fit_plate_no_bias", chosen, False)):
        t0 = time.perf_counter()
        idf = fit_identity_views(template, [v if keep_bias else replace(v, bias=None) for v in use], space=True)
        row[label] = face_error_mm(truth, template.neutral + idf.displacement, template.triangles)
        row[label + "_s"] = round(time.perf_counter() - t0, 1)
        row[label + "_rms_px"] = [round(idf.rms_before, 2), round(idf.rms_after, 2)]
        row[label + "_views"] = len(use)
    return row


def summarise(rows, tune):
    """Label each row tune / report / failed build (``BUILT_MM``), print the table and the
    medians per set; returns {set: {model: [median, p90]}}."""
    print(f"{'face':>6} {'set':>12} {'template mm':>14} {'no space mm':>14} {'space mm':>14} {'clip mm':>14} "
          f"{'px before->after':>18}")
    f = lambda m: f"{m[0]:.2f} / {m[1]:.2f}"          # noqa: E731
    for r in rows:
        r["built"] = "build_error" not in r and max(r["landmark_mm"].values()) <= BUILT_MM
        r["set"] = ("tune" if r["seed"] in tune else "report") if r["built"] else "failed build"
        if "build_error" in r:
            print(f"{r['seed']:>6} {r['set']:>12} {r['build_error'][:90]}")
            continue
        clip = f(r["clip"]) if "clip" in r else "-"
        print(f"{r['seed']:>6} {r['set']:>12} {f(r['template']):>14} {f(r['no_space']):>14} {f(r['space']):>14} "
              f"{clip:>14} {r['space_rms_px'][0]:>8.2f} -> {r['space_rms_px'][1]:.2f}")
    failed = [r["seed"] for r in rows if not r["built"]]
    if failed:
        print(f"left out, the build's landmarks more than {BUILT_MM:g} mm from the annotated ones: faces {failed}")
    summary = {}
    for part in ("tune", "report"):
        sel = [r for r in rows if r["set"] == part]
        if sel:
            summary[part] = {k: [float(np.median([r[k][0] for r in sel])), float(np.median([r[k][1] for r in sel]))]
                             for k in ("template", "no_space", "space_no_bias", "space", "clip_no_bias", "clip",
                                       "clip_fit_plate_no_bias", "clip_fit_plate")
                             if all(k in r for r in sel)}
            print(f"{part} ({len(sel)} faces), median of the per-face median / p90 (mm): " + ", ".join(
                f"{k} {v[0]:.2f} / {v[1]:.2f}" for k, v in summary[part].items()))
    return summary


def parse_range(spec):
    a, b = (int(x) for x in spec.split(":"))
    return list(range(a, b))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path)
    ap.add_argument("--seeds", default="0:15")
    ap.add_argument("--tune", default="0:5", help="the seeds tuned on, reported apart (default 0:5)")
    ap.add_argument("--sd", type=float, default=1.5)
    ap.add_argument("--curves", choices=("detector", "truth"), default="detector")
    ap.add_argument("--clip", type=int, default=24, help="frames of the turning clip (default 24; 0: the photo alone)")
    ap.add_argument("--turn", type=float, default=30.0, help="the clip's head turn each way, degrees (default 30)")
    ap.add_argument("--report-only", action="store_true", help="the table of the rows in --json, made before")
    add_json_option(ap)
    a = ap.parse_args()
    if not (ICT / "identities.npz").exists():
        sys.exit(f"{ICT}: ICT-FaceKit not found (neutral.obj, identities.npz); this bench needs it")
    a.out.mkdir(parents=True, exist_ok=True)
    template = None if a.report_only else invface.template.build(1.0)
    tune = set(parse_range(a.tune))
    if a.report_only:
        rows = json.loads(Path(a.json).read_text())["figures"]["rows"]
    else:
        rows = [one_face(a.out, seed, a.sd, template, a.curves, a.clip, a.turn) for seed in parse_range(a.seeds)]
    summary = summarise(rows, tune)
    write_json(a.json, {"curves": a.curves, "sd": a.sd, "clip": a.clip, "turn": a.turn, "rows": rows,
                        "summary": summary})


if __name__ == "__main__":
    main()
