"""Film plates: an image in linear light (``io.images.load_image``), its camera and undistortion.

Inside invface images are linear-light float32 (H, W, 3). A plate may have a
JSON camera file (``camera.Camera``); a plate with lens distortion is undistorted through
OpenCV before fitting, as in paper 000, and then uses the same K without distortion.

    plate = load_plate("frame0001.png", camera="cam.json")   # undistorted, linear
    plate.image (H, W, 3) float32; plate.camera; plate.mask (H, W) bool or None
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import CameraError, ImageError
# the image readers and writers live in io.images; they stay importable from here, where
# users' scripts found them
from ..io.images import EXTS, SRGB_EXTS, linear_to_srgb, load_image, read_image, srgb_to_linear, write_image  # noqa: F401
from .camera import Camera


def undistort(image, camera: Camera):
    """Remove lens distortion (OpenCV) from a linear image; returns (image, camera without
    distortion, same K)."""
    import cv2
    if not np.any(camera.dist):
        return image, camera
    h, w = image.shape[:2]
    m1, m2 = cv2.initUndistortRectifyMap(camera.K, camera.dist, None, camera.K, (w, h), cv2.CV_32FC1)
    out = cv2.remap(np.ascontiguousarray(image, np.float32), m1, m2, cv2.INTER_LINEAR,
                    borderMode=cv2.BORDER_REPLICATE)
    return out.reshape(image.shape), camera.undistorted


@dataclass
class Plate:
    """A plate ready to fit: linear image (H, W, 3), undistorted camera, optional mask, and the
    landmark detector's own ARKit scores when it found the plate's curves ({name: [0, 1]}:
    MediaPipe's estimate, a peer's, not truth) and the colour space its file was read in
    (``io.colorspaces``; "" when the image came from memory)."""

    image: np.ndarray
    camera: Camera
    path: str = ""
    mask: np.ndarray | None = None
    peer_arkit: dict | None = None
    colorspace: str = ""


def load_plate(path, camera=None, colorspace=None):
    """Read a plate and its camera (a Camera, a JSON path, or None: the sidecar
    ``<plate>.json`` if present, else the default front view at the plate's size),
    check that they agree and undistort. colorspace: the file's colour space
    (``io.colorspaces.resolve``; None: the format's default, ``io.colorspaces.default_for``)."""
    path = Path(path)
    read = load_image(path, colorspace)
    image, alpha = read.rgb, read.alpha
    h, w = image.shape[:2]
    if camera is None:
        side = path.with_suffix(".json")
        camera = Camera.load(side) if side.is_file() else Camera.front_view(w, h)
    elif not isinstance(camera, Camera):
        camera = Camera.load(camera)
    if camera.size != (w, h):
        raise CameraError(f"{path}: plate is {w}x{h} px but its camera is "
                          f"{camera.width}x{camera.height}; use the camera calibrated for this plate")
    mask = None
    if alpha is not None:
        mask = undistort(alpha[..., None], camera)[0][..., 0] > 0.5
        if not mask.any():
            raise ImageError(f"{path}: its alpha channel is transparent everywhere, so no pixel is left to fit: "
                             "save the plate with the face opaque, or without an alpha channel")
    image, camera = undistort(image, camera)
    return Plate(image=image, camera=camera, path=str(path), mask=mask, colorspace=read.colorspace)
