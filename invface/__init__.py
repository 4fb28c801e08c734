"""invface: anatomically based, differentiable face capture.

Public API (stable names)::

    import invface
    model = invface.FaceModel.load("head.npz")
    model = invface.template.build(resolution=1.0)
    x = model.surface(w, kind="blendshape")
"""
from ._env import configure_llvm as _configure_llvm

_configure_llvm()

from .errors import InvfaceError  # noqa: E402
from .model import FaceModel, Muscle, Controls  # noqa: E402
from . import template  # noqa: E402

__version__ = "0.1.0"
__all__ = ["FaceModel", "Muscle", "Controls", "InvfaceError", "template", "__version__"]
