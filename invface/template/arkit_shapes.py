"""The built-in head's ARKit blendshapes: ICT-FaceKit's sculpted expressions carried onto it.

``data/arkit_ict.npz`` holds 51 of ARKit's 52 controls as offsets of the template's render
skin at resolution 1, derived from ICT-FaceKit (MIT; its licence is ``data/LICENSE-ICT-FaceKit.txt``)
by ``scripts/derive_arkit_shapes.py``. ICT-FaceKit has no tongueOut, and its two cheekPuff and
browInnerUp halves are summed into ARKit's one control each. The template replaces the two
eyeBlink shapes with its own kinematic blink (``expressions.add_blinks``), which closes the
lids onto the slit they were opened from. tongueOut, the 52nd, is a shape with no skin offset:
it moves the tongue part out of the mouth (``model.tongue``).

As paper 000 has it, the blendshapes are sculpted and drive the muscle simulation through
their tracks (Eq. 7-11). ``ARKIT_MUSCLES`` names the muscles each control engages, with the
activation that the shape is taken to need: they calibrate each muscle's activation-length
curve (Eq. 9, ``expressions.calibrate_activation_curves``) and are stored as the shapes'
``blendshape_activations``. Controls no facial muscle makes (the jaw's, which the jaw bone makes;
cheekPuff, which is air; the gaze's lids and eyeWide, which are the eyeball's and the levator
palpebrae's; tongueOut, the tongue's own muscles) engage none.

A template at another resolution takes the offsets by closest point on the stored skin. The
closed mouth's slit has its upper and lower lips' vertices at the same points: there each
side reads its own side's slit vertices. The lids' offsets are bent onto the head's eyeballs
(``slide_on_eyeballs``).
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from ..errors import BundleError
from ..io.arrays import load_npz
from ..mesh.closest import barycentric_points, closest_points
from .expressions import activations_for

DATA = Path(__file__).parent / "data" / "arkit_ict.npz"
KINEMATIC = ("eyeBlinkLeft", "eyeBlinkRight")      # the template makes these itself
TONGUE = "tongueOut"       # no skin offset: it moves the tongue part (``model.tongue``)

# ARKit control: ({muscle base name: activation}, sides); sides 'L'/'R' engage only the actor's
# left/right paired muscles, 'LR' both; midline muscles (procerus, orbicularis oris) always.
# The blinks' are with the blinks (``expressions.BLINKS``).
ARKIT_MUSCLES = {
    "browDownLeft": ({"corrugator_supercilii": 0.8, "procerus": 0.35}, "L"),
    "browDownRight": ({"corrugator_supercilii": 0.8, "procerus": 0.35}, "R"),
    "browInnerUp": ({"frontalis_medialis": 0.8}, "LR"),
    "browOuterUpLeft": ({"frontalis_lateralis": 0.8}, "L"),
    "browOuterUpRight": ({"frontalis_lateralis": 0.8}, "R"),
    "cheekPuff": ({}, "LR"),
    "cheekSquintLeft": ({"orbicularis_oculi": 0.5, "zygomaticus_minor": 0.3}, "L"),
    "cheekSquintRight": ({"orbicularis_oculi": 0.5, "zygomaticus_minor": 0.3}, "R"),
    "eyeLookDownLeft": ({}, "L"), "eyeLookDownRight": ({}, "R"),
    "eyeLookInLeft": ({}, "L"), "eyeLookInRight": ({}, "R"),
    "eyeLookOutLeft": ({}, "L"), "eyeLookOutRight": ({}, "R"),
    "eyeLookUpLeft": ({}, "L"), "eyeLookUpRight": ({}, "R"),
    "eyeSquintLeft": ({"orbicularis_oculi_palpebralis": 0.3, "orbicularis_oculi": 0.3}, "L"),
    "eyeSquintRight": ({"orbicularis_oculi_palpebralis": 0.3, "orbicularis_oculi": 0.3}, "R"),
    "eyeWideLeft": ({}, "L"), "eyeWideRight": ({}, "R"),
    "jawForward": ({}, "LR"), "jawLeft": ({}, "LR"), "jawOpen": ({}, "LR"), "jawRight": ({}, "LR"),
    "mouthClose": ({"orbicularis_oris": 0.4, "orbicularis_oris_marginalis": 0.4}, "LR"),
    "mouthDimpleLeft": ({"buccinator": 0.8}, "L"),
    "mouthDimpleRight": ({"buccinator": 0.8}, "R"),
    "mouthFrownLeft": ({"depressor_anguli_oris": 0.8}, "L"),
    "mouthFrownRight": ({"depressor_anguli_oris": 0.8}, "R"),
    "mouthFunnel": ({"orbicularis_oris": 0.45, "orbicularis_oris_marginalis": 0.2, "levator_labii_superioris": 0.3,
                     "depressor_labii_inferioris": 0.3}, "LR"),
    "mouthLeft": ({"risorius": 0.5, "buccinator": 0.4, "zygomaticus_major": 0.3}, "L"),
    "mouthRight": ({"risorius": 0.5, "buccinator": 0.4, "zygomaticus_major": 0.3}, "R"),
    "mouthLowerDownLeft": ({"depressor_labii_inferioris": 0.8}, "L"),
    "mouthLowerDownRight": ({"depressor_labii_inferioris": 0.8}, "R"),
    "mouthPressLeft": ({"orbicularis_oris_marginalis": 0.5, "incisivus_labii_superioris": 0.4,
                        "incisivus_labii_inferioris": 0.4, "mentalis": 0.3}, "L"),
    "mouthPressRight": ({"orbicularis_oris_marginalis": 0.5, "incisivus_labii_superioris": 0.4,
                         "incisivus_labii_inferioris": 0.4, "mentalis": 0.3}, "R"),
    "mouthPucker": ({"orbicularis_oris": 0.7, "incisivus_labii_superioris": 0.5,
                     "incisivus_labii_inferioris": 0.5}, "LR"),
    "mouthRollLower": ({"orbicularis_oris_marginalis": 0.7, "mentalis": 0.3}, "LR"),
    "mouthRollUpper": ({"orbicularis_oris_marginalis": 0.7}, "LR"),
    "mouthShrugLower": ({"mentalis": 0.8}, "LR"),
    "mouthShrugUpper": ({"mentalis": 0.5, "levator_labii_superioris": 0.2}, "LR"),
    "mouthSmileLeft": ({"zygomaticus_major": 0.8}, "L"),
    "mouthSmileRight": ({"zygomaticus_major": 0.8}, "R"),
    "mouthStretchLeft": ({"risorius": 0.8, "platysma": 0.5}, "L"),
    "mouthStretchRight": ({"risorius": 0.8, "platysma": 0.5}, "R"),
    "mouthUpperUpLeft": ({"levator_labii_superioris": 0.8}, "L"),
    "mouthUpperUpRight": ({"levator_labii_superioris": 0.8}, "R"),
    "noseSneerLeft": ({"levator_labii_superioris_alaeque_nasi": 0.8, "nasalis": 0.6, "procerus": 0.5}, "L"),
    "noseSneerRight": ({"levator_labii_superioris_alaeque_nasi": 0.8, "nasalis": 0.6, "procerus": 0.5}, "R"),
    "tongueOut": ({}, "LR"),
}


def load(path=DATA):
    """The stored shapes: {'names' (K,), 'deltas' (K,V0,3) m, 'jaw' (K,6), 'neutral' (V0,3) m,
    'triangles' (F0,3)} on the template's render skin at resolution 1."""
    a = load_npz(path, BundleError, "ARKit shape file")
    return {"names": [str(n) for n in a["names"]], "deltas": a["deltas_mm"].astype(float) / 1000.0,
            "jaw": np.asarray(a["jaw"], float), "neutral": np.asarray(a["neutral"], float),
            "triangles": np.asarray(a["triangles"], np.int64)}


