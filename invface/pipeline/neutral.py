"""A shot's neutral frame and the actor's identity from it: the frame to calibrate on
(Eq. 14 once per shot) and the model adapted to the actor's face."""
from __future__ import annotations

from ..errors import InvfaceError
from .plates import _say


def pick_neutral(model, clip, candidates=8, lam=None, progress=None, face=0):
    """The clip's most neutral-looking frame to calibrate on (Eq. 14 once per shot): among up
    to ``candidates`` frames evenly spread over the selection, the one whose curve fit
    (Eq. 15, blendshape rig, ``pose_from_curves``) has the least expression: the sum of its
    weights plus 10 x its jaw opening (rad). Returns (Frame, its curves, their source, its
    PoseEstimate)."""
    from .plates import find_curves, pose_from_curves
    n = len(clip)
    positions = sorted({round(i * (n - 1) / max(candidates - 1, 1)) for i in range(min(candidates, n))})
    best = None
    for pos in positions:
        frame = next(clip.frames(pos, pos + 1))
        try:
            curves, source = find_curves(model, frame.plate, face=face)
        except InvfaceError as e:
            _say(progress, message=f"{frame.name}: not a calibration candidate ({e})")
            continue
        pose = pose_from_curves(model, frame.plate, curves, lam, source=source)
        score = float(pose.p[pose.vector.weights].sum() + 10 * max(pose.p[pose.vector.jaw][0], 0.0))
        _say(progress, message=f"{frame.name}: expression {score:.2f}")
        if best is None or score < best[0]:
            best = (score, frame, curves, source, pose)
    if best is None:
        raise InvfaceError(f"{clip.source}: no face found in the {len(positions)} frames tried for the calibration; "
                           "pass --calib or --neutral-frame")
    return best[1:]


def actor_identity(model, frame, curves, lam=None, pose=None, progress=None):
    """The model adapted to the actor of a shot from one neutral-looking frame's curves
    {name: (n,2) px}: the controls and pose of Eq. 15 (``pose``, a PoseEstimate, or fitted
    here), then a smooth neutral correction (``fit.identity.fit_identity``) carried into the
    anatomy (``morph.build.adapt_identity``). Returns (FaceModel, IdentityFit); the model is
    ``model`` itself when the correction is larger than ``IDENTITY_MAX_MM`` (not an identity:
    a wrong frame or wrong curves), with a message saying so."""
    from ..fit.identity import IDENTITY_MAX_MM, fit_identity
    from ..morph.build import adapt_identity
    from .plates import pose_from_curves
    pose = pose or pose_from_curves(model, frame.plate, curves, lam)
    fit = fit_identity(model, frame.plate.camera, curves, pose.p, pose.rotation, pose.translation)
    if fit.max_mm > IDENTITY_MAX_MM:
        _say(progress, message=f"{frame.name}: {fit.describe()}: more than {IDENTITY_MAX_MM:g} mm is no identity "
                               "correction; the model is used as it is")
        return model, fit
    _say(progress, message=f"{frame.name}: {fit.describe()}")
    return adapt_identity(model, fit.displacement, progress=lambda m: _say(progress, message=m)), fit
