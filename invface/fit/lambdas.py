"""The weights of the paper's objectives (paper 000), one meaning per name, and their
scaling with the face's size in a plate.

Eq. 13 (scan):       |F* - x_R(w)|^2 + EQ13_LAMBDA |w|^2                       (m^2)
Eq. 14 (calibration): |F* - F(gamma, c)|^2 + EQ14_LAMBDA |L c|^2               (pixels, vertices)
Eq. 15 (curves):     |E_1(w^)|^2 + EQ15_LAMBDA_1 |w^|^2                         (px^2)
Eq. 16 (shading):    |E_2|^2 + EQ16_LAMBDA_1 |E_1|^2 + EQ16_LAMBDA_2 |w - w^|^2 (linear light)
sequence frames:     Eq. 15 + TEMPORAL_LAMBDA |(z - z_prev) / scales|^2                (px^2)
                     Eq. 16 + EQ16_TEMPORAL TEMPORAL_LAMBDA |(z - z_prev) / scales|^2  (linear light)

The plate weights are the paper's for its plates, except EQ16_LAMBDA_1 (below). Eq. 15's
residuals are pixels and Eq. 14's data term sums over the face's pixels, so both grow with
the face's area in the image:
``face_scale`` gives (d / SAMPLE_EYE_PX)^2 for a face d px between the outer eye corners,
224 px on the sample plates, where the paper's values were checked.
"""
from __future__ import annotations

import numpy as np

EQ13_LAMBDA = 1e-6          # scan fit: weight regulariser (m^2 per unit weight^2)
EQ14_LAMBDA = 2500.0        # calibration: albedo smoothness
EQ15_LAMBDA_1 = 3600.0      # curve fit: weight regulariser (px^2 per unit weight^2)
EQ15_TRACK_LAMBDA = 1.0     # curve fit's pose pass (ours, not the paper's): a weak regulariser,
                            # so the pose does not explain the expression
EQ15_ANCHOR_LAMBDA = 1.0    # curve fit's pose pass (ours): the head translation held near a calibration frame's,
                            # px^2 per mm^2 (``fit.curves.pose_anchor``)
EQ16_LAMBDA_1 = 1e-2        # shading: weight of the curve term E_1 (px^2); the paper's 1e-4 is negligible
                            # against the image term in our units (linear light, whole pyramid): the shading
                            # stage then moves the lips off the curves without lowering the image RMS
                            # (bench/RESULTS.md)
EQ16_LAMBDA_2 = 1.0         # shading: pull towards the curve solution w^
TEMPORAL_LAMBDA = 1.0       # sequences (ours): |z - z_prev|^2 in FitVector.scales() units (0.1 weight,
                            # 0.01 rad, 1 mm) added to Eq. 15, px^2 per unit^2 (scaled with the face)
EQ16_TEMPORAL = 0.1         # sequences (ours): the temporal term in Eq. 16 at this times its Eq. 15 weight (linear
                            # light per px^2): it takes most of the jitter out of a clip without moving its curve
                            # or image RMS; without it the head's depth jumps frame to frame (bench/RESULTS.md)

SAMPLE_EYE_PX = 224.0       # outer eye-corner distance (px) on the sample plates (720x540, 30 deg)


def face_scale(curves):
    """(area factor (d / SAMPLE_EYE_PX)^2, d px) for plate curves {name: (n, 2) px} with the
    eyes' upper lids (their first points are the outer corners); (1.0, nan) without them."""
    if "eye_L_upper" not in curves or "eye_R_upper" not in curves:
        return 1.0, float("nan")
    d = float(np.linalg.norm(np.asarray(curves["eye_L_upper"])[0] - np.asarray(curves["eye_R_upper"])[0]))
    return (d / SAMPLE_EYE_PX) ** 2, d


def curve_lambda(curves, lam=None):
    """Eq. 15's lambda_1 (px^2 per unit weight^2) for plate curves {name: (n, 2) px}: ``lam`` when
    given, else EQ15_LAMBDA_1 scaled with the face's area in pixels (``face_scale``), so a face
    twice as wide in the image gets four times the weight, as its curve term does. The session
    layer (and so the CLI) resolves lambda_1 here; the fit layer's own default is still the
    unscaled EQ15_LAMBDA_1 (a face-scaled default there changes the tests' tuned plates)."""
    return float(lam) if lam is not None else EQ15_LAMBDA_1 * face_scale(curves)[0]
