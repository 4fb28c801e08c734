"""The FaceModel data model, its .npz bundle and the hybrid blendshape rig."""
from .controls import Controls
from .facemodel import FaceModel, Muscle

__all__ = ["FaceModel", "Muscle", "Controls"]
