"""Sample plates with ground truth: the template rendered with known controls, pose, light
and albedo, by the blendshape rig or by the muscle simulation, with the curve files a roto
artist would draw (``plates/`` ships them; tests, the demo and ``bench/fit.py`` make them).

It sits in ``fit`` rather than ``render`` because it needs the fitting side's plate curves and
the simulation, which ``render`` must not import (DESIGN.md, import direction).
"""
from __future__ import annotations

import numpy as np

from ..render.camera import Camera
from ..render.synthetic import render_plate, skin_albedo, studio_light
from .curves import PLATE_CURVES, curve_points, projection_jacobian, write_curves

# name -> (model kind that makes it, blendshape weights, jaw (6,), head rotation, translation)
SAMPLES = {
    "neutral": ("blendshape", {}, None, (0.03, -0.12, 0.0), (0.0, 0.0, 0.0)),
    "smile_blendshape": ("blendshape", {"mouthSmileLeft": 0.7, "mouthSmileRight": 0.6,
                                          "cheekSquintLeft": 0.3, "cheekSquintRight": 0.3},
                         (0.03, 0, 0, 0, 0, 0), (0.04, -0.1, 0.01), (0.002, -0.001, 0.003)),
    "brows_blendshape": ("blendshape", {"browInnerUp": 0.6, "browOuterUpLeft": 0.4},
                         None, (-0.03, 0.08, 0.0), (-0.002, 0.002, 0.0)),
    "smile_simulation": ("simulation", {"mouthSmileLeft": 0.7, "mouthSmileRight": 0.6,
                                          "cheekSquintLeft": 0.3, "cheekSquintRight": 0.3},
                         (0.03, 0, 0, 0, 0, 0), (0.04, -0.1, 0.01), (0.002, -0.001, 0.003)),
    "pucker_simulation": ("simulation", {"mouthPucker": 0.8}, None, (0.0, 0.1, -0.02), (0.0, 0.001, -0.002)),
    "open_simulation": ("simulation", {"mouthLowerDownLeft": 0.4, "mouthLowerDownRight": 0.4,
                                       "mouthUpperUpLeft": 0.25, "mouthUpperUpRight": 0.25},
                        (0.12, 0, 0, 0, 0, 0), (0.06, -0.05, 0.0), (0.0, 0.0, 0.0)),
}


def sample_camera(width=720, height=540):
    """The sample plates' camera: 30 degrees, 0.72 m in front of the face (brow to chin in view)."""
    return Camera.front_view(width, height, eye=(0.0, 0.0, 0.72), target=(0.0, 0.0, 0.0))


def write_sample_plates(model, folder, names=None, size=(720, 540), noise=0.005, curve_noise=0.3,
                        progress=None):
    """Render the SAMPLES into ``folder`` with ``write_plate``. Deterministic. Returns the
    plate paths."""
    out = []
    for i, name in enumerate(names or SAMPLES):
        kind, weights, jaw, rot, tr = SAMPLES[name]
        if progress:
            progress(f"plate {name} ({kind} model)")
        out.append(write_plate(model, folder, name, kind, {"weights": weights, "jaw": jaw}, rot, tr, seed=i,
                               size=size, noise=noise, curve_noise=curve_noise))
    return out