def slit_sides(X, tol=1e-7):
    """Vertices of X (V,3) that share their point with another vertex (the closed mouth's
    slit): (upper (s,), lower (s,)) ids; the duplicate, the higher id, is the lower lip's."""
    pairs = np.array(sorted(cKDTree(X).query_pairs(tol)), np.int64).reshape(-1, 2)
    pairs.sort(axis=1)
    return pairs[:, 0], pairs[:, 1]


def carry(shapes, neutral, triangles):
    """The stored offsets (K,V0,3) carried onto a render skin ``neutral`` (V,3) m with
    ``triangles``: exact where it is the stored skin, else by closest point, the slit's upper
    and lower vertices each from their own side's nearest stored slit vertex. (K,V,3) m."""
    X0, D = shapes["neutral"], shapes["deltas"]
    neutral = np.asarray(neutral, float)
    if X0.shape == neutral.shape and np.abs(X0 - neutral).max() < 1e-6:
        return D.copy()
    tri, w, _ = closest_points(neutral, X0, shapes["triangles"])
    out = np.stack([barycentric_points(d, shapes["triangles"], tri, w) for d in D])
    new_sides, old_sides = slit_sides(neutral), slit_sides(X0)
    for ids, old in zip(new_sides, old_sides):
        if len(ids) and len(old):
            _, near = cKDTree(X0[old]).query(neutral[ids])
            out[:, ids] = D[:, old[near]]
    return out


