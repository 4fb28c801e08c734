"""Where the eye rests (issue 59): the iris's height between the eye's corners on real plates, the
built-in head's own, and the line of sight the pose pass fits to people who look into the lens.

    python bench/eye_rest.py [--photos DIR] [--clip FILE] [--every 6] [--json FILE]

1. On each real plate (the photos in DIR, default ``../shared/data/real/photos``, the astronaut
   of scikit-image, and every ``--every``-th frame of the shared 72-frame clip) the landmark
   detector gives each eye's corners and iris. ``height`` is the iris centre's distance above
   the corners' line, in eye widths (corner to corner), averaged over the two eyes.
2. The built-in head's own ``height``: its pupil (the eyeball's front pole) against its eye
   curves' end vertices, projected from the front, and the detector's on a render of it.
3. The pose pass (``pipeline.plates.pose_from_curves``, Eq. 15) poses the built-in head on each
   plate; ``sight`` is the line of sight's pitch in the camera's frame (rad, positive up), the
   eyes' mean pitch less the head's. A portrait's subject looks into the lens, so its truth is
   about 0; the clip's actor looks at the phone that films him.

The split: tuned on 0-f1, 0-f15, 15-f13 and the clip's first half; held out are 45-m7,
single_face, the astronaut and the clip's second half. Prints per plate and the medians per
split.
"""
from __future__ import annotations

import argparse
import sys
import tempfile
from pathlib import Path

import numpy as np
from _common import SHARED, add_json_option, write_json

import invface
from invface.fit.landmarks import curves_from_landmarks, detect_face
from invface.io.images import linear_to_srgb, srgb_to_linear, write_image
from invface.model.gaze import Eyes, eye_angles
from invface.pipeline.clips import open_clip
from invface.pipeline.plates import find_curves, pose_from_curves
from invface.render.camera import Camera
from invface.render.plates import load_plate
from invface.render.synthetic import render_plate, skin_albedo, studio_light

PHOTOS = SHARED / "real" / "photos"
CLIP = SHARED / "real" / "video" / "single_face.mp4"
TUNE = ("0-f1", "0-f15", "15-f13")


def height(curves):
    """The iris centres' mean height above their eye's corners' line, in eye widths (image y
    points down, so up is the line's normal towards -y), from curves {eye_S_upper (n,2) px,
    iris_S (k,2) px}."""
    out = []
    for s in "LR":
        lid = np.asarray(curves[f"eye_{s}_upper"], float)
        a, b = sorted((lid[0], lid[-1]), key=lambda q: q[0])
        u = (b - a) / np.linalg.norm(b - a)
        up = np.array([u[1], -u[0]])
        out.append((np.asarray(curves[f"iris_{s}"], float).mean(0) - (a + b) / 2) @ up / np.linalg.norm(b - a))
    return float(np.mean(out))


def plates(photos, clip, every, scratch):
    """[(name, split, Plate)]: the photos, the astronaut (written to ``scratch`` as a PNG) and
    every ``every``-th clip frame."""
    import skimage.data
    out = []
    for p in sorted(q for q in photos.iterdir() if q.suffix.lower() in (".jpg", ".jpeg", ".png")):
        name = p.stem.split("-ph")[0].rsplit("-", 1)[0] if "-ph" in p.stem else p.stem
        out.append((name, "tune" if name in TUNE else "held-out", load_plate(p)))
    path = write_image(Path(scratch) / "astronaut.png", srgb_to_linear(skimage.data.astronaut() / 255.0))
    out.append(("astronaut", "held-out", load_plate(path)))
    frames = [f.plate for f in open_clip(clip).frames()]
    for i in range(0, len(frames), every):
        out.append((f"clip{i:02d}", "tune" if i < len(frames) // 2 else "held-out", frames[i]))
    return out


def model_heights(model):
    """(the model's own height, the detector's on a front render of it) at rest."""
    cam = Camera.front_view(512, 512)
    p = model.parameters({})
    X = model.surface_model("blendshape").surface(p)
    own = {k: cam.project(X[np.asarray(model.curves[k])])[0] for k in ("eye_L_upper", "eye_R_upper")}
    pupils = cam.project(Eyes(model).pupils(p)[0])[0]
    own["iris_L"], own["iris_R"] = pupils[:1], pupils[1:]
    img, _ = render_plate(model, X, cam, studio_light(), skin_albedo(model), parts_x=model.parts_positions(p), spp=16)
    points, _ = detect_face(linear_to_srgb(img), name="render")
    return height(own), height(curves_from_landmarks(points))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--photos", type=Path, default=PHOTOS)
    ap.add_argument("--clip", type=Path, default=CLIP)
    ap.add_argument("--every", type=int, default=6, help="every n-th clip frame (default 6)")
    add_json_option(ap)
    a = ap.parse_args()
    if not a.photos.is_dir() or not a.clip.exists():
        sys.exit(f"{a.photos} or {a.clip}: the shared photos and clip are needed")
    model = invface.template.build(1.0)
    own, rendered = model_heights(model)
    print(f"built-in head: height {own:+.3f} eye widths (its own pupil and corners), "
          f"{rendered:+.3f} (the detector on a front render)")
    rows = []
    scratch = tempfile.TemporaryDirectory()
    for name, split, plate in plates(a.photos, a.clip, a.every, scratch.name):
        curves, _ = find_curves(model, plate, None)           # the detector; its scores in plate.peer_arkit
        scores = plate.peer_arkit
        pose = pose_from_curves(model, plate, curves)
        eyes = eye_angles(model.blendshape_names, pose.p[:len(model.blendshape_names)])
        r = {"plate": name, "split": split, "height": height(curves),
             "head_pitch": float(-pose.rotation[0]), "eye_pitch": float(np.mean([eyes[s][1] for s in "LR"])),
             "curve_rms_px": float(pose.rms_px),
             "mediapipe_look_up": float(np.mean([scores.get(f"eyeLookUp{s}", 0.0) for s in ("Left", "Right")])),
             "mediapipe_look_down": float(np.mean([scores.get(f"eyeLookDown{s}", 0.0) for s in ("Left", "Right")]))}
        r["sight"] = r["eye_pitch"] + r["head_pitch"]
        rows.append(r)
        print(f"  {name:>12} ({split:8}): height {r['height']:+.3f}, head pitch {r['head_pitch']:+.3f} "
              f"(up), eyes {r['eye_pitch']:+.3f}, sight {r['sight']:+.3f} rad, curves {r['curve_rms_px']:.2f} px, "
              f"MediaPipe up/down {r['mediapipe_look_up']:.2f}/{r['mediapipe_look_down']:.2f}", flush=True)
    summary = {}
    for split in ("tune", "held-out"):
        sel = [r for r in rows if r["split"] == split]
        summary[split] = {k: float(np.median([r[k] for r in sel])) for k in ("height", "sight", "curve_rms_px")}
        summary[split]["abs_sight"] = float(np.median([abs(r["sight"]) for r in sel]))
        print(f"{split:>8}: median height {summary[split]['height']:+.3f} eye widths, sight "
              f"{summary[split]['sight']:+.3f} rad (|sight| {summary[split]['abs_sight']:.3f}), curves "
              f"{summary[split]['curve_rms_px']:.2f} px")
    write_json(a.json, {"model_height": own, "render_height": rendered, "plates": rows, "medians": summary})


if __name__ == "__main__":
    main()
