"""The FaceModel data model, its .npz bundle and the hybrid blendshape rig."""
from .controls import Controls, FitVector
from .facemodel import FaceModel, Muscle, register_surface_model

__all__ = ["FaceModel", "Muscle", "Controls", "FitVector", "register_surface_model"]
