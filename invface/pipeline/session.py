"""A fit-plate run's set-up, before its frames are fitted: the frame that stands for the shot
(the calibration's and the identity's), whether an earlier run in the output folder is resumed
or refused, and the actor's identity and the light and albedo, each reused from that run when
it made them from the same frame.

    frame = shot_frame(model, clip, whole=open_clip(path))
    model, calibration, record = prepare_run(model, frame, "take", calibration=None)
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from ..errors import InvfaceError
from .plates import _say


@dataclass
class ShotFrame:
    """The frame a run calibrates on and takes the actor's identity from: the clip's Frame, its
    curves {name: (n, 2) px} and their source, the curve fit's PoseEstimate when one was made
    to choose it (else None), why it was chosen (a phrase for run.json and the page), and the
    other frames looked at to choose it (``neutral.Candidate``s), which an identity in the
    face-shape space shares."""

    frame: object
    curves: dict
    source: str
    pose: object
    why: str
    others: tuple = ()


def shot_frame(model, clip, whole=None, neutral_frame=None, curves=None, face=0, lam=None, progress=None):
    """The frame that stands for the shot: the frame numbered ``neutral_frame`` among the
    clip's selected ones, the plate itself for a single plate, else the most neutral-looking of
    ``whole`` (the whole shot) or, without it, of the clip's selected frames
    (``neutral.pick_neutral``). curves: a curve file for a single plate (``find_curves``).
    Returns a ShotFrame."""
    from .neutral import pick_neutral
    from .plates import find_curves
    if neutral_frame is not None:
        numbers = [clip.numbers[i] for i in clip.indices]
        if neutral_frame not in numbers:
            raise InvfaceError(f"--neutral-frame {neutral_frame}: not among the selected frames "
                               f"({numbers[0]}..{numbers[-1]})")
        pos = numbers.index(neutral_frame)
        frame = next(clip.frames(pos, pos + 1))
        found, source = find_curves(model, frame.plate, curves, face=face, crop=len(clip) == 1)
        return ShotFrame(frame, found, source, None, "given with --neutral-frame")
    if len(clip) == 1:
        frame = next(clip.frames())
        found, source = find_curves(model, frame.plate, curves, face=face, crop=True)
        return ShotFrame(frame, found, source, None, "the plate itself")
    over = "the whole shot" if whole is not None else "the selected frames"
    _say(progress, message=f"picking the most neutral-looking frame of {over} to calibrate on")
    chosen, why, seen = pick_neutral(model, whole or clip, lam=lam, progress=progress, face=face, over=over)
    _say(progress, message=f"calibrating on {chosen.frame.name}: {why}")
    return ShotFrame(chosen.frame, chosen.curves, chosen.source, chosen.pose, why,
                     tuple(c for c in seen if c is not chosen))


def prepare_run(model, shot, out, calibration=None, identity=True, restart=False, lam=None, calibrate=None,
                progress=None, identity_space=False):
    """The model and calibration a run fits its frames with, and what run.json records of them.

    shot: the ShotFrame (None when neither is needed: a given ``calibration`` and no
    ``identity``). An ``out`` folder holding fits of an earlier run whose identity or
    calibration came from another frame is refused unless ``restart``. With ``identity`` the
    model is adapted to the shot frame's face (``neutral.actor_identity``) and saved as
    out/actor.npz, or that file is reused when the run being resumed made it from the same
    frames; the model is then read back from it, as a resumed run reads it; ``identity_space``:
    the adaptation starts in the face-shape space and is shared by the shot's other frames
    that show the head from another side (``neutral.actor_identity``, ``neutral.distinct_views``;
    run.json's identity_frames). Without a given
    ``calibration``, out/calib.npz is reused likewise or made by ``calibrate(model, plate,
    path, curves, source)`` (default: ``plates.auto_calibrate`` and save). Returns (model,
    Calibration or PlateCalibration, {run.json keys})."""
    from ..fit.calibrate import Calibration
    from ..report.runs import earlier_fits
    from .runs import read_run
    out = Path(out)
    record, frame = {}, shot.frame if shot is not None else None
    if shot is not None and shot.why:
        record["calibration_why"] = shot.why
    before = {} if restart else read_run(out)
    mine = {"identity_from": frame.digest if identity else None}
    shared = _views(shot) if identity and identity_space else []
    if identity_space:
        mine["identity_space"] = True
    if shared:
        mine["identity_frames"] = [c.frame.digest for c in shared]
    if calibration is None:
        mine["calibrated_on"] = frame.digest
    if earlier_fits(out) and any(before.get(k) != v for k, v in mine.items()) and not restart:
        raise InvfaceError(f"{out}: holds an earlier run's fits; pass --restart to replace them, or "
                           "choose another output folder")           # refused before any work is done
    if identity:
        model, record["identity"] = _identity(model, shot, out, before, lam, progress, identity_space, shared)
        record["identity_from"] = frame.digest
        record.update({k: v for k, v in mine.items() if k in ("identity_space", "identity_frames")})
    if calibration is None:
        saved = out / "calib.npz"
        if saved.is_file() and all(before.get(k) == v for k, v in mine.items()):
            _say(progress, message=f"reusing {saved}: calibrated on {frame.name} by the run being resumed")
            calibration = Calibration.load(saved, vertex_count=len(model.neutral))
        else:
            _say(progress, message=f"no calibration given: calibrating light and albedo on {frame.name} (Eq. 14)")
            calibration = (calibrate or _calibrate_and_save)(model, frame.plate, saved, shot.curves, shot.source)
        record.update(calibrated_on=frame.digest, calibration_frame=frame.name)
    return model, calibration, record


def _identity(model, shot, out, before, lam, progress, space=False, others=()):
    """(the model adapted to the shot frame's face, with ``space`` shared by the Candidates
    ``others`` (``_views``), and read back from out/actor.npz, the sentence run.json keeps),
    reusing the resumed run's actor.npz made from the same frames."""
    from ..model.facemodel import FaceModel
    from .neutral import actor_identity
    frame, actor = shot.frame, out / "actor.npz"
    same = (before.get("identity_from") == frame.digest and before.get("identity_space", False) == space
            and before.get("identity_frames", []) == [c.frame.digest for c in others])
    if actor.is_file() and same:
        _say(progress, message=f"reusing {actor}: the actor's identity from {frame.name}"
                               + (f" and {len(others)} other frame(s)" if others else "")
                               + ", made by the run being resumed")
        said = before.get("identity", "")
    else:
        names = frame.name + (f" and {len(others)} other frame(s) ({', '.join(c.frame.name for c in others)})"
                              if others else "")
        _say(progress, message=f"the actor's identity from the curves of {names}")
        adapted, fit = actor_identity(model, frame, shot.curves, lam=lam, pose=shot.pose, progress=progress,
                                      space=space, others=others)
        out.mkdir(parents=True, exist_ok=True)
        adapted.save(actor)
        if adapted is not model:
            from ..report.identity import NAME, write_identity_figure
            write_identity_figure(out / NAME, model.neutral, adapted.neutral, adapted.triangles, fit.coefficients)
        said = (f"The model was adapted to the face of {names} first ({fit.describe()}; {actor.name})"
                if adapted is not model else
                f"The model is used as it is: the identity fit on {names} moved it too far ({fit.describe()})")
    return FaceModel.load(actor), said           # as a resumed run reads it: the same bytes, the same run hash


def _views(shot):
    """The shot's other frames an identity in the face-shape space shares: those that show the
    head from another side than the shot frame and each other (``neutral.distinct_views``)."""
    from .neutral import Candidate, distinct_views
    if not shot.others or shot.pose is None:
        return []
    return distinct_views(Candidate(shot.frame, shot.curves, shot.source, shot.pose), shot.others)


def _calibrate_and_save(model, plate, path, curves, source):
    """Eq. 14 on a plate of unknown pose (``plates.auto_calibrate``), saved to ``path``."""
    from .plates import auto_calibrate
    result = auto_calibrate(model, plate, curves, source)
    result.save(path)
    return result
