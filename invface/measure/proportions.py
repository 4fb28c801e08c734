"""Facial proportions from landmarks, for comparing a model with a real head."""
from __future__ import annotations

import numpy as np

# name -> (kind, landmark names): 'dist' = 3D distance between two points (or pairs of
# points, averaged); 'dy' = vertical distance between two points.
MEASURES = {
    "inter-ocular distance": ("dist", [("eye_inner_L", "eye_inner_R")]),
    "eye width": ("dist", [("eye_inner_L", "eye_outer_L"), ("eye_inner_R", "eye_outer_R")]),
    "nose length (sellion-subnasale)": ("dist", [("nose_bridge", "subnasale")]),
    "nose width": ("dist", [("alar_L", "alar_R")]),
    "mouth width": ("dist", [("mouth_corner_L", "mouth_corner_R")]),
    "upper face height (glabella-subnasale)": ("dy", [("glabella", "subnasale")]),
    "lower face height (subnasale-chin)": ("dy", [("subnasale", "chin")]),
    "face width at cheekbones": ("dist", [("cheek_contour_L", "cheek_contour_R")]),
    "face width at jaw": ("dist", [("jaw_contour_L", "jaw_contour_R")]),
    "forehead height (glabella-top of head)": ("dy", [("top_of_head", "glabella")]),
}


def proportions(points):
    """Measures (metres) from ``points``: dict landmark name -> (3,) position."""
    out = {}
    for name, (kind, pairs) in MEASURES.items():
        vals = []
        for a, b in pairs:
            pa, pb = np.asarray(points[a], float), np.asarray(points[b], float)
            vals.append(np.linalg.norm(pa - pb) if kind == "dist" else abs(pa[1] - pb[1]))
        out[name] = float(np.mean(vals))
    return out


# ICT-FaceKit / Multi-PIE 68-point indices for the same landmarks (0-based).
MULTIPIE_68 = {
    "eye_inner_L": 42, "eye_inner_R": 39, "eye_outer_L": 45, "eye_outer_R": 36,
    "nose_bridge": 27, "subnasale": 33, "alar_L": 35, "alar_R": 31,
    "mouth_corner_L": 54, "mouth_corner_R": 48, "chin": 8,
    "cheek_contour_L": 15, "cheek_contour_R": 1, "jaw_contour_L": 12, "jaw_contour_R": 4,
}


def multipie_points(vertices, lm68):
    """Landmark positions of a 68-point annotated head (vertices (V,3) m, lm68 (68,) ids).

    The glabella is the midpoint of the inner brow points 21/22; the top of the head is the
    highest vertex.
    """
    pts = {k: vertices[lm68[i]] for k, i in MULTIPIE_68.items()}
    pts["glabella"] = 0.5 * (vertices[lm68[21]] + vertices[lm68[22]])
    pts["top_of_head"] = vertices[np.argmax(vertices[:, 1])]
    return pts
