"""The built-in anatomical template head: ``invface.template.build(resolution=1.0)``."""
from .build import build, cache_path, generate, sizes

__all__ = ["build", "generate", "cache_path", "sizes"]

from .._lazy import submodules as _submodules  # noqa: E402

__getattr__ = _submodules(__name__, __path__)
