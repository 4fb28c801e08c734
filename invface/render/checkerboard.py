"""Camera intrinsics from checkerboard photographs (OpenCV), for ``invface camera calibrate``."""
from __future__ import annotations

import numpy as np

from ..errors import CameraError
from .camera import Camera
from ..io.images import linear_to_srgb, read_image


def board_points(inner, square):
    """3D corner positions (N, 3) m of a board with ``inner`` = (columns, rows) inner corners."""
    cols, rows = inner
    g = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2)
    return np.hstack([g * square, np.zeros((len(g), 1))]).astype(np.float32)


def find_corners(gray8, inner):
    """Sub-pixel inner corners (N, 2) of a checkerboard in an 8-bit grey image, or None."""
    import cv2
    ok, corners = cv2.findChessboardCorners(gray8, tuple(inner),
                                            cv2.CALIB_CB_ADAPTIVE_THRESH | cv2.CALIB_CB_NORMALIZE_IMAGE)
    if not ok:
        return None
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    return cv2.cornerSubPix(gray8, corners, (5, 5), (-1, -1), crit).reshape(-1, 2)


def calibrate(paths, inner=(9, 6), square=0.025, distortion=True):
    """Estimate a Camera (K, distortion; extrinsics of the first view) from board images.

    Returns (camera, rms reprojection error in px, list of the images where the board was
    found). Raises CameraError when fewer than 3 images show the whole board."""
    import cv2
    obj, img_pts, used, size = [], [], [], None
    for p in paths:
        rgb, _ = read_image(p)
        h, w = rgb.shape[:2]
        if size is None:
            size = (w, h)
        elif size != (w, h):
            raise CameraError(f"{p}: image is {w}x{h} px, the others are {size[0]}x{size[1]}")
        gray = (linear_to_srgb(rgb).mean(-1) * 255 + 0.5).astype(np.uint8)
        c = find_corners(gray, inner)
        if c is not None:
            obj.append(board_points(inner, square))
            img_pts.append(c.astype(np.float32))
            used.append(str(p))
    if len(used) < 3:
        raise CameraError(f"the {inner[0]}x{inner[1]} inner-corner board was found in {len(used)} of "
                          f"{len(paths)} images; at least 3 views are needed (check --board)")
    flags = 0 if distortion else (cv2.CALIB_FIX_K1 | cv2.CALIB_FIX_K2 | cv2.CALIB_FIX_K3 |
                                  cv2.CALIB_ZERO_TANGENT_DIST)
    rms, K, dist, rvecs, tvecs = cv2.calibrateCamera(obj, img_pts, size, None, None, flags=flags)
    R = cv2.Rodrigues(rvecs[0])[0]
    cam = Camera(K=K, width=size[0], height=size[1], dist=dist.ravel()[:5], R=R, t=tvecs[0].ravel())
    return cam, float(rms), used
