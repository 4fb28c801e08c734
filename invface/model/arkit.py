"""ARKit's 52 face controls: their names, the map from a model's controls to them, and aliases.

ARKit (Apple's ARFaceAnchor blend shapes, also read and written by Live Link Face, MediaPipe
and MetaHuman) names 52 controls, each a value in [0, 1]. Left and Right are the actor's own
(+X in invface's model frame), as in ARKit. ``ARKIT_NAMES`` is in the order of a Live Link
Face recording.

A model's blendshapes reach ARKit by name:
- a shape named with an ARKit name is that control: the built-in head's 52 shapes
  (``template.arkit_shapes``) are named so;
- ICT-FaceKit's style, ``mouthSmile_L`` / ``_R``, is ``mouthSmileLeft`` / ``Right``;
- the FACS-style names of the built-in head before its ARKit shapes (``LEGACY``; actor bundles
  built then still carry them, and ``build-model --expressions simulate`` still makes them) map
  to one or two ARKit controls each: ``lipCornerPull_L`` is mouthSmileLeft; ``browDown`` drives
  browDownLeft and browDownRight (one to two); ``browInnerUp_L`` and ``_R`` together are ARKit's
  single browInnerUp (two to one: its value is their mean). ``lipsPart`` has no ARKit twin: it
  stays an extra on a model that has it, and a weight for it given to a model without it is
  read as the lips' parting controls (``READ_AS``).

The jaw is a bone with 6 DOF (``rig.JAW_NAMES``); four ARKit controls read it, 1.0 being the
jaw's bound in that direction:
- jawOpen = jaw_rx / rig.JAW_UPPER[0] (0.6 rad);
- jawLeft = jaw_tx / JAW_UPPER[3], jawRight = jaw_tx / JAW_LOWER[3] (+-8 mm along the jaw
  frame's x, the actor's left);
- jawForward = jaw_tz / JAW_UPPER[5] (8 mm along the jaw frame's z, out of the face).
The jaw's roll and yaw (jaw_ry, jaw_rz) and its vertical slide (jaw_ty) have no ARKit name; they
stay in fit.json's ``jaw``. The built-in head's blendshape named jawOpen is the soft tissue that
goes with an open jaw (its jaw pose is the fit's jaw_rx), so ARKit's jawOpen reads the jaw.

The eyeLook controls are blendshapes (the lids) that also turn the eyeballs (``model.gaze``);
tongueOut is a blendshape with no skin offset that moves the tongue (``model.tongue``). Controls
a model cannot make (those an old actor bundle lacks) are 0 in ``arkit_values`` and listed by
``unsupported``.
"""
from __future__ import annotations

import re

import numpy as np

from ..errors import ControlsError
from .rig import JAW_LOWER, JAW_UPPER

ARKIT_NAMES = (
    "eyeBlinkLeft", "eyeLookDownLeft", "eyeLookInLeft", "eyeLookOutLeft", "eyeLookUpLeft", "eyeSquintLeft",
    "eyeWideLeft", "eyeBlinkRight", "eyeLookDownRight", "eyeLookInRight", "eyeLookOutRight", "eyeLookUpRight",
    "eyeSquintRight", "eyeWideRight", "jawForward", "jawRight", "jawLeft", "jawOpen", "mouthClose",
    "mouthFunnel", "mouthPucker", "mouthRight", "mouthLeft", "mouthSmileLeft", "mouthSmileRight",
    "mouthFrownLeft", "mouthFrownRight", "mouthDimpleLeft", "mouthDimpleRight", "mouthStretchLeft",
    "mouthStretchRight", "mouthRollLower", "mouthRollUpper", "mouthShrugLower", "mouthShrugUpper",
    "mouthPressLeft", "mouthPressRight", "mouthLowerDownLeft", "mouthLowerDownRight", "mouthUpperUpLeft",
    "mouthUpperUpRight", "browDownLeft", "browDownRight", "browInnerUp", "browOuterUpLeft",
    "browOuterUpRight", "cheekPuff", "cheekSquintLeft", "cheekSquintRight", "noseSneerLeft",
    "noseSneerRight", "tongueOut",
)
JAW_CONTROLS = ("jawOpen", "jawLeft", "jawRight", "jawForward")

# the built-in head's FACS-style controls and the ARKit controls each one drives
LEGACY = {
    "browInnerUp_L": ("browInnerUp",), "browInnerUp_R": ("browInnerUp",),
    "browOuterUp_L": ("browOuterUpLeft",), "browOuterUp_R": ("browOuterUpRight",),
    "browDown": ("browDownLeft", "browDownRight"),
    "cheekRaise": ("cheekSquintLeft", "cheekSquintRight"),
    "noseWrinkle": ("noseSneerLeft", "noseSneerRight"),
    "upperLipRaise": ("mouthUpperUpLeft", "mouthUpperUpRight"),
    "lipCornerPull_L": ("mouthSmileLeft",), "lipCornerPull_R": ("mouthSmileRight",),
    "dimpler": ("mouthDimpleLeft", "mouthDimpleRight"),
    "lipCornerDepress_L": ("mouthFrownLeft",), "lipCornerDepress_R": ("mouthFrownRight",),
    "lowerLipDepress": ("mouthLowerDownLeft", "mouthLowerDownRight"),
    "chinRaise": ("mouthShrugLower",),
    "lipPucker": ("mouthPucker",),
    "lipStretch": ("mouthStretchLeft", "mouthStretchRight"),
    "lipFunnel": ("mouthFunnel",),
    "lipPress": ("mouthPressLeft", "mouthPressRight"),
    "eyeBlink_L": ("eyeBlinkLeft",), "eyeBlink_R": ("eyeBlinkRight",),
}


