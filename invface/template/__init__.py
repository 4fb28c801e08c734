"""The built-in anatomical template head: ``invface.template.build(resolution=1.0)``."""
from .build import build, cache_path, generate, sizes

__all__ = ["build", "generate", "cache_path", "sizes"]
