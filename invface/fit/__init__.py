"""Fitting: lighting/albedo calibration (Eq. 14); scan and plate fits build on it."""

from .._lazy import submodules as _submodules  # noqa: E402

__getattr__ = _submodules(__name__, __path__)
