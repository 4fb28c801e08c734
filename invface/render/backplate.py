"""What the plate shows behind the head: the backplate of the shading fit (Eq. 16).

The renderer composites the face over a backplate, so that silhouette derivatives see a
background. The plate itself is the wrong backplate: at the head's outline it already holds
the face, so a render at the true pose shows face-over-face where the plate shows
face-over-background, and the fit shrinks the head (moves it away from the camera) to hide
the difference: with the plate as backplate the image term is lowest behind the true depth,
with the true background at it. ``background_plate`` fills the pixels the head covers from
the background around them.
"""
from __future__ import annotations

import numpy as np


def head_silhouette(camera, x, triangles):
    """(H, W) bool: the pixels covered by the projection of the posed surface x (V, 3) m,
    triangles (F, 3), in the camera's full image (every triangle filled, so occlusion does
    not matter for the union)."""
    import cv2
    uv = camera.project(np.asarray(x, float))[0]
    shift = 4                                   # 1/16 px fixed point
    poly = np.round(uv[np.asarray(triangles)] * (1 << shift)).astype(np.int32)
    out = np.zeros((camera.height, camera.width), np.uint8)
    cv2.fillPoly(out, list(poly), 1, lineType=cv2.LINE_8, shift=shift)
    return out.astype(bool)


def background_plate(image, covered, grow_px=None):
    """The linear plate (H, W, 3) with the pixels in ``covered`` (H, W) bool, grown by
    ``grow_px`` (default: 3 % of the covered region's larger side, at least 3 px: the head's
    anti-aliased edge and the pose changes of a fit), filled in from the surrounding pixels
    (OpenCV's Navier-Stokes inpainting, per channel, in float32: its Telea method is wrong on
    float images in OpenCV 5.0). Returns (H, W, 3) float32."""
    import cv2
    img = np.ascontiguousarray(image, np.float32)
    covered = np.asarray(covered, bool)
    if not covered.any():
        return img.copy()
    if grow_px is None:
        ys, xs = np.nonzero(covered)
        grow_px = max(3, int(round(0.03 * max(np.ptp(xs), np.ptp(ys)))))
    k = 2 * int(grow_px) + 1
    hole = cv2.dilate(covered.astype(np.uint8), cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (k, k)))
    if hole.all():
        return img.copy()
    return np.stack([cv2.inpaint(img[..., c], hole, 3, cv2.INPAINT_NS) for c in range(img.shape[2])], -1)
