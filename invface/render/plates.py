"""Film plates: reading and writing images in linear light, camera files and undistortion.

Inside invface images are linear-light float32 (H, W, 3). PNG and JPEG (8 or 16 bit) are
decoded from sRGB through colour-science; EXR is already linear (OpenEXR). A plate may have a
JSON camera file (``camera.Camera``); a plate with lens distortion is undistorted through
OpenCV before fitting, as in paper 000, and then uses the same K without distortion.

    plate = load_plate("frame0001.png", camera="cam.json")   # undistorted, linear
    plate.image (H, W, 3) float32; plate.camera; plate.mask (H, W) bool or None
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import CameraError, ImageError
from .camera import Camera

SRGB_EXTS = {".png", ".jpg", ".jpeg"}
EXTS = SRGB_EXTS | {".exr"}


def srgb_to_linear(a):
    """sRGB-encoded values in [0, 1] -> linear light (colour-science's sRGB EOTF)."""
    import colour
    return np.asarray(colour.cctf_decoding(np.asarray(a, np.float64), function="sRGB"), np.float32)


def linear_to_srgb(a):
    """Linear light -> sRGB-encoded values (clipped to [0, 1])."""
    import colour
    return np.asarray(colour.cctf_encoding(np.clip(np.asarray(a, np.float64), 0, 1), function="sRGB"),
                      np.float32)


def _check_complete(path, data):
    """Truncated PNG/JPEG files still half-decode in OpenCV; check their end markers."""
    ext = path.suffix.lower()
    if ext == ".png" and (data[:8] != b"\x89PNG\r\n\x1a\n" or b"IEND" not in data[-64:]):
        raise ImageError(f"{path}: not a complete PNG file (truncated or corrupted)")
    if ext in (".jpg", ".jpeg") and (data[:2] != b"\xff\xd8" or b"\xff\xd9" not in data.rstrip(b"\0")[-16:]):
        raise ImageError(f"{path}: not a complete JPEG file (truncated or corrupted)")


def read_image(path):
    """Read an image as linear float32 RGB (H, W, 3), plus its alpha (H, W) or None.

    PNG/JPEG (8/16-bit, grey or colour) are sRGB-decoded; EXR channels R, G, B (and A) are
    taken as linear. Raises ImageError naming the file for unreadable, truncated or
    non-finite images."""
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in EXTS:
        raise ImageError(f"{path}: unsupported image type '{ext}' (use PNG, JPEG or EXR)")
    if not path.is_file():
        raise ImageError(f"{path}: image file not found")
    alpha = None
    if ext == ".exr":
        import OpenEXR
        try:
            with OpenEXR.File(str(path), separate_channels=True) as f:
                ch = {k: np.asarray(v.pixels, np.float32) for k, v in f.channels().items()}
        except Exception as e:  # noqa: BLE001 - OpenEXR raises plain exceptions
            raise ImageError(f"{path}: unreadable EXR file ({e})") from None
        if all(k in ch for k in "RGB"):
            rgb = np.stack([ch["R"], ch["G"], ch["B"]], -1)
        elif "Y" in ch:
            rgb = np.repeat(ch["Y"][..., None], 3, -1)
        else:
            raise ImageError(f"{path}: EXR has no R, G, B or Y channels (has {sorted(ch)})")
        alpha = ch.get("A")
    else:
        import cv2
        data = path.read_bytes()
        _check_complete(path, data)
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        if img is None or img.size == 0:
            raise ImageError(f"{path}: unreadable image file")
        scale = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}.get(img.dtype)
        if scale is None:
            raise ImageError(f"{path}: unsupported pixel type {img.dtype} (8 or 16 bit expected)")
        img = img.astype(np.float32) / scale
        if img.ndim == 2:
            img = np.repeat(img[..., None], 3, -1)
        elif img.shape[2] == 4:
            alpha = img[..., 3]
            img = img[..., 2::-1]
        else:
            img = img[..., 2::-1] if img.shape[2] == 3 else np.repeat(img[..., :1], 3, -1)
        rgb = srgb_to_linear(img)
    if not np.all(np.isfinite(rgb)):
        bad = int((~np.isfinite(rgb)).any(-1).sum())
        raise ImageError(f"{path}: {bad} pixels are not finite (NaN or Inf)")
    return np.ascontiguousarray(rgb, np.float32), alpha


def write_image(path, image, bits=8):
    """Write a linear float image (H, W, 3|4) as EXR (float32, exact) or sRGB PNG/JPEG.

    The file appears atomically (temporary file, then rename)."""
    path = Path(path)
    ext = path.suffix.lower()
    img = np.asarray(image, np.float32)
    if img.ndim != 3 or img.shape[2] not in (3, 4):
        raise ImageError(f"{path}: expected an (H, W, 3|4) image, got shape {img.shape}")
    if ext not in EXTS:
        raise ImageError(f"{path}: unsupported image type '{ext}' (use PNG, JPEG or EXR)")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.stem}.tmp{ext}")
    if ext == ".exr":
        import OpenEXR
        hdr = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
        names = "RGBA"[:img.shape[2]]
        OpenEXR.File(hdr, {c: np.ascontiguousarray(img[..., i]) for i, c in enumerate(names)}).write(str(tmp))
    else:
        import cv2
        enc = linear_to_srgb(img[..., :3])
        if img.shape[2] == 4:
            enc = np.concatenate([enc, np.clip(img[..., 3:], 0, 1)], -1)
        if bits == 16 and ext == ".png":
            out = (enc * 65535 + 0.5).astype(np.uint16)
        else:
            out = (enc * 255 + 0.5).astype(np.uint8)
        out = out[..., [2, 1, 0, 3]] if out.shape[2] == 4 else out[..., ::-1]
        ok, buf = cv2.imencode(ext, np.ascontiguousarray(out))
        if not ok:
            raise ImageError(f"{path}: OpenCV could not encode the image")
        tmp.write_bytes(buf.tobytes())
    os.replace(tmp, path)
    return path


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
    """A plate ready to fit: linear image (H, W, 3), undistorted camera, optional mask."""

    image: np.ndarray
    camera: Camera
    path: str = ""
    mask: np.ndarray | None = None


def load_plate(path, camera=None):
    """Read a plate and its camera (a Camera, a JSON path, or None: the sidecar
    ``<plate>.json`` if present, else the default front view at the plate's size),
    check that they agree and undistort."""
    path = Path(path)
    image, alpha = read_image(path)
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
    image, camera = undistort(image, camera)
    return Plate(image=image, camera=camera, path=str(path), mask=mask)