def write_plate(model, folder, name, kind, controls, rotation, translation, seed=0, size=(720, 540),
                noise=0.005, curve_noise=0.3):
    """Render ``model``'s ``kind`` surface at ``controls`` ({"weights": {name: w}, "jaw": (6,)
    rad/m or None}), posed by ``rotation`` (3,) rad and ``translation`` (3,) m, through
    ``sample_camera`` into ``folder``: NAME.png (sRGB 8-bit, with ``noise`` of Gaussian noise),
    NAME.json (camera), NAME.truth.json (the controls, pose and model kind that made it) and
    NAME.curves.json (the model's plate curves projected from the truth, with ``curve_noise``
    px of noise). Studio light, the model's skin albedo. Deterministic in ``seed``. Returns the
    plate's path."""
    from pathlib import Path

    from ..io.images import write_image
    from ..io.jsonfile import write_object
    from ..model.controls import FitVector
    from ..model.pose import pose_points
    folder = Path(folder)
    cam = sample_camera(*size)
    weights, jaw = controls["weights"], controls.get("jaw")
    p = model.parameters({"weights": weights, "jaw": np.zeros(6) if jaw is None else jaw})
    x = model.surface_model(kind).surface(p)
    image, _ = render_plate(model, x, cam, studio_light(), skin_albedo(model), rotation, translation, noise=noise,
                            seed=seed, parts_x=model.parts_positions(p))
    path = write_image(folder / f"{name}.png", image)
    cam.save(folder / f"{name}.json")
    truth = {"kind": kind, "weights": weights, "jaw": p[FitVector.of(model).jaw].tolist(),
             "rotation": list(rotation), "translation": list(translation), "light": "studio_light()",
             "albedo": "skin_albedo(model, seed=0)", "noise": noise}
    write_object(folder / f"{name}.truth.json", truth)
    xr = pose_points(x, rotation, translation)
    rng = np.random.default_rng(100 + seed)
    curves = {c: projection_jacobian(cam, curve_points(model, c, xr))[0] for c in PLATE_CURVES}
    curves = {c: v + rng.normal(0, curve_noise, v.shape) for c, v in curves.items()}
    write_curves(folder / f"{name}.curves.json", curves, image_size=cam.size)
    return path


def occluded_mouth_plate(model, size=(320, 240)):
    """A hand over the mouth: the model's neutral rendered front on (``Camera.front_view`` at
    ``size``, studio light, its skin albedo), and the same plate with a skin-toned, striped box
    over the mouth (the outer lips' extent and 10-14 px more). Returns {"camera", "albedo" (V,3),
    "clean", "occluded" (H,W,3) linear, "box" (H,W) bool, "front" (V,) bool: the vertices
    facing the camera, "under" (V,) bool: those whose projection falls in the box}."""
    from ..render import shading
    cam = Camera.front_view(*size)
    albedo = skin_albedo(model)
    clean, _ = render_plate(model, model.neutral, cam, studio_light(), albedo, spp=16)
    lips = np.concatenate([projection_jacobian(cam, curve_points(model, n, model.neutral))[0]
                           for n in ("lip_outer_upper", "lip_outer_lower")])
    lo, hi = lips.min(0) - [12, 10], lips.max(0) + [12, 14]
    yy, xx = np.mgrid[:size[1], :size[0]]
    box = (xx >= lo[0]) & (xx <= hi[0]) & (yy >= lo[1]) & (yy <= hi[1])
    stripes = np.sin(xx / 3.0)
    hand = np.stack([0.42 + 0.08 * stripes, 0.28 + 0.05 * stripes, 0.22 + 0.04 * stripes], -1)
    occluded = clean.copy()
    occluded[box] = hand[box]
    uv = cam.project(model.neutral)[0]
    front = shading.vertex_normals(model.neutral, model.triangles)[:, 2] > 0.3
    under = front & (uv[:, 0] >= lo[0]) & (uv[:, 0] <= hi[0]) & (uv[:, 1] >= lo[1]) & (uv[:, 1] <= hi[1])
    return {"camera": cam, "albedo": albedo, "clean": clean, "occluded": occluded, "box": box, "under": under,
            "front": front}


