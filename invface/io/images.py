"""Images in and out, in linear light.

Inside invface images are linear-light float32 (H, W, 3). Files are read with OpenImageIO
(DPX, Cineon, EXR, TIFF 8/16/32-bit, PNG, JPEG, PPM/PGM, BMP, WebP, HDR), turned upright by
their EXIF orientation, and converted from their colour space to the working space by
``io.colorspaces`` (the default depends on the format and the header; ``colorspace`` names
another). Without OpenImageIO, OpenCV reads PNG and JPEG and OpenEXR reads EXR. Reports write
display-encoded pictures (``write_display_image``) and matplotlib figures (``save_figure``).
Every write is atomic.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import ImageError
from . import colorspaces
from .atomic import atomic_path, write_bytes

SRGB_EXTS = {".png", ".jpg", ".jpeg"}
EXTS = SRGB_EXTS | {".exr"}                                    # written by write_image
OIIO_EXTS = {".dpx", ".cin", ".tif", ".tiff", ".ppm", ".pgm", ".pnm", ".bmp", ".webp", ".hdr", ".pfm"}
READ_EXTS = EXTS | OIIO_EXTS                                   # read by read_image


def srgb_to_linear(a):
    """sRGB-encoded values in [0, 1] -> linear light (colour-science's sRGB EOTF)."""
    return colorspaces.to_linear(a, colorspaces.SRGB)


def linear_to_srgb(a):
    """Linear light -> sRGB-encoded values (clipped to [0, 1])."""
    return colorspaces.from_linear(a, colorspaces.SRGB)


def _check_complete(path, tail=65536):
    """Truncated PNG/JPEG files still half-decode; check their start and end markers. Only the
    file's first bytes and last ``tail`` bytes are read (all of it when those are zero padding):
    the decoder reads the file itself."""
    ext = path.suffix.lower()
    with open(path, "rb") as f:
        head = f.read(8)
        f.seek(max(f.seek(0, 2) - tail, 0))
        end = f.read()
        if not end.strip(b"\0"):
            f.seek(0)
            end = f.read()
    if ext == ".png" and (head != b"\x89PNG\r\n\x1a\n" or b"IEND" not in end[-64:]):
        raise ImageError(f"{path}: not a complete PNG file (truncated or corrupted)")
    if ext in (".jpg", ".jpeg") and (head[:2] != b"\xff\xd8" or b"\xff\xd9" not in end.rstrip(b"\0")[-16:]):
        raise ImageError(f"{path}: not a complete JPEG file (truncated or corrupted)")


@dataclass
class Decoded:
    """A file's pixels before colour conversion: code values (H, W, C) float32 (integers
    scaled to [0, 1] by their bit depth), channel names, the format's name, bits per sample,
    whether the samples are float, and the header's attributes."""

    pixels: np.ndarray
    channels: tuple
    format: str
    bits: int
    is_float: bool
    attrs: dict


def _decode_oiio(path, oiio):
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        raise ImageError(f"{path}: unreadable image file ({oiio.geterror().strip() or 'unknown format'})")
    try:
        spec, fmt = inp.spec(), inp.format_name()
        attrs = {a.name: a.value for a in spec.extra_attribs}
        is_float = spec.format.basetype in (oiio.FLOAT, oiio.HALF, oiio.DOUBLE)
        bits = int(attrs.get("oiio:BitsPerSample", spec.format.size() * 8))
        if int(attrs.get("Orientation", 1)) != 1:          # EXIF orientation: turn the image upright
            buf = oiio.ImageBufAlgo.reorient(oiio.ImageBuf(str(path)))
            px = buf.get_pixels(oiio.FLOAT)
        else:
            px = inp.read_image(0, 0, 0, spec.nchannels, oiio.FLOAT)
        if px is None:
            raise ImageError(f"{path}: unreadable {fmt} image ({inp.geterror().strip() or 'truncated or corrupted'})")
    finally:
        inp.close()
    px = np.asarray(px, np.float32).reshape(px.shape[0], px.shape[1], -1)
    if not is_float and bits < spec.format.size() * 8:   # 10/12-bit codes stored in 16 bits
        top = float(2 ** bits - 1)
        px = np.round(px * top) / top
    return Decoded(px, tuple(spec.channelnames), fmt, bits, is_float, attrs)


def _decode_fallback(path):
    """PNG/JPEG through OpenCV and EXR through OpenEXR, when OpenImageIO is not installed."""
    ext = path.suffix.lower()
    if ext == ".exr":
        import OpenEXR
        try:
            with OpenEXR.File(str(path), separate_channels=True) as f:
                ch = {k: np.asarray(v.pixels, np.float32) for k, v in f.channels().items()}
        except Exception as e:  # noqa: BLE001 - OpenEXR raises plain exceptions
            raise ImageError(f"{path}: unreadable EXR file ({e})") from None
        names = tuple(ch)
        return Decoded(np.stack([ch[n] for n in names], -1), names, "openexr", 32, True, {})
    if ext not in SRGB_EXTS:
        raise ImageError(f"{path}: reading '{ext}' files needs OpenImageIO (pip install openimageio)")
    import cv2
    img = cv2.imdecode(np.frombuffer(path.read_bytes(), np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None or img.size == 0:
        raise ImageError(f"{path}: unreadable image file")
    scale = {np.dtype(np.uint8): 255.0, np.dtype(np.uint16): 65535.0}.get(img.dtype)
    if scale is None:
        raise ImageError(f"{path}: unsupported pixel type {img.dtype} (8 or 16 bit expected)")
    img = img.astype(np.float32) / scale
    img = img[..., None] if img.ndim == 2 else img[..., [2, 1, 0, 3][:img.shape[2]]] if img.shape[2] >= 3 else img
    names = {1: ("Y",), 2: ("Y", "A"), 3: tuple("RGB"), 4: tuple("RGBA")}[img.shape[2]]
    return Decoded(img, names, ext.lstrip(".").replace("jpg", "jpeg"), int(scale).bit_length(), False, {})


def decode_image(path):
    """A file's pixels and header before colour conversion (``Decoded``). Raises ImageError
    naming the file for a missing, unsupported, truncated or unreadable one."""
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in READ_EXTS:
        raise ImageError(f"{path}: unsupported image type '{ext}' (read: {', '.join(sorted(READ_EXTS))})")
    if not path.is_file():
        raise ImageError(f"{path}: image file not found")
    if ext in SRGB_EXTS:
        _check_complete(path)
    try:
        import OpenImageIO as oiio
    except ImportError:
        return _decode_fallback(path)
    return _decode_oiio(path, oiio)


def header(path):
    """An image file's header attributes ({name: value}, OpenImageIO's names), read without
    its pixels; {} when OpenImageIO is not installed or cannot open the file."""
    try:
        import OpenImageIO as oiio
    except ImportError:
        return {}
    inp = oiio.ImageInput.open(str(path))
    if inp is None:
        oiio.geterror()
        return {}
    try:
        return {a.name: a.value for a in inp.spec().extra_attribs}
    finally:
        inp.close()


def _rgb_alpha(path, d):
    """(H, W, 3) colour and (H, W) alpha or None from the decoded channels, by name."""
    idx = {n.split(".")[-1].upper(): i for i, n in enumerate(d.channels)}
    px = d.pixels
    if all(c in idx for c in "RGB"):
        rgb = px[..., [idx["R"], idx["G"], idx["B"]]]
    elif "Y" in idx or px.shape[2] in (1, 2):
        rgb = np.repeat(px[..., idx.get("Y", 0)][..., None], 3, -1)
    elif px.shape[2] >= 3:
        rgb = px[..., :3]
    else:
        raise ImageError(f"{path}: no R, G, B or Y channels (has {', '.join(d.channels)})")
    return rgb, (px[..., idx["A"]] if "A" in idx else None)


@dataclass
class LinearImage:
    """An image read into the working space: rgb (H, W, 3) float32 linear, alpha (H, W) or
    None, the colour space it was read in, and why that one (``--colorspace``, or the
    format's default)."""

    rgb: np.ndarray
    alpha: np.ndarray | None
    colorspace: str
    reason: str


def load_image(path, colorspace=None):
    """Read an image file into linear light (``LinearImage``), converting from
    ``colorspace`` (a name ``io.colorspaces.resolve`` takes) or the file's default
    (``io.colorspaces.default_for``). Raises ImageError naming the file for unreadable,
    truncated or non-finite images."""
    path = Path(path)
    d = decode_image(path)
    if colorspace:
        space, why = colorspaces.resolve(colorspace), "given with --colorspace"
    else:
        space, why = colorspaces.default_for(d.format, d.bits, d.is_float, d.attrs)
    code, alpha = _rgb_alpha(path, d)
    rgb = colorspaces.to_linear(code, space)
    if not np.all(np.isfinite(rgb)):
        bad = int((~np.isfinite(rgb)).any(-1).sum())
        raise ImageError(f"{path}: {bad} pixels are not finite (NaN or Inf)")
    return LinearImage(np.ascontiguousarray(rgb, np.float32), alpha, space, why)


def read_image(path, colorspace=None):
    """Read an image as linear float32 RGB (H, W, 3), plus its alpha (H, W) or None
    (``load_image``)."""
    im = load_image(path, colorspace)
    return im.rgb, im.alpha


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
