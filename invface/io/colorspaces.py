"""Colour spaces of plates: from a file's code values to invface's working space and back.

invface works in scene-linear light with Rec.709/sRGB primaries: the space of Eq. 14's albedo
and spherical-harmonics lighting and of Eq. 16's shading term. A plate's code values (floats,
integers scaled to [0, 1]) are converted from one of:

- ``sRGB``: the sRGB EOTF (colour-science). The default for 8- and 16-bit integer files (PNG,
  JPEG, TIFF, BMP, WebP, PPM/PGM) and for video.
- ``linear``: scene-linear Rec.709, taken as it is. The default for float files (EXR, float
  TIFF, HDR, PFM).
- ``Cineon``: Kodak's printing-density log (10-bit code 95 is black, 685 is white, 0.002
  density per code value, negative gamma 0.6), Rec.709 primaries assumed. The default for
  Cineon files and for DPX files whose header gives the transfer as printing density,
  logarithmic, user-defined or nothing; a DPX marked linear is read as ``linear`` and one
  marked ITU-R 709 as ``Camera Rec.709``.
- any colour space of OpenColorIO's built-in ACES studio config (``ACEScct``, ``ACEScg``,
  ``ARRI LogC3 (EI800)``, ``S-Log3 S-Gamut3``, ``Log3G10 REDWideGamutRGB`` ...; OCIO's
  aliases such as ``acescct_ap1`` too), converted by OCIO to ``Linear Rec.709 (sRGB)``.

    lin = to_linear(code, "ACEScct")      # float32 (..., 3)
    code = from_linear(lin, "ACEScct")
"""
from __future__ import annotations

import difflib
from functools import lru_cache

import numpy as np

from ..errors import ImageError

SRGB, LINEAR, CINEON = "sRGB", "linear", "Cineon"
OWN = (SRGB, LINEAR, CINEON)
OCIO_CONFIG = "ocio://studio-config-latest"
WORKING = "Linear Rec.709 (sRGB)"            # the OCIO name of invface's working space

# Kodak Cineon: 10-bit codes, 0.002 density per code, negative gamma 0.6, black 95, white 685.
_CIN_STEP, _CIN_BLACK, _CIN_WHITE = 0.002 / 0.6, 95.0, 685.0
_CIN_OFFSET = 10.0 ** ((_CIN_BLACK - _CIN_WHITE) * _CIN_STEP)


@lru_cache(maxsize=1)
def _config():
    try:
        import PyOpenColorIO as ocio
    except ImportError:
        return None
    return ocio.Config.CreateFromFile(OCIO_CONFIG)


def names():
    """The colour-space names ``--colorspace`` takes: invface's own three, then OCIO's."""
    cfg = _config()
    return list(OWN) + ([n for n in cfg.getColorSpaceNames() if "Display" not in n] if cfg else [])


def resolve(name, option="--colorspace"):
    """The canonical name of colour space ``name`` (case-insensitive; OCIO aliases allowed).
    Raises ImageError naming the option and the closest names for an unknown one."""
    key = str(name).strip()
    for own in OWN:
        if key.lower() == own.lower():
            return own
    cfg = _config()
    if cfg is not None:
        cs = cfg.getColorSpace(key)
        if cs is not None:
            return cs.getName()
    known = names()
    flat = lambda text: "".join(c for c in text.lower() if c.isalnum())
    near = [n for n in known if flat(key) in flat(n)][:4] or difflib.get_close_matches(key, known, n=4, cutoff=0.4)
    near = near or ["sRGB", "linear", "Cineon", "ACEScct"]
    where = "" if cfg is not None else " (OpenColorIO is not installed: pip install opencolorio)"
    raise ImageError(f"{option} {name}: unknown colour space{where}; did you mean "
                     f"{', '.join(repr(n) for n in near)}? (docs/formats.md lists them)")


def to_linear(code, name):
    """Code values (..., 3) float in colour space ``name`` -> scene-linear Rec.709 float32."""
    a = np.asarray(code, np.float64)
    space = resolve(name)
    if space == LINEAR:
        return a.astype(np.float32)
    if space == SRGB:
        import colour
        return np.asarray(colour.cctf_decoding(a, function="sRGB"), np.float32)
    if space == CINEON:
        lin = (10.0 ** ((a * 1023.0 - _CIN_WHITE) * _CIN_STEP) - _CIN_OFFSET) / (1.0 - _CIN_OFFSET)
        return lin.astype(np.float32)
    return _ocio(a, space, WORKING)


def from_linear(linear, name):
    """Scene-linear Rec.709 (..., 3) -> code values in colour space ``name`` (float32; the
    inverse of ``to_linear``; sRGB clips to [0, 1] first)."""
    a = np.asarray(linear, np.float64)
    space = resolve(name)
    if space == LINEAR:
        return a.astype(np.float32)
    if space == SRGB:
        import colour
        return np.asarray(colour.cctf_encoding(np.clip(a, 0, 1), function="sRGB"), np.float32)
    if space == CINEON:
        x = np.maximum(a * (1.0 - _CIN_OFFSET) + _CIN_OFFSET, 1e-10)
        return ((np.log10(x) / _CIN_STEP + _CIN_WHITE) / 1023.0).astype(np.float32)
    return _ocio(a, WORKING, space)


def _ocio(a, src, dst):
    cpu = _config().getProcessor(src, dst).getDefaultCPUProcessor()
    rgb = np.ascontiguousarray(a.reshape(-1, 3), np.float32)
    cpu.applyRGB(rgb)
    return rgb.reshape(a.shape)


def default_for(fmt, bits, is_float, attrs=None):
    """The colour space a file is read in without ``--colorspace``, and why (one phrase).

    fmt: OpenImageIO's format name ("dpx", "cineon", "openexr", "png", ...); bits: bits per
    sample; is_float: float pixels; attrs: header attributes ({"dpx:Transfer": ...})."""
    attrs = attrs or {}
    if fmt == "cineon":
        return CINEON, "a Cineon file is printing-density log"
    if fmt == "dpx":
        transfer = str(attrs.get("dpx:Transfer", "")).strip()
        if transfer.lower() == "linear":
            return LINEAR, "its DPX header says the transfer is linear"
        if transfer.lower().startswith("itu-r 709"):
            return "Camera Rec.709", "its DPX header says the transfer is ITU-R 709"
        return CINEON, f"a DPX file whose header's transfer is {transfer or 'not given'} is read as Cineon log"
    if is_float:
        return LINEAR, f"{bits}-bit float pixels are scene-linear"
    return SRGB, f"{bits}-bit integer pixels are sRGB-encoded"
