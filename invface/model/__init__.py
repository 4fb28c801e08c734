"""The FaceModel data model, its .npz bundle and the hybrid blendshape rig."""
from .controls import Controls, FitVector
from .facemodel import FaceModel, register_surface_model
from .muscle import Muscle

__all__ = ["FaceModel", "Muscle", "Controls", "FitVector", "register_surface_model"]

from .._lazy import submodules as _submodules  # noqa: E402

__getattr__ = _submodules(__name__, __path__)
