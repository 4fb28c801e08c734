"""Animator controls ``w``: blendshape weights by name, 6-DOF jaw, rigid head pose."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import ControlsError


@dataclass
class Controls:
    """Controls w = (b, j) plus the rigid pose used by the renderer.

    weights: blendshape name -> weight (usually in [0, 1]).
    jaw: (6,) rotations (rad, about the jaw frame's x, y, z axes through the pivot) and
         translations (m, in the jaw frame). jaw[0] > 0 opens the mouth.
    rotation: (3,) Euler angles (rad, XYZ) of the rigid head pose; translation: (3,) m.
    """
    weights: dict = field(default_factory=dict)
    jaw: np.ndarray = field(default_factory=lambda: np.zeros(6))
    rotation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))

    @classmethod
    def coerce(cls, w, names=None):
        """Build Controls from None, a Controls, or a dict {name: weight, 'jaw': [...], ...}.

        names: the model's blendshape names; weights for other names are rejected.
        """
        if w is None:
            return cls()
        if isinstance(w, Controls):
            c = w
        elif isinstance(w, dict):
            w = dict(w)
            c = cls(jaw=np.asarray(w.pop("jaw", np.zeros(6)), float),
                    rotation=np.asarray(w.pop("rotation", np.zeros(3)), float),
                    translation=np.asarray(w.pop("translation", np.zeros(3)), float))
            c.weights = {str(k): v for k, v in w.pop("weights", {}).items()}
            c.weights.update({str(k): v for k, v in w.items()})
        else:
            raise ControlsError(f"controls must be a Controls or a dict, not {type(w).__name__}")
        for key, shape in (("jaw", (6,)), ("rotation", (3,)), ("translation", (3,))):
            v = np.asarray(getattr(c, key), float)
            if v.shape != shape:
                raise ControlsError(f"controls '{key}' must have shape {shape}, got {v.shape}")
            if not np.all(np.isfinite(v)):
                raise ControlsError(f"controls '{key}' has non-finite values: {v}")
            setattr(c, key, v)
        known = set(names or ())
        for k, v in c.weights.items():
            if names is not None and k not in known:
                raise ControlsError(f"unknown blendshape '{k}'; the model has: {', '.join(sorted(known)) or 'none'}")
            if not np.isfinite(float(v)):
                raise ControlsError(f"blendshape weight '{k}' is not finite ({v})")
        return c

    def weight_vector(self, names):
        """Blendshape weights b (K,) in the order of ``names``."""
        return np.array([float(self.weights.get(n, 0.0)) for n in names])