# ARKit's opposite pairs: two controls that move the same tissue the opposite way along one
# direction (the eye up or down, in or out; the upper lid down in a blink and up in a wide eye;
# a mouth corner up in a smile and down in a frown; the outer brow down or up; the mouth to the
# actor's left or right). A face makes one of each pair at a time, so the fits' prior charges
# the part the two share (``fit.priors.opposite_rows``); without it the eyeLook controls'
# relieved prior lets a fit trace an eye's lids with its up and down shapes at once.
OPPOSITES = tuple(
    pair for side in ("Left", "Right") for pair in (
        (f"eyeLookUp{side}", f"eyeLookDown{side}"), (f"eyeLookIn{side}", f"eyeLookOut{side}"),
        (f"eyeBlink{side}", f"eyeWide{side}"), (f"mouthSmile{side}", f"mouthFrown{side}"),
        (f"browDown{side}", f"browOuterUp{side}"))) + (("mouthLeft", "mouthRight"),)


# old names with no ARKit twin, read on a model that lacks them as the controls that make the
# same motion (lipsPart: the lower lip down and the upper lip up, on both sides)
READ_AS = {"lipsPart": ("mouthLowerDownLeft", "mouthLowerDownRight", "mouthUpperUpLeft", "mouthUpperUpRight")}


def arkit_name(name):
    """The ARKit control a blendshape name means, or None: ARKit's own names, ICT-FaceKit's
    ``_L`` / ``_R`` style (``mouthSmile_L`` -> mouthSmileLeft, ``browInnerUp_L`` -> browInnerUp)
    and the built-in head's names with a single twin (``lipCornerPull_L`` -> mouthSmileLeft)."""
    if name in ARKIT_NAMES:
        return name
    twins = LEGACY.get(name)
    if twins is not None:
        return twins[0] if len(twins) == 1 else None
    m = re.fullmatch(r"(\w+?)_([LR])", name)
    if m:
        full = m.group(1) + ("Left" if m.group(2) == "L" else "Right")
        if full in ARKIT_NAMES:
            return full
        if m.group(1) in ARKIT_NAMES:             # ICT's browInnerUp_L / _R: one ARKit control
            return m.group(1)
    return None


def drives(name):
    """The ARKit controls (tuple) a blendshape name drives; empty for an extra (lipsPart)."""
    if name in LEGACY:
        return LEGACY[name]
    a = arkit_name(name)
    return () if a is None or a in JAW_CONTROLS else (a,)


def arkit_values(names, weights, jaw):
    """{ARKit name: value in [0, 1]} for all 52, from a model's blendshape names (K,), their
    weights (K,) and the jaw (6,) (``rig.JAW_NAMES``). Several shapes driving one control
    (browInnerUp_L and _R) give it their mean."""
    total = dict.fromkeys(ARKIT_NAMES, 0.0)
    count = dict.fromkeys(ARKIT_NAMES, 0)
    for n, w in zip(names, np.asarray(weights, float)):
        for a in drives(n):
            total[a] += float(w)
            count[a] += 1
    out = {a: total[a] / count[a] if count[a] else 0.0 for a in ARKIT_NAMES}
    j = np.asarray(jaw, float)
    out.update(jawOpen=j[0] / JAW_UPPER[0], jawLeft=j[3] / JAW_UPPER[3], jawRight=j[3] / JAW_LOWER[3],
               jawForward=j[5] / JAW_UPPER[5])
    return {a: round(float(np.clip(v, 0.0, 1.0)), 6) for a, v in out.items()}


def opposite_pairs(names):
    """(n, 2) int: the index pairs into ``names`` of blendshapes that drive the two controls of
    an ARKit opposite pair (``OPPOSITES``), by any name they answer to (``drives``)."""
    driven = [set(drives(n)) for n in names]
    pairs = [(i, j) for a, b in OPPOSITES for i, di in enumerate(driven) if a in di
             for j, dj in enumerate(driven) if b in dj and j != i]
    return np.array(sorted(set(pairs)), int).reshape(-1, 2)


def unsupported(names):
    """The ARKit controls (sorted) that no blendshape of ``names`` nor the jaw drives."""
    driven = {a for n in names for a in drives(n)} | set(JAW_CONTROLS)
    return sorted(set(ARKIT_NAMES) - driven)


def translate(weights, names):
    """Weights by a model's own blendshape names from weights by any names it answers to:
    its own, ARKit's, ICT-FaceKit's ``_L`` / ``_R`` and the built-in head's FACS-style ones, in
    either direction (old fit.json files on an ARKit-named model, ARKit names on the built-in
    head). A control that two of the given names drive takes their mean; one that drives two
    (browDown, from browDownLeft and browDownRight) takes the mean of those given. Raises
    ControlsError naming a name the model does not answer to."""
    names = list(names)
    known = set(names)
    by_arkit = {}
    for n in names:
        for a in drives(n):
            by_arkit.setdefault(a, []).append(n)
    sums, counts = {}, {}
    for k, v in weights.items():
        if k in known:
            targets = [k]
        else:
            targets = sorted({t for a in drives(k) or READ_AS.get(k, ()) for t in by_arkit.get(a, ())})
        if not targets:
            raise ControlsError(f"unknown blendshape '{k}'; the model has: {', '.join(sorted(known)) or 'none'} "
                                "(ARKit, ICT-style _L/_R and FACS-style names are accepted where they map)")
        for t in targets:
            sums[t] = sums.get(t, 0.0) + float(v)
            counts[t] = counts.get(t, 0) + 1
    return {t: sums[t] / counts[t] for t in sums}
