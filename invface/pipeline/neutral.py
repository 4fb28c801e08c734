"""A shot's neutral frame and the actor's identity from it: the frame to calibrate on
(Eq. 14 once per shot) and the model adapted to the actor's face."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InvfaceError
from .plates import _say


# how much a shut eye counts against a calibration candidate, in the score's units (a weight
# of 1): the albedo under shut lids is the lids', and the identity's eye curves are a slit
EYES_SHUT_COST = 2.0
MIN_VIEW_ANGLE = 0.1    # rad: frames whose heads turn less than this from each other are one view (distinct_views)


def neutral_score(pose, peer=None):
    """A calibration candidate's expression: the sum of its curve fit's weights, plus 10 x its
    jaw opening (rad), plus EYES_SHUT_COST x the detector's own mean eyeBlink score (``peer``,
    MediaPipe's {name: [0, 1]}, when it found the curves). Returns (score, its parts)."""
    parts = {"weights": float(pose.p[pose.vector.weights].sum()),
             "jaw": 10 * max(float(pose.p[pose.vector.jaw][0]), 0.0)}
    if peer and "eyeBlinkLeft" in peer and "eyeBlinkRight" in peer:
        parts["eyes shut"] = EYES_SHUT_COST * 0.5 * (float(peer["eyeBlinkLeft"]) + float(peer["eyeBlinkRight"]))
    return sum(parts.values()), parts


@dataclass(eq=False)
class Candidate:
    """A frame looked at for the calibration: the clip's Frame, its curves {name: (n, 2) px},
    their source, and its curve fit's PoseEstimate (Eq. 15)."""
    frame: object
    curves: dict
    source: str
    pose: object


def pick_neutral(model, clip, candidates=8, lam=None, progress=None, face=0, over="the selected frames"):
    """The clip's most neutral-looking frame to calibrate on (Eq. 14 once per shot): among up
    to ``candidates`` frames evenly spread over ``clip`` (the frames asked for, or the whole
    shot: ``over`` names which, for the sentence), the one of least ``neutral_score``: its
    curve fit's (Eq. 15, blendshape rig, ``pose_from_curves``) expression and jaw, and its eyes
    shut. Returns (the chosen Candidate, a sentence saying why it was chosen, every Candidate
    in which a face was found, in clip order)."""
    from .plates import find_curves, pose_from_curves
    n = len(clip)
    looked = min(candidates, n)                     # a clip shorter than that: every frame
    positions = sorted({round(i * (n - 1) / max(looked - 1, 1)) for i in range(looked)})
    best, seen = None, []
    for pos in positions:
        frame = next(clip.frames(pos, pos + 1))
        try:
            curves, source = find_curves(model, frame.plate, face=face)
        except InvfaceError as e:
            _say(progress, message=f"{frame.name}: not a calibration candidate ({e})")
            continue
        seen.append(Candidate(frame, curves, source, pose_from_curves(model, frame.plate, curves, lam, source=source)))
        score, parts = neutral_score(seen[-1].pose, frame.plate.peer_arkit)
        _say(progress, message=f"{frame.name}: expression {score:.2f} ("
                               + ", ".join(f"{k} {v:.2f}" for k, v in parts.items()) + ")")
        if best is None or score < best[0]:
            best = (score, seen[-1], parts)
    if best is None:
        raise InvfaceError(f"{clip.source}: no face found in the {len(positions)} frames tried for the calibration; "
                           "pass --calib or --neutral-frame")
    score, chosen, parts = best
    why = (f"the most neutral-looking of {len(seen)} frames spread over {over} (expression {score:.2f}: "
           + ", ".join(f"{k} {v:.2f}" for k, v in parts.items()) + ")")
    return chosen, why, seen


def distinct_views(chosen, others, angle=MIN_VIEW_ANGLE):
    """The Candidates among ``others`` that show the head from another side: in their order,
    each kept where its head rotation differs from the ``chosen`` Candidate's and from every
    one kept before by at least ``angle`` rad. A frame seen from the same side adds no view of
    the depth, only its expression, which an identity shared with it takes up."""
    from ..model.rig import euler_xyz
    kept, seen = [], [euler_xyz(np.asarray(chosen.pose.rotation, float))]
    for c in others:
        R = euler_xyz(np.asarray(c.pose.rotation, float))
        if all(_angle(R, S) >= angle for S in seen):
            kept.append(c)
            seen.append(R)
    return kept


def _angle(R, S):
    """The angle (rad) of the rotation between R and S (3,3)."""
    return float(np.arccos(np.clip((np.trace(R.T @ S) - 1) / 2, -1.0, 1.0)))


def _view(plate, curves, pose):
    """The IdentityView of a frame's ``plate``, its curves {name: (n,2) px} and its
    PoseEstimate: the plate's camera, the curves, the controls and the pose."""
    from ..fit.identity import IdentityView
    return IdentityView(plate.camera, curves, pose.p, pose.rotation, pose.translation)


def actor_identity(model, frame, curves, lam=None, pose=None, progress=None, space=False, others=()):
    """The model adapted to the actor of a shot from one neutral-looking frame's curves
    {name: (n,2) px}: the controls and pose of Eq. 15 (``pose``, a PoseEstimate, or fitted
    here), then a smooth neutral correction (``fit.identity.fit_identity_views``) carried into
    the anatomy (``morph.build.adapt_identity``). With ``space`` the correction starts in the
    face-shape space and is shared with the frames ``others`` (Candidates: each with its own
    controls and pose; several head poses pin the depth one view cannot). The detector's own
    offsets from the model's curves (``fit.identity.detector_bias``) are not taken off: on
    faces with a 3D truth they took the fitted face further from it (``bench/identity_3d.py``).
    Returns (FaceModel, IdentityFit); the model is ``model`` itself when the correction is
    larger than ``IDENTITY_MAX_MM`` (not an identity: a wrong frame or wrong curves), with a
    message saying so."""
    from ..fit.identity import IDENTITY_MAX_MM, fit_identity_views
    from ..morph.build import adapt_identity
    from .plates import pose_from_curves
    pose = pose or pose_from_curves(model, frame.plate, curves, lam)
    views = [_view(frame.plate, curves, pose)] + [_view(c.frame.plate, c.curves, c.pose) for c in others if space]
    fit = fit_identity_views(model, views, space=space)
    if fit.max_mm > IDENTITY_MAX_MM:
        _say(progress, message=f"{frame.name}: {fit.describe()}: more than {IDENTITY_MAX_MM:g} mm is no identity "
                               "correction; the model is used as it is")
        return model, fit
    _say(progress, message=f"{frame.name}: {fit.describe()}")
    return adapt_identity(model, fit.displacement, progress=lambda m: _say(progress, message=m)), fit
