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
    MediaPipe's estimate, a peer's, not truth), the colour space its file was read in
    (``io.colorspaces``; "" when the image came from memory), and, for a plate fitted on a
    crop of its file (``crop_plate``), how the crop's pixels map back to the file's."""

    image: np.ndarray
    camera: Camera
    path: str = ""
    mask: np.ndarray | None = None
    peer_arkit: dict | None = None
    colorspace: str = ""
    crop: dict | None = None


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


def crop_plate(plate, box, scale=1.0):
    """The Plate of the pixels ``box`` = (x0, y0, x1, y1) of ``plate`` (ints, x1 and y1 left
    out), resized by ``scale`` (<= 1; OpenCV's area filter), its mask with it. The camera is
    moved and scaled to match, so every pixel keeps its ray: the same 3D camera. ``crop`` =
    {"origin": [x0, y0] px, "scale": [sx, sy], "size": [W, H] of the whole plate} maps a
    crop pixel back: u = (u' + 0.5) / sx - 0.5 + x0 (OpenCV's pixel centres)."""
    import cv2
    x0, y0, x1, y1 = (int(v) for v in box)
    w, h = max(1, round((x1 - x0) * scale)), max(1, round((y1 - y0) * scale))
    sx, sy = w / (x1 - x0), h / (y1 - y0)
    image = plate.image[y0:y1, x0:x1]
    if (w, h) != (x1 - x0, y1 - y0):
        image = cv2.resize(np.ascontiguousarray(image), (w, h), interpolation=cv2.INTER_AREA)
    mask = None
    if plate.mask is not None:
        mask = cv2.resize(plate.mask[y0:y1, x0:x1].astype(np.uint8), (w, h), interpolation=cv2.INTER_NEAREST) > 0
    cam = plate.camera
    K = cam.K.copy()
    K[0] = [K[0, 0] * sx, K[0, 1] * sx, (K[0, 2] - x0 + 0.5) * sx - 0.5]
    K[1] = [0.0, K[1, 1] * sy, (K[1, 2] - y0 + 0.5) * sy - 0.5]
    camera = Camera(K=K, width=w, height=h, dist=np.zeros(5), R=cam.R.copy(), t=cam.t.copy())
    crop = {"origin": [x0, y0], "scale": [sx, sy], "size": [int(cam.width), int(cam.height)]}
    return Plate(image=np.ascontiguousarray(image, np.float32), camera=camera, path=plate.path, mask=mask,
                 peer_arkit=plate.peer_arkit, colorspace=plate.colorspace, crop=crop)


def to_crop_pixels(points, crop):
    """Points (n, 2) in the whole plate's pixels -> the crop's (``crop_plate``'s ``crop``)."""
    return (np.asarray(points, float) - crop["origin"] + 0.5) * crop["scale"] - 0.5
