"""Landmarks and feature curves of the template's render skin.

Landmarks follow paper 001 (Fig. 6: the 17 profile, eye, mouth, nose and head landmarks)
plus a few used for proportions. They are found by geometric rules on the generated mesh
(slit ends, profile extrema, silhouettes, grooves), not placed at fixed coordinates.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from . import grid
from .shape import MOUTH_Y, skin_field


def _dedupe(ids):
    ids = np.asarray(ids)
    keep = np.concatenate([[True], ids[1:] != ids[:-1]])
    return ids[keep]


def curve_from_points(tree, pts, step=0.0005):
    """Vertex polyline (n,) following the 3D polyline pts (m,3) through nearest vertices."""
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    s = np.concatenate([[0], np.cumsum(seg)])
    u = np.linspace(0, s[-1], max(int(s[-1] / step), 2) + 1)
    dense = np.stack([np.interp(u, s, pts[:, k]) for k in range(3)], 1)
    return _dedupe(tree.query(dense)[1])


# The jaw line, one side from the cheek to the chin's middle, points (m) on the skin: where the
# landmark detector's lower face oval lies on a render of this head at rest, seen from the front
# (``scripts/jaw_line.py``), so the model's curve and the detector's mean the same points. The
# detector draws the sides on the silhouette and the chin a few millimetres above its lower edge.
JAW_POINTS = np.array([(0.0685, -0.0173, 0.0228), (0.0639, -0.0367, 0.0245), (0.0573, -0.0517, 0.0353),
                       (0.0475, -0.0585, 0.0642), (0.0377, -0.0630, 0.0854), (0.0289, -0.0669, 0.0981),
                       (0.0201, -0.0712, 0.1023), (0.0114, -0.0736, 0.1037), (0.0, -0.0765, 0.1024)])


def frontal_curve(tree, xy):
    """Vertex polyline through the skin points seen from the front at xy (m,2)."""
    xy = np.asarray(xy, float)
    return curve_from_points(tree, grid.point_at(skin_field, xy[:, 0], xy[:, 1]))


def _mirror_xy(xy):
    return [(-x, y) for x, y in xy]


def profile_concavity(P, ids, h=0.002):
    """Turning of the profile P (n,3) towards the head at points ids, over ~h metres either side."""
    s = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(P[:, 1:], axis=0), axis=1))])
    out = []
    for i in ids:
        a = P[np.argmin(np.abs(s - (s[i] - h))), 1:]
        b = P[np.argmin(np.abs(s - (s[i] + h))), 1:]
        u, v = P[i, 1:] - a, b - P[i, 1:]
        out.append(u[0] * v[1] - u[1] * v[0])     # (y, z) cross product: > 0 turns inwards
    return np.array(out)


def find_features(fine, V):
    """(landmarks dict name -> vertex id, curves dict name -> vertex ids) on the fine skin.

    fine: the fine SkinGrid; V (Vf,3) its vertex positions.
    """
    ni, _ = fine.shape
    profile = fine.grid_index()[ni // 2, :]          # midline, bottom to top
    L = _feature_landmarks(fine, V, profile)
    return L, _feature_curves(fine, V, L, profile)


def _feature_landmarks(fine, V, profile):
    """The landmarks (name -> vertex id) on the fine skin: slit corners, the profile's points,
    the nostrils' rims, the silhouette's cheek and jaw points and the brows."""
    ni, _ = fine.shape
    idx = fine.grid_index()
    P = V[profile]
    L = {}
    mouth_up = fine.slit_vertices("mouth", "upper")
    L["mouth_corner_R"], L["mouth_corner_L"] = int(mouth_up[0]), int(mouth_up[-1])
    L["stomion"] = int(mouth_up[len(mouth_up) // 2])
    eL = fine.slit_vertices("eye_L", "upper")
    eR = fine.slit_vertices("eye_R", "upper")
    L["eye_inner_L"], L["eye_outer_L"] = int(eL[0]), int(eL[-1])
    L["eye_outer_R"], L["eye_inner_R"] = int(eR[0]), int(eR[-1])

    tip = int(np.argmax(P[:, 2]))
    L["nose_tip"] = int(profile[tip])
    above = np.nonzero((np.arange(len(P)) > tip) & (P[:, 1] < 0.06))[0]
    L["nose_bridge"] = int(profile[above[np.argmin(P[above, 2])]])          # sellion
    stom_y = V[L["stomion"], 1]
    # subnasale: the sharpest concave corner of the profile between the tip and the lip
    between = np.nonzero((np.arange(len(P)) < tip) & (P[:, 1] > stom_y + 0.006))[0]
    L["subnasale"] = int(profile[between[np.argmax(profile_concavity(P, between))]])
    below = np.nonzero(P[:, 1] < stom_y - 0.012)[0]
    chin = below[np.argmax(P[below, 2] - P[below, 1])]                       # most down-forward point
    L["chin"] = int(profile[chin])
    front = below[P[below, 2] > 0.0]
    L["neck_start"] = int(profile[front[np.argmin(np.abs(P[front, 1] - (P[chin, 1] - 0.02)))]])
    L["top_of_head"] = int(profile[np.argmax(P[:, 1])])
    brow = np.nonzero((P[:, 1] > 0.045) & (P[:, 1] < 0.075))[0]
    L["glabella"] = int(profile[brow[np.argmax(P[brow, 2])]])
    L["head_extreme_L"] = int(np.argmax(V[:, 0]))
    L["head_extreme_R"] = int(np.argmin(V[:, 0]))

    # nostril outer rims (Multi-PIE 31/35): on the row just above the subnasale, walking
    # out from the midline, past the nostril's depth minimum to the rim's depth maximum
    row = int(np.argmin(np.abs(P[:, 1] - (V[L["subnasale"], 1] + 0.004))))
    for side, cols in (("L", np.arange(ni // 2, ni)), ("R", np.arange(ni // 2, -1, -1))):
        z = V[idx[cols, row], 2]
        k = 1
        while k < len(z) - 1 and not (z[k] <= z[k - 1] and z[k] <= z[k + 1]):
            k += 1
        while k < len(z) - 1 and not (z[k] >= z[k - 1] and z[k] >= z[k + 1]):
            k += 1
        L[f"alar_{side}"] = int(idx[cols[k], row])

    for s in "LR":
        L[f"cheek_contour_{s}"] = _silhouette(V, 0.015, s)
        L[f"jaw_contour_{s}"] = _silhouette(V, -0.045, s)
        sx = 1 if s == "L" else -1
        m = (np.abs(V[:, 0] - sx * 0.030) < 0.002) & (V[:, 1] > 0.045) & (V[:, 1] < 0.075)
        cand = np.nonzero(m)[0]
        L[f"brow_{s}"] = int(cand[np.argmax(V[cand, 2])])
    return L


def _silhouette(V, y, side):
    """The skin's outermost vertex on ``side`` ("L": +X) at height ``y`` (m), in front."""
    m = (np.abs(V[:, 1] - y) < 0.0015) & (V[:, 2] > 0.03)
    cand = np.nonzero(m)[0]
    return int(cand[np.argmax(V[cand, 0])] if side == "L" else cand[np.argmin(V[cand, 0])])


