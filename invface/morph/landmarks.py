"""The 17 landmarks of paper 001 (sec. 6, Fig. 6) on a target aligned to the template.

The target is already in the model frame (orient.align_to_template): +Y up, +Z forward. Each
landmark starts from a prior, the template's landmark carried to the target's closest point,
and is then found by the paper's rule for it:

- on the profile curve (mesh ∩ symmetry plane): the nose tip (most forward point), the nose
  bridge (the deepest point above the tip), the subnasale (the sharpest concave corner
  between tip and mouth), the upper and lower lip (most forward points either side of the
  stomion), the chin (the most down-and-forward point below the mouth), the neck start
  (2 cm below the chin) and the top of the head (the highest point);
- the left/right extreme points of the head above the chin;
- eye corners, mouth corners and alar points by curvature-weighted local registration: the
  template's skin within 15 mm of the landmark, each vertex weighted by its fixed-stencil
  feature strength (sec. 6: curvature is what marks these features), is rigidly registered
  (trimmed ICP) onto the target from the global alignment, and the landmark moves with it.

Deviation: the paper finds corners as the high-curvature points nearest to corners of boxes
spanned by other landmarks. On the generated template the eye and mouth corners are the ends
of zero-width slits, which the 5 mm stencil smears (its curvature maximum lies 3-8 mm from
the slit end), and the box rule then depends on the box; registering the curvature-weighted
patch finds the same anatomical point on both meshes.
"""
from __future__ import annotations

import numpy as np

from ..errors import MeshError
from ..mesh.closest import closest_points
from ..mesh.sections import plane_sections
from ..template.features import profile_concavity
from .curvature import feature_strength
from .orient import rigid_icp

LANDMARKS = ("nose_tip", "nose_bridge", "subnasale", "top_of_head", "chin", "neck_start",
             "head_extreme_L", "head_extreme_R", "eye_inner_L", "eye_outer_L", "eye_inner_R",
             "eye_outer_R", "mouth_corner_L", "mouth_corner_R", "lip_upper", "lip_lower",
             "alar_L", "alar_R", "stomion")
PATCH_RADIUS = 0.015      # m: template skin registered around eye/mouth corners and alar points


_TEMPLATE_POINTS = {}


def template_landmarks(model):
    """{name: (3,) point} of LANDMARKS on the template: its own landmarks, and the lip points
    (which it does not list) found by the same profile rules as on a target."""
    if id(model) not in _TEMPLATE_POINTS:
        found, _ = find_landmarks(model.neutral, model.triangles, model)
        pts = {k: model.neutral[v] for k, v in model.landmarks.items() if k in LANDMARKS}
        _TEMPLATE_POINTS[id(model)] = {k: pts.get(k, found[k]) for k in LANDMARKS}
    return _TEMPLATE_POINTS[id(model)]


def profile_curve(V, F, prior_tip, depth=0.16):
    """The front profile (n,3): the pieces of mesh ∩ plane x = 0 no more than ``depth`` behind
    the nose tip, each ordered bottom to top and joined in height order (an open mouth or
    eyes split the section into pieces)."""
    chains = plane_sections(V, F, np.zeros(3), np.array([1.0, 0, 0]))
    parts = []
    for c in chains:
        Q = c.points[c.points[:, 2] > prior_tip[2] - depth]
        if len(Q) < 2:
            continue
        parts.append(Q if Q[0, 1] < Q[-1, 1] else Q[::-1])
    if not parts:
        raise MeshError("the symmetry plane does not cut the front of the aligned target")
    parts.sort(key=lambda Q: Q[:, 1].mean())
    return np.concatenate(parts)


_PATCHES = {}


def _template_patch(model, vid, radius=PATCH_RADIUS):
    """Template skin points (n,3) within ``radius`` of vertex vid and their weights (n,)."""
    key = (id(model), vid)
    if key not in _PATCHES:
        Vt = model.neutral
        ids = np.flatnonzero(np.linalg.norm(Vt - Vt[vid], axis=1) < radius)
        w = feature_strength(Vt, model.triangles, ids)
        _PATCHES[key] = (Vt[ids], w / w.mean())
    return _PATCHES[key]


