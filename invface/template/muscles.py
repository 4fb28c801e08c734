"""The template's facial muscles: centre-lines from origin (bone) to insertion (skin).

Each muscle is given by control points (x, y, t) on the left side (x >= 0): (x, y) is the
skin point seen from the front at that lateral position and height, t the depth fraction
between skin (0) and bone (1). Its tets are the flesh tets whose centroid lies within
``radius`` of the 3D centre-line; each tet's fibre is the centre-line tangent at the
nearest point. Paired muscles are mirrored exactly; rings are closed loops.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from . import grid
from .shape import skin_field

# name: (side 'pair' or 'M', points [(x, y, t)], radius m, closed ring?)
MUSCLES = {
    "frontalis_medialis": ("pair", [(0.016, 0.118, 0.55), (0.016, 0.092, 0.45), (0.016, 0.064, 0.2)], 0.010, False),
    "frontalis_lateralis": ("pair", [(0.044, 0.116, 0.55), (0.044, 0.090, 0.45), (0.044, 0.063, 0.2)], 0.011, False),
    "corrugator_supercilii": ("pair", [(0.008, 0.050, 0.9), (0.018, 0.056, 0.5), (0.030, 0.059, 0.2)], 0.0055, False),
    "procerus": ("M", [(0.0, 0.028, 0.9), (0.0, 0.042, 0.5), (0.0, 0.056, 0.2)], 0.0065, False),
    "orbicularis_oculi": ("pair", "ring:0.031,0.034,0.025,0.020,0.35", 0.0075, True),
    # the palpebral part (pretarsal and preseptal), in the lids, which slide on the eyeball
    "orbicularis_oculi_palpebralis": ("pair", "ring:0.031,0.0335,0.015,0.011,0.15", 0.005, True),
    "levator_labii_superioris_alaeque_nasi": ("pair", [(0.012, 0.036, 0.9), (0.014, 0.008, 0.5), (0.015, -0.019, 0.2)], 0.0045, False),
    "levator_labii_superioris": ("pair", [(0.025, 0.018, 0.9), (0.019, -0.004, 0.5), (0.012, -0.024, 0.2)], 0.0055, False),
    "zygomaticus_minor": ("pair", [(0.042, 0.012, 0.9), (0.030, -0.008, 0.5), (0.018, -0.026, 0.2)], 0.0045, False),
    "zygomaticus_major": ("pair", [(0.058, 0.010, 0.9), (0.044, -0.012, 0.5), (0.029, -0.034, 0.3)], 0.0055, False),
    "levator_anguli_oris": ("pair", [(0.022, 0.000, 0.9), (0.025, -0.016, 0.6), (0.027, -0.031, 0.3)], 0.0045, False),
    "risorius": ("pair", [(0.062, -0.036, 0.5), (0.045, -0.036, 0.4), (0.029, -0.036, 0.3)], 0.0045, False),
    "buccinator": ("pair", [(0.050, -0.036, 0.95), (0.040, -0.036, 0.8), (0.029, -0.035, 0.6)], 0.008, False),
    "depressor_anguli_oris": ("pair", [(0.036, -0.074, 0.9), (0.032, -0.056, 0.5), (0.028, -0.039, 0.3)], 0.0055, False),
    "depressor_labii_inferioris": ("pair", [(0.020, -0.072, 0.9), (0.015, -0.058, 0.5), (0.010, -0.045, 0.2)], 0.0055, False),
    "mentalis": ("pair", [(0.006, -0.054, 0.95), (0.007, -0.062, 0.5), (0.008, -0.071, 0.15)], 0.0045, False),
    "masseter": ("pair", [(0.060, 0.012, 0.9), (0.058, -0.020, 0.85), (0.050, -0.052, 0.9)], 0.010, False),
    "nasalis": ("pair", [(0.016, 0.000, 0.9), (0.010, 0.010, 0.5), (0.004, 0.019, 0.3)], 0.0045, False),
    "platysma": ("pair", [(0.048, -0.105, 0.4), (0.040, -0.075, 0.35), (0.029, -0.046, 0.3)], 0.012, False),
    "orbicularis_oris": ("M", "ring:0.0,-0.0345,0.031,0.0145,0.45", 0.0065, True),
    # the lips' own part of the ring (pars marginalis), under the vermilion: it rolls and
    # presses the lips (Bao et al. Fig. 6)
    "orbicularis_oris_marginalis": ("M", "ring:0.0,-0.0345,0.0235,0.0055,0.25", 0.0045, True),
    # from the incisor fossae of the maxilla and the mandible to the modiolus
    "incisivus_labii_superioris": ("pair", [(0.010, -0.018, 0.9), (0.018, -0.026, 0.6), (0.025, -0.033, 0.35)], 0.0035, False),
    "incisivus_labii_inferioris": ("pair", [(0.010, -0.052, 0.9), (0.018, -0.045, 0.6), (0.025, -0.038, 0.35)], 0.0035, False),
}

DEFAULT_ACTIVATION_CURVE = np.array([[0.5, 1.0], [1.0, 0.0], [1.5, 0.0]])


def _control_points(spec):
    if isinstance(spec, str):
        cx, cy, rx, ry, t = map(float, spec.split(":")[1].split(","))
        s = np.linspace(0, 2 * np.pi, 25)
        return np.stack([cx + rx * np.cos(s), cy + ry * np.sin(s), np.full_like(s, t)], 1)
    return np.array(spec, float)


def embed_points(xyt, depth_of):
    """3D points (n,3) for frontal control points xyt (n,3): skin at (x, y), depth fraction t.

    depth_of(p_skin (n,3)) -> tissue depth (n,) metres along the ray.
    """
    p = grid.point_at(skin_field, xyt[:, 0], xyt[:, 1])
    d = p - grid.CENTER
    r = np.linalg.norm(d, axis=1)
    return grid.CENTER + (d / r[:, None]) * (r - xyt[:, 2] * depth_of(p))[:, None]


def _resample(poly, step=0.0005):
    seg = np.linalg.norm(np.diff(poly, axis=0), axis=1)
    s = np.concatenate([[0], np.cumsum(seg)])
    u = np.linspace(0, s[-1], max(int(s[-1] / step), 2) + 1)
    pts = np.stack([np.interp(u, s, poly[:, k]) for k in range(3)], 1)
    tang = np.gradient(pts, axis=0)
    return pts, tang / np.linalg.norm(tang, axis=1, keepdims=True)


def build_muscles(X, tets, depth_of, min_tets=4, warp=None):
    """Muscle list for the flesh mesh X (N,3), tets (T,4). Returns [Muscle, ...].

    warp: optional map of centre-line points (n,3) -> (n,3) applied after they are placed on
    the analytic skin: the flesh's own change from it (the lids opened, ``eyelids.open_lids``)."""
    from ..model.facemodel import Muscle

    centroids = X[tets].mean(1)
    out = []
    for name, (side, spec, radius, ring) in MUSCLES.items():
        ctrl = _control_points(spec)
        variants = [("M", ctrl)] if side == "M" else [("L", ctrl), ("R", ctrl * [-1, 1, 1])]
        for sd, c in variants:
            line = embed_points(c, depth_of)
            if warp is not None:
                line = warp(line)
            pts, tang = _resample(line)
            dist, idx = cKDTree(pts).query(centroids)
            sel = np.nonzero(dist < radius)[0]
            if len(sel) < min_tets:       # thin muscle on a coarse mesh: take the nearest tets
                sel = np.sort(np.argsort(dist)[:min_tets])
            fib = tang[idx[sel]]
            out.append(Muscle(name if sd == "M" else f"{name}_{sd}", sel.astype(np.int64), fib, line,
                              DEFAULT_ACTIVATION_CURVE.copy(), sd))
    return out
