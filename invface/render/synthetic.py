"""Synthetic plates: the model rendered under a known light and albedo (tests, demo, plates/).

The ground truth comes with the image, so calibration and fitting can be checked against it.
"""
from __future__ import annotations

import numpy as np

from .camera import Camera
from .renderer import FaceRenderer
from .shading import SKIN_ALBEDO, constant_light


def studio_light():
    """gamma (9, 3): a warm key light from above-front-left on a cooler ambient fill."""
    g = constant_light([0.85, 0.82, 0.8])
    g[1] = [0.28, 0.27, 0.25]     # y: from above
    g[2] = [0.5, 0.48, 0.45]      # z: from the front
    g[3] = [0.3, 0.26, 0.22]      # x: from the actor's left
    g[4:] = [[0.03, 0.03, 0.02], [0.05, 0.05, 0.04], [-0.06, -0.06, -0.05],
             [0.04, 0.03, 0.03], [0.02, 0.02, 0.02]]
    return g


def skin_albedo(model, seed=0):
    """(V, 3) albedo: skin with redder lips, darker brows, flushed cheeks and ~1 cm mottling."""
    V = model.neutral
    rng = np.random.default_rng(seed)

    def blob(name, sigma):
        if name not in model.landmarks:
            return np.zeros((len(V), 1))
        return np.exp(-np.sum((V - V[model.landmarks[name]]) ** 2, 1) / (2 * sigma ** 2))[:, None]
    centres = V[rng.choice(len(V), min(60, len(V)), replace=False)]
    mottle = sum(rng.normal(0, 1, 3) * np.exp(-np.sum((V - c) ** 2, 1) / (2 * 0.01 ** 2))[:, None]
                 for c in centres)
    a = SKIN_ALBEDO * (1 + 0.05 * mottle + blob("stomion", 0.012) * [0.2, -0.2, -0.1]
                - 0.3 * (blob("brow_L", 0.01) + blob("brow_R", 0.01))
                + 0.1 * (blob("cheek_contour_L", 0.015) + blob("cheek_contour_R", 0.015)) * [1, 0.2, 0.2])
    return np.clip(a, 0.02, 1.0)


def render_plate(model, x, camera: Camera, gamma, albedo, rotation=None, translation=None,
                 background=(0.18, 0.2, 0.22), noise=0.005, spp=64, seed=0):
    """A linear plate (H, W, 3): the surface x (V, 3) rendered over a flat background, with
    Gaussian noise of std ``noise``; and its face mask (H, W) bool."""
    r = FaceRenderer(model.triangles, camera, spp=spp, seed=seed)
    img = r.image(x, gamma, albedo, rotation, translation)
    a = img[..., 3:4]
    plate = img[..., :3] + (1 - a) * np.asarray(background, np.float32)
    plate = plate + np.random.default_rng(seed).normal(0, noise, plate.shape).astype(np.float32)
    return np.clip(plate, 0, None), a[..., 0] > 0.5


# name -> (model kind that makes it, blendshape weights, jaw (6,), head rotation, translation)
SAMPLES = {
    "neutral": ("blendshape", {}, None, (0.03, -0.12, 0.0), (0.0, 0.0, 0.0)),
    "smile_blendshape": ("blendshape", {"lipCornerPull_L": 0.7, "lipCornerPull_R": 0.6, "cheekRaise": 0.3},
                         (0.03, 0, 0, 0, 0, 0), (0.04, -0.1, 0.01), (0.002, -0.001, 0.003)),
    "brows_blendshape": ("blendshape", {"browInnerUp_L": 0.6, "browInnerUp_R": 0.6, "browOuterUp_L": 0.4},
                         None, (-0.03, 0.08, 0.0), (-0.002, 0.002, 0.0)),
    "smile_simulation": ("simulation", {"lipCornerPull_L": 0.7, "lipCornerPull_R": 0.6, "cheekRaise": 0.3},
                         (0.03, 0, 0, 0, 0, 0), (0.04, -0.1, 0.01), (0.002, -0.001, 0.003)),
    "pucker_simulation": ("simulation", {"lipPucker": 0.8}, None, (0.0, 0.1, -0.02), (0.0, 0.001, -0.002)),
    "open_simulation": ("simulation", {"lipsPart": 0.5, "lowerLipDepress": 0.4}, (0.12, 0, 0, 0, 0, 0),
                        (0.06, -0.05, 0.0), (0.0, 0.0, 0.0)),
}


def sample_camera(width=720, height=540):
    """The sample plates' camera: 30 degrees, 0.72 m in front of the face (brow to chin in view)."""
    return Camera.front_view(width, height, eye=(0.0, 0.0, 0.72), target=(0.0, 0.0, 0.0))


def write_sample_plates(model, folder, names=None, size=(720, 540), noise=0.005, curve_noise=0.3,
                        progress=None):
    """Render the SAMPLES into ``folder``: NAME.png (sRGB 8-bit), NAME.json (camera),
    NAME.truth.json (the controls, pose and model kind that made it) and NAME.curves.json
    (the model's plate curves projected from the truth, with ``curve_noise`` px of noise).
    Deterministic. Returns the plate paths."""
    import json
    from pathlib import Path

    from ..fit.curves import PLATE_CURVES, projection_jacobian, write_curves
    from ..model.rig import euler_xyz
    from .plates import write_image
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    cam = sample_camera(*size)
    gamma, albedo = studio_light(), skin_albedo(model)
    K = len(model.blendshape_names)
    out = []
    for i, name in enumerate(names or SAMPLES):
        kind, weights, jaw, rot, tr = SAMPLES[name]
        if progress:
            progress(f"plate {name} ({kind} model)")
        p = np.zeros(K + 6)
        for k, v in weights.items():
            p[model.blendshape_names.index(k)] = v
        if jaw is not None:
            p[K:] = jaw
        x = model.surface_model(kind).surface(p)
        image, _ = render_plate(model, x, cam, gamma, albedo, rot, tr, noise=noise, seed=i)
        path = write_image(folder / f"{name}.png", image)
        cam.save(folder / f"{name}.json")
        truth = {"kind": kind, "weights": weights, "jaw": p[K:].tolist(), "rotation": list(rot),
                 "translation": list(tr), "light": "studio_light()", "albedo": "skin_albedo(model, seed=0)",
                 "noise": noise}
        (folder / f"{name}.truth.json").write_text(json.dumps(truth, indent=1))
        xr = x @ euler_xyz(np.asarray(rot)).T + np.asarray(tr)
        rng = np.random.default_rng(100 + i)
        curves = {c: projection_jacobian(cam, xr[model.curves[c]])[0] for c in PLATE_CURVES}
        curves = {c: v + rng.normal(0, curve_noise, v.shape) for c, v in curves.items()}
        write_curves(folder / f"{name}.curves.json", curves, image_size=cam.size)
        out.append(path)
    return out
