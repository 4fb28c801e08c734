"""Mitsuba variant selection: ``cuda_ad_rgb`` when a GPU works, else ``llvm_ad_rgb``."""
from __future__ import annotations

import os

from .._env import configure_llvm
from ..errors import DependencyError

_MI = None


def mitsuba(variant: str | None = None):
    """Import Mitsuba once, select a variant and return the module.

    ``variant`` (or the INVFACE_VARIANT environment variable) forces one; otherwise CUDA is
    tried first and the LLVM CPU backend is the fallback.
    """
    global _MI
    if _MI is not None and variant is None:
        return _MI
    configure_llvm()
    try:
        import mitsuba as mi
    except ImportError as e:  # pragma: no cover - install problem
        raise DependencyError(f"mitsuba is not installed ({e}); run scripts/install.sh") from e
    wanted = variant or os.environ.get("INVFACE_VARIANT")
    candidates = [wanted] if wanted else ["cuda_ad_rgb", "llvm_ad_rgb"]
    errors = []
    for v in candidates:
        try:
            mi.set_variant(v)
            # a tiny allocation proves the backend really works
            mi.Float([0.0]).numpy()
            _MI = mi
            return mi
        except Exception as e:  # noqa: BLE001 - each backend fails differently
            errors.append(f"{v}: {e}")
    raise DependencyError("no usable Mitsuba variant (" + "; ".join(errors) + "). On Debian "
                          "install LLVM 19 (apt-get install libllvm19) or set DRJIT_LIBLLVM_PATH")