def _register_patch(model, vid, V, F):
    """Template landmark vid carried onto the target (V, F; aligned) by curvature-weighted
    rigid ICP of its surrounding template patch."""
    P, w = _template_patch(model, vid)
    R, t, _ = rigid_icp(P, V, F, np.eye(3), np.zeros(3), iters=30, weights=w)
    q = R @ model.neutral[vid] + t
    tri, bw, _ = closest_points(q[None], V, F)
    return np.einsum("k,kj->j", bw[0], V[F[tri[0]]])


def find_landmarks(V, F, model):
    """Landmarks {name: (3,) point in the model frame} and the profile polyline, on an aligned
    target (V (n,3) m in the model frame, F). Raises MeshError when a landmark cannot be placed."""
    prior = {k: model.neutral[v] for k, v in model.landmarks.items() if k in LANDMARKS}
    # priors carried onto the target surface
    tri, w, _ = closest_points(np.array(list(prior.values())), V, F)
    prior = dict(zip(prior, np.einsum("nk,nkj->nj", w, V[F[tri]])))
    P = profile_curve(V, F, prior["nose_tip"])
    y, z = P[:, 1], P[:, 2]
    idx = np.arange(len(P))
    L = {}

    def window(center, r):
        return np.linalg.norm(P - center, axis=1) < r

    near_tip = window(prior["nose_tip"], 0.025)
    if not near_tip.any():
        raise MeshError("the profile curve misses the nose: the alignment to the template failed")
    tip = idx[near_tip][np.argmax(z[near_tip])]
    L["nose_tip"] = P[tip]
    above = (idx > tip) & window(prior["nose_bridge"], 0.015)
    if not above.any():
        raise MeshError("no nose bridge above the nose tip on the profile")
    L["nose_bridge"] = P[idx[above][np.argmin(z[above])]]
    for name in ("eye_inner_L", "eye_outer_L", "eye_inner_R", "eye_outer_R", "mouth_corner_L",
                 "mouth_corner_R", "alar_L", "alar_R"):
        L[name] = _register_patch(model, model.landmarks[name], V, F)
    # mouth: stomion at the corners' height, lips either side
    my = 0.5 * (L["mouth_corner_L"][1] + L["mouth_corner_R"][1])
    mouth = (idx < tip) & (np.abs(y - my) < 0.006) & window(prior["stomion"], 0.008)
    if not mouth.any():
        raise MeshError("no mouth found on the profile at the height of the mouth corners")
    stom = idx[mouth][np.argmin(z[mouth])]
    L["stomion"] = P[stom]
    between = (idx < tip) & (idx > stom) & (y > P[stom, 1] + 0.006) & window(prior["subnasale"], 0.01)
    sub = idx[between][np.argmax(profile_concavity(P, idx[between]))] if between.any() else tip
    L["subnasale"] = P[sub]
    up = (idx > stom) & (idx < sub)
    L["lip_upper"] = P[idx[up][np.argmax(z[up])]] if up.any() else P[stom]
    below = (idx < stom) & (y < P[stom, 1] - 0.012)
    if not below.any():
        raise MeshError("the profile ends at the mouth: no chin found")
    chin = idx[below][np.argmax(z[below] - y[below])]
    L["chin"] = P[chin]
    lo = (idx < stom) & (idx > chin)
    L["lip_lower"] = P[idx[lo][np.argmax(z[lo])]] if lo.any() else P[stom]
    neck = idx[(idx <= chin)]
    L["neck_start"] = P[neck[np.argmin(np.abs(y[neck] - (P[chin, 1] - 0.02)))]]
    L["top_of_head"] = P[np.argmax(y)]
    band = (V[:, 1] > L["chin"][1]) & (np.abs(V[:, 1] - prior["head_extreme_L"][1]) < 0.03)
    if not band.any():
        raise MeshError("no head sides found above the chin")
    bid = np.flatnonzero(band)
    L["head_extreme_L"] = V[bid[np.argmax(V[bid, 0])]]
    L["head_extreme_R"] = V[bid[np.argmin(V[bid, 0])]]
    return {k: np.asarray(L[k], float) for k in LANDMARKS}, P