def _feature_curves(fine, V, L, profile):
    """The feature curves (name -> vertex ids) on the fine skin: the slits' lids and inner
    lips, the outer lips, brows and jaw line as frontal curves, the nose's bridge and base,
    and the profile."""
    tree = cKDTree(V)
    P = V[profile]
    tip = int(np.argmax(P[:, 2]))
    C = {}
    C["lip_inner_upper"] = fine.slit_vertices("mouth", "upper")
    C["lip_inner_lower"] = fine.slit_vertices("mouth", "lower")
    for s in "LR":
        C[f"eye_{s}_upper"] = fine.slit_vertices(f"eye_{s}", "upper")
        C[f"eye_{s}_lower"] = fine.slit_vertices(f"eye_{s}", "lower")
    xc = abs(V[L["mouth_corner_L"], 0])
    xs = np.linspace(-xc, xc, 21)
    bow = 1 - (xs / xc) ** 2
    C["lip_outer_upper"] = frontal_curve(tree, np.stack([xs, MOUTH_Y + 0.0095 * bow ** 0.7
                                                         - 0.0012 * np.exp(-(xs / 0.004) ** 2)], 1))
    C["lip_outer_lower"] = frontal_curve(tree, np.stack([xs, MOUTH_Y - 0.0105 * bow ** 0.6], 1))
    brow_xy = [(0.012, 0.057), (0.022, 0.060), (0.033, 0.060), (0.045, 0.057), (0.052, 0.053)]
    C["brow_L"] = frontal_curve(tree, brow_xy)
    C["brow_R"] = frontal_curve(tree, _mirror_xy(brow_xy))
    bridge = np.nonzero((np.arange(len(P)) >= tip) & (P[:, 1] <= V[L["nose_bridge"], 1] + 1e-9))[0]
    C["nose_bridge"] = profile[bridge[::-1]]
    C["nose_base"] = curve_from_points(tree, V[[L["alar_R"], L["subnasale"], L["alar_L"]]])
    C["jaw_line"] = curve_from_points(tree, np.concatenate([JAW_POINTS * [-1, 1, 1], JAW_POINTS[::-1][1:]]))
    C["profile"] = profile
    return C
