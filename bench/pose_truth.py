"""The head's pose and the eyes' gaze against the truth: ICT-FaceKit identity mixes built into
actors and rendered looking straight ahead, at rest, then posed by the built-in head.

    python bench/pose_truth.py OUT [--seeds 0:7] [--sd 1.5] [--drop CURVE ...] [--fit]
                               [--json FILE]

1. Each face is an actor built from ICT-FaceKit's neutral plus its 20 identity shapes at
   coefficients ~ N(0, sd^2) (``identity_3d.truth_actor``, kept in OUT), rendered at neutral
   with rotation 0, the gaze 0 and no expression (``identity_3d.truth_plate``). The actor's
   frame is the template's (the builder aligns the scan to it), so the true pose is 0.
2. The landmark detector finds the curves, as on a user's photo. ``pipeline.plates.
   pose_from_curves`` poses the built-in head (Eq. 15's pose pass, then its controls pass),
   with the curves named by ``--drop`` left out of both passes.
3. With ``--fit``, ``invface fit-plate PLATE`` also runs as a user runs it (identity, then the
   fit) and its fit.json gives the head's rotation and the eyes' angles.

Prints and writes, per face, the rotation (rad; x is the pitch, positive turning the face down)
and the eyes' (yaw, pitch) (rad), all of which are 0 in truth, and the medians of their
absolute values; ``sight_pitch`` is the eyes' line of sight in the camera's frame, the eye's
pitch (positive up) less the head's: where the eyes look, whatever share of it the fit gives
the head and the eyes.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
from _common import SHARED, add_json_option, write_json
from identity_3d import parse_range, truth_actor, truth_plate

import invface
from invface.model.gaze import eye_angles
from invface.pipeline.plates import find_curves, pose_from_curves
from invface.render.plates import load_plate

ICT = SHARED / "ict-facekit"


def plate_of(out, seed, sd, template):
    """The path of face ``seed``'s plate (rendered once, kept in OUT/plates), or None when its
    build failed."""
    path = out / "plates" / f"face{seed:02d}.png"
    if path.exists():
        return path
    truth, _ = truth_actor(out, seed, sd, template)
    if truth is None:
        return None
    return truth_plate(out, truth, seed)


def posed(template, path, drop):
    """(rotation (3,) rad, eyes {"L"/"R": (yaw, pitch)} rad) of ``pose_from_curves``."""
    plate = load_plate(path)
    curves, _ = find_curves(template, plate, None)
    pose = pose_from_curves(template, plate, {k: v for k, v in curves.items() if k not in drop})
    eyes = eye_angles(template.blendshape_names, pose.p[:len(template.blendshape_names)])
    return pose.rotation, eyes


def fitted(path, out):
    """(rotation, eyes) from ``invface fit-plate PATH``'s fit.json."""
    folder = out / "fits" / path.stem
    if not (folder / "blendshape" / "fit.json").exists():
        subprocess.run(["invface", "fit-plate", str(path), "-o", str(folder), "--force"], check=True,
                       stdout=subprocess.DEVNULL)
    d = json.loads((folder / "blendshape" / "fit.json").read_text())
    return np.array(d["rotation"]), {k: (v["yaw"], v["pitch"]) for k, v in d["eyes"].items()}


def row(label, rotation, eyes):
    r = {"rotation": np.round(rotation, 3).tolist(), "eyes": {k: np.round(v, 3).tolist() for k, v in eyes.items()}}
    print(f"  {label:>10}: rotation {r['rotation']}, eyes L {r['eyes']['L']} R {r['eyes']['R']}", flush=True)
    return r


def medians(rows, key):
    sel = [r[key] for r in rows if key in r]
    if not sel:
        return {}
    return {"pitch": float(np.median([abs(r["rotation"][0]) for r in sel])),
            "yaw": float(np.median([abs(r["rotation"][1]) for r in sel])),
            "eye_pitch": float(np.median([abs(r["eyes"][e][1]) for r in sel for e in "LR"])),
            "eye_yaw": float(np.median([abs(r["eyes"][e][0]) for r in sel for e in "LR"])),
            "sight_pitch": float(np.median([abs(r["eyes"][e][1] - r["rotation"][0]) for r in sel for e in "LR"]))}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path)
    ap.add_argument("--seeds", default="0:7")
    ap.add_argument("--sd", type=float, default=1.5)
    ap.add_argument("--drop", nargs="*", default=[], help="curves left out of the pose (e.g. jaw_line)")
    ap.add_argument("--fit", action="store_true", help="also run invface fit-plate on each plate")
    add_json_option(ap)
    a = ap.parse_args()
    if not (ICT / "identities.npz").exists():
        sys.exit(f"{ICT}: ICT-FaceKit not found (neutral.obj, identities.npz); this bench needs it")
    a.out.mkdir(parents=True, exist_ok=True)
    template = invface.template.build(1.0)
    rows = []
    for seed in parse_range(a.seeds):
        path = plate_of(a.out, seed, a.sd, template)
        if path is None:
            print(f"face {seed}: build failed")
            continue
        print(f"face {seed} (truth: every angle 0)")
        r = {"seed": seed, "pose_pass": row("pose pass", *posed(template, path, set(a.drop)))}
        if a.fit:
            r["fit_plate"] = row("fit-plate", *fitted(path, a.out))
        rows.append(r)
    summary = {k: medians(rows, k) for k in ("pose_pass", "fit_plate")}
    for k, v in summary.items():
        if v:
            print(f"{k}: median |error| (rad): " + ", ".join(f"{n} {x:.3f}" for n, x in v.items()))
    write_json(a.json, {"sd": a.sd, "drop": a.drop, "rows": rows, "summary": summary})


if __name__ == "__main__":
    main()
