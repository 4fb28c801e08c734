"""Images in and out, in linear light.

Inside invface images are linear-light float32 (H, W, 3). PNG and JPEG (8 or 16 bit) are
decoded from sRGB through colour-science; EXR is already linear (OpenEXR). Reports write
display-encoded pictures (``write_display_image``) and matplotlib figures (``save_figure``).
Every write is atomic.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import ImageError
from .atomic import atomic_path, write_bytes

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
    if ext == ".exr":
        import OpenEXR
        hdr = {"compression": OpenEXR.ZIP_COMPRESSION, "type": OpenEXR.scanlineimage}
        names = "RGBA"[:img.shape[2]]
        with atomic_path(path) as tmp:
            OpenEXR.File(hdr, {c: np.ascontiguousarray(img[..., i]) for i, c in enumerate(names)}).write(str(tmp))
        return path
    enc = linear_to_srgb(img[..., :3])
    if img.shape[2] == 4:
        enc = np.concatenate([enc, np.clip(img[..., 3:], 0, 1)], -1)
    if bits == 16 and ext == ".png":
        out = (enc * 65535 + 0.5).astype(np.uint16)
    else:
        out = (enc * 255 + 0.5).astype(np.uint8)
    return _encode(path, out)


def _encode(path, rgb):
    """Encode integer RGB(A) pixels (H, W, 3|4) by the file's suffix (OpenCV) and write the
    file atomically."""
    import cv2
    out = rgb[..., [2, 1, 0, 3]] if rgb.shape[2] == 4 else rgb[..., ::-1]
    ok, buf = cv2.imencode(path.suffix.lower(), np.ascontiguousarray(out))
    if not ok:
        raise ImageError(f"{path}: OpenCV could not encode the image")
    write_bytes(path, buf.tobytes())
    return path


def write_display_image(path, image):
    """Write an image that is already display-encoded (sRGB): uint8 (H, W, 3|4), or float in
    [0, 1], as PNG or JPEG, atomically; returns the Path. Reports and previews use it."""
    path = Path(path)
    img = np.asarray(image)
    if img.ndim == 2:
        img = np.repeat(img[..., None], 3, -1)
    if img.ndim != 3 or img.shape[2] not in (3, 4):
        raise ImageError(f"{path}: expected an (H, W, 3|4) image, got shape {img.shape}")
    if path.suffix.lower() not in SRGB_EXTS:
        raise ImageError(f"{path}: a display image is PNG or JPEG, not '{path.suffix}'")
    if img.dtype != np.uint8:
        img = (np.clip(np.asarray(img, np.float64), 0, 1) * 255 + 0.5).astype(np.uint8)
    return _encode(path, img)


def save_figure(path, fig, **kwargs):
    """Save a matplotlib figure (format by suffix) atomically; returns the Path."""
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, **kwargs)
    return path
