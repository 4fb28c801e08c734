"""Image regions of a plate bounded by its curves, and a fit's image RMS in each.

    masks = curve_regions(curves, (H, W))        # {"mouth": (H, W) bool, "opening": ..., "eyes": ...}
    rms = region_rms(render, plate, curves)      # {"mouth": 0.118, "opening": 0.15, "eyes": 0.18}

The whole plate's image RMS is dominated by the cheeks and forehead; the mouth, where the two
model kinds differ most (the simulation keeps the lips' volume, the rig does not), is 1-3 % of
a face's pixels. Each region is the polygon of a pair of the plate's curves, the upper one
then the lower one reversed: the mouth inside the outer lip curves, its opening inside the
inner ones, the eyes' openings inside both lids' curves.
"""
from __future__ import annotations

import numpy as np

REGIONS = {"mouth": (("lip_outer_upper", "lip_outer_lower"),),
           "opening": (("lip_inner_upper", "lip_inner_lower"),),
           "eyes": (("eye_L_upper", "eye_L_lower"), ("eye_R_upper", "eye_R_lower"))}


def curve_regions(curves, shape):
    """{region: (H, W) bool} for the regions of ``REGIONS`` whose curve pairs are all in
    ``curves`` ({name: (n, 2) px, OpenCV convention: (0, 0) the top-left pixel's centre});
    shape (H, W). OpenCV's anti-aliased fill: a region holds its edge's pixels too (a
    rhombus of 400 px^2 fills 440 px)."""
    import cv2
    out = {}
    for region, pairs in REGIONS.items():
        if not all(up in curves and lo in curves for up, lo in pairs):
            continue
        m = np.zeros(shape, np.uint8)
        for up, lo in pairs:
            poly = np.concatenate([np.asarray(curves[up], float), np.asarray(curves[lo], float)[::-1]])
            cv2.fillPoly(m, [np.round(poly * 4).astype(np.int32)], 1, cv2.LINE_AA, shift=2)
        out[region] = m.astype(bool)
    return out


def region_rms(render, plate, curves):
    """{region: image RMS (linear)} of render - plate (H, W, 3) in each region of
    ``curve_regions`` that has pixels."""
    d = np.asarray(render, np.float64)[..., :3] - np.asarray(plate, np.float64)[..., :3]
    return {k: float(np.sqrt(np.mean(d[m] ** 2))) for k, m in curve_regions(curves, d.shape[:2]).items() if m.any()}
