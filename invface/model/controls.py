"""Animator controls ``w``: blendshape weights by name, 6-DOF jaw, rigid head pose."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import ControlsError
from .arkit import arkit_values, opposite_pairs, translate, unsupported
from .gaze import eye_angles


# one unit of each fit-vector entry (``FitVector.scales``): weight, jaw (3 rad, 3 m), head rotation
# (rad), head translation (m)
WEIGHT_SCALE, JAW_SCALES, ROTATION_SCALE, TRANSLATION_SCALE = 0.1, (0.01, 0.01, 0.01, 0.001, 0.001, 0.001), 0.01, 0.001


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

        names: the model's blendshape names; weights under other names are taken by their
        aliases (ARKit's names, ICT-FaceKit's _L/_R, the built-in head's FACS-style names:
        ``arkit.translate``), and rejected when they have none.
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
        for k, v in c.weights.items():
            if not np.isfinite(float(v)):
                raise ControlsError(f"blendshape weight '{k}' is not finite ({v})")
        if names is not None and not set(c.weights) <= set(names):
            c.weights = translate(c.weights, names)          # ARKit, ICT-style or FACS-style aliases
        return c

    def weight_vector(self, names):
        """Blendshape weights b (K,) in the order of ``names``."""
        return np.array([float(self.weights.get(n, 0.0)) for n in names])


JAW_SIZE = 6          # jaw: 3 rotations (rad) + 3 translations (m) about the jaw pivot
POSE_SIZE = 6         # rigid head pose: Euler XYZ (3, rad) + translation (3, m)


class FitVector:
    """The one owner of the fit vector's layout

        z = (b (K,) | jaw (6,) | rotation (3,) | translation (3,)),   p = z[:K+6]

    p (the first K+6 entries) is what a surface model takes (``FaceModel.surface_model``);
    z adds the rigid head pose x_R = R(rotation) x + translation. Packs and unpacks, names
    every entry, gives the fits' bounds and converts to and from the named dictionaries of
    ``fit.json`` and ``Controls``. Nothing else slices z or p by position.
    """

    def __init__(self, blendshape_names):
        from .rig import JAW_NAMES
        self.blendshape_names = list(blendshape_names)
        self.K = len(self.blendshape_names)
        self.P = self.K + JAW_SIZE                      # controls p = (b, jaw)
        self.size = self.P + POSE_SIZE                  # z = (p, rotation, translation)
        self.names = self.blendshape_names + list(JAW_NAMES) + \
            ["rotation_x", "rotation_y", "rotation_z", "translation_x", "translation_y", "translation_z"]
        self.weights = slice(0, self.K)
        self.jaw = slice(self.K, self.P)
        self.controls = slice(0, self.P)
        self.rotation = slice(self.P, self.P + 3)
        self.translation = slice(self.P + 3, self.size)
        self.pose = slice(self.P, self.size)
        self.opposites = opposite_pairs(self.blendshape_names)   # (n, 2) weight indices (``arkit.OPPOSITES``)

    @classmethod
    def of(cls, model):
        """The layout of a FaceModel's fits."""
        return cls(model.blendshape_names)

    def __eq__(self, other):
        return isinstance(other, FitVector) and other.blendshape_names == self.blendshape_names

    def __repr__(self):
        return f"FitVector(K={self.K}, size={self.size})"

    # -- packing ----------------------------------------------------------------------
    def pack(self, p=None, rotation=None, translation=None, weights=None, jaw=None):
        """z (size,) from controls p (K+6,) (or b = ``weights`` (K,) and ``jaw`` (6,)) and the
        pose; anything not given is zero."""
        z = np.zeros(self.size)
        if p is not None:
            z[self.controls] = self._checked(p, self.P, "controls p")
        if weights is not None:
            z[self.weights] = self._checked(weights, self.K, "blendshape weights")
        if jaw is not None:
            z[self.jaw] = self._checked(jaw, JAW_SIZE, "jaw")
        if rotation is not None:
            z[self.rotation] = self._checked(rotation, 3, "rotation")
        if translation is not None:
            z[self.translation] = self._checked(translation, 3, "translation")
        return z

    def unpack(self, z):
        """(p (K+6,), rotation (3,), translation (3,)) copies from z (size,)."""
        z = self._checked(z, self.size, "fit vector z")
        return z[self.controls].copy(), z[self.rotation].copy(), z[self.translation].copy()

    def controls_vector(self, weights=None, jaw=None):
        """p (K+6,) from b (K,) and jaw (6,) (zeros where not given)."""
        return self.pack(weights=weights, jaw=jaw)[self.controls]

    def with_pose(self, z, rotation, translation):
        """z with its pose replaced."""
        z = np.array(z, float)
        z[self.rotation], z[self.translation] = rotation, translation
        return z

    def _checked(self, v, n, what):
        v = np.asarray(v, float).reshape(-1)
        if v.shape != (n,):
            raise ControlsError(f"{what}: expected {n} values, got {v.size}")
        return v

    # -- bounds and scales ----------------------------------------------------------------
    def bounds(self):
        """Box (lower (size,), upper (size,)) the fits keep to: blendshape weights in [0, 1];
        the jaw within its anatomical range (``rig.JAW_LOWER``/``JAW_UPPER``: opening
        -0.02..0.6 rad about the hinge, +-0.15 rad sideways and twist, +-8 mm translation but
        not up);
        the rigid pose free."""
        from .rig import JAW_LOWER, JAW_UPPER
        lo, hi = np.full(self.size, -np.inf), np.full(self.size, np.inf)
        lo[self.weights], hi[self.weights] = 0.0, 1.0
        lo[self.jaw], hi[self.jaw] = JAW_LOWER, JAW_UPPER
        return lo, hi

    def scales(self):
        """One unit of each entry for the optimisers' variables: weights 0.1, jaw rotations
        0.01 rad, jaw translations 1 mm, head rotation 0.01 rad, head translation 1 mm."""
        s = np.full(self.size, WEIGHT_SCALE)
        s[self.jaw] = JAW_SCALES
        s[self.rotation], s[self.translation] = ROTATION_SCALE, TRANSLATION_SCALE
        return s

    def hinge(self, z_or_p):
        """The jaw's opening about the hinge (rad): jaw[0]."""
        return float(np.asarray(z_or_p, float)[self.K])

    def with_hinge(self, z, angle):
        """z (or p) with the jaw's hinge opening set to ``angle`` (rad)."""
        z = np.array(z, float)
        z[self.K] = angle
        return z

    # -- names ----------------------------------------------------------------------------
    def weights_dict(self, z_or_p, digits=6):
        """{blendshape name: weight} of z or p."""
        b = np.asarray(z_or_p, float)[self.weights]
        return dict(zip(self.blendshape_names, np.round(b, digits).tolist()))

    def to_dict(self, z):
        """The named dictionary of ``fit.json``: weights by name, jaw (6), rotation (rad) and
        translation (m) of the head, and the 52 ARKit controls (``arkit.arkit_values``) with the
        ones this model cannot make (``arkit_unsupported``), and each eye's gaze, yaw and pitch
        in rad (``gaze.eye_angles``: yaw towards the actor's left, pitch up)."""
        p, rot, tr = self.unpack(z)
        eyes = eye_angles(self.blendshape_names, p[self.weights])
        return {"weights": self.weights_dict(p), "jaw": p[self.jaw].tolist(),
                "rotation": rot.tolist(), "translation": tr.tolist(),
                "eyes": {s: {"yaw": round(y, 6), "pitch": round(q, 6)} for s, (y, q) in eyes.items()},
                "arkit": arkit_values(self.blendshape_names, p[self.weights], p[self.jaw]),
                "arkit_unsupported": unsupported(self.blendshape_names)}

    def from_dict(self, d, what="controls"):
        """z from a dictionary as ``to_dict`` writes (or a Controls / a ground-truth file's dict);
        unknown blendshape names are a ControlsError naming ``what``."""
        try:
            c = Controls.coerce({k: d[k] for k in ("weights", "jaw", "rotation", "translation") if k in d},
                                self.blendshape_names)
        except ControlsError as e:
            raise ControlsError(f"{what}: {e}") from None
        return self.from_controls(c)

    def from_controls(self, c):
        """z from a Controls value (or a dict ``Controls.coerce`` accepts)."""
        c = Controls.coerce(c, self.blendshape_names)
        return self.pack(weights=c.weight_vector(self.blendshape_names), jaw=c.jaw,
                         rotation=c.rotation, translation=c.translation)

    def to_controls(self, z):
        """The Controls value of z."""
        p, rot, tr = self.unpack(z)
        return Controls(weights=self.weights_dict(p, digits=12), jaw=p[self.jaw], rotation=rot, translation=tr)