def clip_controls(model, n, fps=24.0):
    """A smooth trajectory of n frames for a synthetic clip: a smile that rises and falls, the
    jaw opening and closing, the brows lifting, the head turning and nodding. Returns
    [(weights {name: w}, jaw (6,), rotation (3,) rad, translation (3,) m)] per frame."""
    t = np.arange(n) / fps
    names = set(model.blendshape_names)
    out = []
    for s in t:
        phase = 2 * np.pi * s / max(n / fps, 1e-9)
        w = {"mouthSmileLeft": 0.35 * (1 - np.cos(phase)), "mouthSmileRight": 0.3 * (1 - np.cos(phase)),
             "browInnerUp": 0.25 * (1 + np.sin(phase))}
        w = {k: float(v) for k, v in w.items() if k in names}
        jaw = np.array([0.04 * (1 - np.cos(2 * phase)), 0, 0, 0, 0, 0])
        rot = (0.03 * np.sin(phase), -0.12 * np.sin(phase + 0.5), 0.0)
        tr = (0.002 * np.sin(phase), 0.0, 0.003 * np.cos(phase))
        out.append((w, jaw, rot, tr))
    return out


def write_sample_clip(model, folder, n=24, kind="blendshape", size=(320, 240), fps=24.0, noise=0.005,
                      curve_noise=0.3, video=True, progress=None):
    """A synthetic clip with known truth from ``clip_controls``: folder/frames/frame_NNN.png
    with each frame's camera, truth and curve files (a folder sequence), and with ``video``
    folder/clip.mp4 (H.264, lossy), its camera clip.json and the per-frame sidecars
    clip.frame_NNNNNN.truth.json / .curves.json beside it. Deterministic (but for the video
    encoder). Returns (frames folder, video path or None)."""
    import contextlib
    from pathlib import Path

    from ..io.video import VideoWriter
    folder = Path(folder)
    cam = sample_camera(*size)
    if video:
        cam.save(folder / "clip.json")
    with VideoWriter(folder / "clip.mp4", fps) if video else contextlib.nullcontext() as writer:
        _write_clip_frames(model, kind, folder, writer, cam, n, fps, noise, curve_noise, progress)
    return folder / "frames", (folder / "clip.mp4") if video else None


def _write_clip_frames(model, kind, folder, writer, cam, n, fps, noise, curve_noise, progress):
    """The frames of ``write_sample_clip``: each rendered and written with its sidecars into
    folder/frames and, with a video ``writer``, appended to it with its sidecars in ``folder``."""
    from ..io.images import linear_to_srgb, write_image
    from ..io.jsonfile import write_object
    from ..model.controls import FitVector
    from ..model.pose import pose_points
    frames = folder / "frames"
    gamma, albedo = studio_light(), skin_albedo(model)
    vec = FitVector.of(model)
    sm = model.surface_model(kind)
    rng = np.random.default_rng(7)
    for i, (weights, jaw, rot, tr) in enumerate(clip_controls(model, n, fps)):
        if progress:
            progress(f"clip frame {i + 1}/{n}")
        p = model.parameters({"weights": weights, "jaw": jaw})
        x = sm.surface(p)
        image, _ = render_plate(model, x, cam, gamma, albedo, rot, tr, noise=noise, seed=i,
                                parts_x=model.parts_positions(p))
        xr = pose_points(x, rot, tr)
        curves = {c: projection_jacobian(cam, curve_points(model, c, xr))[0] for c in PLATE_CURVES}
        curves = {c: v + rng.normal(0, curve_noise, v.shape) for c, v in curves.items()}
        truth = {"kind": kind, "weights": weights, "jaw": p[vec.jaw].tolist(), "rotation": list(rot),
                 "translation": list(tr), "light": "studio_light()", "albedo": "skin_albedo(model, seed=0)",
                 "noise": noise, "frame": i, "time": i / fps}
        name = f"frame_{i:03d}"
        write_image(frames / f"{name}.png", image)
        cam.save(frames / f"{name}.json")
        write_object(frames / f"{name}.truth.json", truth)
        write_curves(frames / f"{name}.curves.json", curves, image_size=cam.size)
        if writer is not None:
            write_object(folder / f"clip.frame_{i:06d}.truth.json", truth)
            write_curves(folder / f"clip.frame_{i:06d}.curves.json", curves, image_size=cam.size)
            rgb = (np.clip(linear_to_srgb(image), 0, 1) * 255 + 0.5).astype(np.uint8)
            writer.write(rgb)