def activations(name, muscles):
    """The activation vector (M,) that ARKit control ``name`` engages over ``muscles``."""
    return activations_for(ARKIT_MUSCLES[name] + (None,), muscles)


LID_REACH = 0.004      # m: skin this close to an eyeball's surface at rest slides on it


def slide_on_eyeballs(neutral, deltas, centres, radius, reach=LID_REACH):
    """Offsets (K,V,3) with the skin within ``reach`` of an eyeball (centres (E,3), ``radius``
    m) kept at its rest distance from the eyeball's centre: the lids slide over the eyeball.
    A carried lid offset is a straight line (ICT's eyeLookDown moves the upper lid 7.5 mm);
    on this head's eyeball it would cut into the eye and show the iris through the lid."""
    out = np.array(deltas, float)
    for c in np.asarray(centres, float):
        rest = np.linalg.norm(neutral - c, axis=1)
        near = np.flatnonzero(rest < radius + reach)
        if not len(near):
            continue
        p = neutral[near] + out[:, near] - c                      # (K, n, 3) from the centre
        r = np.linalg.norm(p, axis=2, keepdims=True)
        out[:, near] = c + p * (rest[near, None] / np.maximum(r, 1e-12)) - neutral[near]
    return out


def add_arkit_shapes(model, path=DATA):
    """Set a template FaceModel's blendshapes to the stored ARKit shapes (in place): names,
    blendshapes (K,V,3), blendshape_activations (K,M) and meta['blendshape_jaw'], leaving out
    ``KINEMATIC`` (made by ``expressions.add_blinks``). Returns the model."""
    from .shape import EYE_CENTER, EYE_RADIUS
    shapes = load(path)
    eyes = [EYE_CENTER * (sx, 1, 1) for sx in (1, -1)]
    D = slide_on_eyeballs(model.neutral, carry(shapes, model.neutral, model.triangles), eyes, EYE_RADIUS)
    keep = [k for k, n in enumerate(shapes["names"]) if n not in KINEMATIC]
    names = [shapes["names"][k] for k in keep]
    model.blendshape_names = names + [TONGUE]
    model.blendshapes = np.concatenate([D[keep], np.zeros((1,) + D.shape[1:])])
    model.blendshape_activations = np.array([activations(n, model.muscles) for n in model.blendshape_names])
    stats = {n: {"sculpted": "ICT-FaceKit", "max_displacement_mm": float(np.linalg.norm(d, axis=1).max() * 1000)}
             for n, d in zip(names, model.blendshapes)}
    stats[TONGUE] = {"sculpted": "none: the tongue part moves (model.tongue)", "max_displacement_mm": 0.0}
    jaw = {n: shapes["jaw"][k].tolist() for n, k in zip(names, keep)}
    model.meta = {**model.meta, "blendshape_jaw": {**jaw, TONGUE: [0.0] * 6}, "blendshape_sims": stats}
    return model
