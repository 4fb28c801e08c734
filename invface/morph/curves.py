"""Feature curves between landmarks, for the surface morph's Dirichlet conditions (sec. 7).

Every curve runs between two landmarks along the mesh's section by the plane that holds both
landmarks and their mean surface normal (for landmarks on the midline: the symmetry plane,
so the profile segments are pieces of the profile curve, as in the paper). The same rule on
the template and on the aligned target gives pairs of curves matched by normalised arc
length. The set follows Fig. 7-9 of paper 001: profile segments, eye curves (inner to outer
corner), the mouth line and lip arcs, nose curves around the tip and alar points, cheek,
jaw and head curves out to the head extremes.
"""
from __future__ import annotations

import numpy as np

from ..mesh.closest import barycentric_points, closest_points
from ..mesh.sections import arc_length, plane_sections, resample_even
from ..mesh.triangles import vertex_normals

# (from, to): the correspondence curves
CURVES = (
    ("top_of_head", "nose_bridge"), ("nose_bridge", "nose_tip"), ("nose_tip", "subnasale"),
    ("subnasale", "lip_upper"), ("lip_upper", "stomion"), ("stomion", "lip_lower"),
    ("lip_lower", "chin"), ("chin", "neck_start"),
    ("eye_inner_L", "eye_outer_L"), ("eye_inner_R", "eye_outer_R"),
    ("nose_bridge", "eye_inner_L"), ("nose_bridge", "eye_inner_R"),
    ("mouth_corner_L", "stomion"), ("stomion", "mouth_corner_R"),
    ("mouth_corner_L", "lip_upper"), ("lip_upper", "mouth_corner_R"),
    ("mouth_corner_L", "lip_lower"), ("lip_lower", "mouth_corner_R"),
    ("alar_L", "nose_tip"), ("nose_tip", "alar_R"), ("alar_L", "subnasale"), ("subnasale", "alar_R"),
    ("alar_L", "mouth_corner_L"), ("alar_R", "mouth_corner_R"),
    ("eye_inner_L", "alar_L"), ("eye_inner_R", "alar_R"),
    ("mouth_corner_L", "chin"), ("mouth_corner_R", "chin"),
    ("eye_outer_L", "head_extreme_L"), ("eye_outer_R", "head_extreme_R"),
    ("top_of_head", "head_extreme_L"), ("top_of_head", "head_extreme_R"),
    ("chin", "head_extreme_L"), ("chin", "head_extreme_R"),
)
SAMPLES = 40             # points per curve
SNAP_TOL = 0.003         # m: a section must pass this close to both landmarks
MAX_DETOUR = 1.6         # a section piece longer than this times the landmarks' distance is refused


def _project(V, F, P):
    tri, w, _ = closest_points(P, V, F)
    return barycentric_points(V, F, tri, w)


def landmark_curve(V, F, a, b, normals_at=None):
    """Polyline (SAMPLES,3) on the mesh from point a to point b (3,), equally spaced in arc
    length: the plane section through a, b and their mean normal; where holes break the
    section, or its piece between them is more than MAX_DETOUR times their distance long (an
    ICT-FaceKit section from the ala to the mouth corner ran 616 mm through the nostril's
    cavity), the straight segment projected onto the mesh."""
    n = normals_at if normals_at is not None else np.array([0, 0, 1.0])
    plane_n = np.cross(b - a, n)
    if np.linalg.norm(plane_n) > 1e-9:
        for c in plane_sections(V, F, a, plane_n):
            P = c.points[:-1] if c.closed else c.points
            ia, ib = (int(np.argmin(np.linalg.norm(P - p, axis=1))) for p in (a, b))
            if np.linalg.norm(P[ia] - a) > SNAP_TOL or np.linalg.norm(P[ib] - b) > SNAP_TOL:
                continue
            if c.closed:       # a loop: the shorter way round
                m = len(P)
                fwd = P[np.arange(ia, ia + (ib - ia) % m + 1) % m]
                bwd = P[np.arange(ia, ia - (ia - ib) % m - 1, -1) % m]
                piece = fwd if arc_length(fwd)[-1] <= arc_length(bwd)[-1] else bwd
            else:
                piece = P[ia:ib + 1] if ia <= ib else P[ib:ia + 1][::-1]
            piece = np.concatenate([[a], piece, [b]])
            if arc_length(piece)[-1] > MAX_DETOUR * np.linalg.norm(b - a):
                continue       # the section wanders (into a nostril and out again): not this one
            return resample_even(piece, SAMPLES)
    t = np.linspace(0, 1, SAMPLES)[:, None]
    return _project(V, F, a + t * (b - a))


def curve_set(V, F, landmarks):
    """{(from, to): polyline (SAMPLES,3)} for CURVES on the mesh (V (n,3), F) with landmark
    points ``landmarks`` {name: (3,)}."""
    N = vertex_normals(V, F)
    idx = closest_points(np.array([landmarks[k] for k in landmarks]), V, F)[0]
    normal = {k: N[F[t]].mean(0) for k, t in zip(landmarks, idx)}
    out = {}
    for a, b in CURVES:
        n = normal[a] + normal[b]
        out[(a, b)] = landmark_curve(V, F, landmarks[a], landmarks[b], n / max(np.linalg.norm(n), 1e-12))
    return out
