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
                 background=(0.18, 0.2, 0.22), noise=0.005, spp=64, seed=0, parts_x=None):
    """A linear plate (H, W, 3): the surface x (V, 3) rendered over a flat background, with
    Gaussian noise of std ``noise``; and its face mask (H, W) bool. The model's inner parts
    (eyes, teeth, mouth) are drawn at parts_x (``model.parts_positions``; default at rest)."""
    r = FaceRenderer(model.triangles, camera, spp=spp, seed=seed, parts=model.parts)
    img = r.image(x, gamma, albedo, rotation, translation, parts_x=parts_x)
    a = img[..., 3:4]
    plate = img[..., :3] + (1 - a) * np.asarray(background, np.float32)
    plate = plate + np.random.default_rng(seed).normal(0, noise, plate.shape).astype(np.float32)
    return np.clip(plate, 0, None), a[..., 0] > 0.5
