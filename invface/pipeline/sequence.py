"""Fitting a plate sequence (a video, a folder of frames or one plate) frame by frame, with
checkpoints, resume, bad-frame flags and animation-curve output.

    clip = open_clip("take3.mp4", frames="0:72")
    frames = fit_sequence(model, clip, calibration, out="fit/take3", kinds="both")
    # fit/take3/<frame>/<kind>/fit.json, fit.npz and index.html, as each finishes
    # fit/take3/curves.csv, curves.json, overlay_<kind>.mp4 and index.html at the end

This module dispatches: the frame loop (``frames.fit_frames``) on this process, or the same
per-frame code on a Dask cluster, chunk by chunk (``distributed.fit_sequence_distributed``);
``runs`` keeps the run's bookkeeping and resume; ``outputs`` writes the curves, the Live Link Face CSV,
the videos and the page.
"""
from __future__ import annotations

from pathlib import Path

from ..errors import InvfaceError
from ..fit.lambdas import EQ16_TEMPORAL, TEMPORAL_LAMBDA
from .clips import open_clip
from .distributed import fit_sequence_distributed
from .frames import fit_frames
from .outputs import usd_suffix, write_arkit_csv, write_sequence_outputs, write_usd_takes
from .plates import _say, model_kinds
from .runs import finish_run, run_hash, start_run


def fit_sequence(model, frames, calibration, out=None, kinds=("blendshape",), curves=None, progress=None,
                 on_kind=None, on_frame=None, force=False, camera=None, select=None, keep=True, workers=None,
                 scheduler=None, extra=None, security=None, colorspace=None, exports=("csv", "usd"), usd_ascii=False,
                 **options):
    """Fit a plate sequence in order (``fit_frames``). frames: a Clip, a
    video, numbered sequence, folder or image path (``open_clip``, with ``select``
    "START:STOP[:STEP]" or "FIRST-LAST[xSTEP]", ``camera`` and ``colorspace``), or a list of
    plate paths; curves: for a single plate only (a sequence takes
    FRAME.curves.json beside each frame, or the detector, tracking frame to frame); out:
    see ``fit_frames``; an out folder with an earlier run's fits is resumed when they were
    made from the same inputs, refused otherwise unless ``force`` (``start_run``); then the
    sequence outputs (``write_sequence_outputs``); ``workers`` or ``scheduler``: on a Dask
    cluster (``distributed.fit_sequence_distributed``; needs ``out``; ``security``: a
    ``distributed.Security`` for a TLS scheduler); ``extra``: more keys for
    run.json; ``exports``: which of "csv" (Live Link Face) and "usd" (the take; text .usda with
    ``usd_ascii``) are written at the end (the rigs: ``outputs.export``). progress receives the fits' events, {"message": ...} for each step (a resumed
    run, the sequence files written) and, on a cluster, {"done": frames, "total": frames}.
    Returns the per-frame summaries of ``fit_frames``, each with its FrameFit as "fit" when
    fitted on this process and ``keep`` (a long clip's fits are on disk: their renders would
    fill the memory)."""
    clip = _clip(frames, select, camera, colorspace)
    if curves is not None and len(clip) > 1:
        raise InvfaceError("one curves file names one plate; in a sequence put FRAME.curves.json beside each "
                           "frame (or let the detector find each frame's curves)")
    kinds = model_kinds(kinds)
    options.setdefault("temporal", TEMPORAL_LAMBDA)
    options.setdefault("temporal_shading", EQ16_TEMPORAL)
    inputs = run_hash(model, calibration, dict(options, curves=str(curves) if curves is not None else None))
    extra = dict(extra or {}, **({"fps": float(clip.fps)} if clip.fps else {}))    # the exports' timecodes
    if out is not None and start_run(out, clip.names if len(clip) > 1 else [], kinds, force, inputs, extra):
        _say(progress, message=f"{out}: resuming the run there (same inputs): its finished frames are skipped")
    if (workers or scheduler) and len(clip) > 1:
        rows = fit_sequence_distributed(model, clip, calibration, out, kinds, inputs=inputs, workers=workers or 1,
                                        scheduler=scheduler, progress=progress, security=security, **options)
    else:
        rows = fit_frames(model, clip, calibration, out, kinds, curves=curves, inputs=inputs, keep=keep,
                          progress=progress, on_kind=on_kind, on_frame=on_frame, **options)
    if out is not None:
        finish_run(out)
        if len(clip) > 1:
            paths = write_sequence_outputs(out, kinds, fps=clip.fps, exports=exports,
                                           usd_suffix=usd_suffix(usd_ascii))
            named = lambda test: ", ".join(str(p) for p in paths if test(p.name))
            _say(progress, message="animation curves: " + named(lambda n: n.startswith("curves.")))
            if "csv" in exports:
                _say(progress, message="ARKit curves (Live Link Face CSV): " + named(lambda n: n.startswith("arkit_")))
            if "usd" in exports:
                _say(progress, message="the take as USD (mesh per frame, camera, ARKit controls, plate card): "
                     + named(lambda n: n.endswith((".usd", ".usda"))))
            if any(p.suffix == ".mp4" for p in paths):
                _say(progress, message="overlay video(s) (plate | render | wipe): " + named(lambda n: n.endswith(".mp4")))
            _say(progress, message=f"sequence report: {paths[-1]}")
        else:
            for p in write_arkit_csv(out, kinds, clip.fps or 24.0, single=True) if "csv" in exports else []:
                _say(progress, message=f"ARKit controls (Live Link Face CSV): {p}")
            usd = usd_suffix(usd_ascii)
            for p in write_usd_takes(out, kinds, clip.fps or 24.0, single=True, suffix=usd) if "usd" in exports else []:
                _say(progress, message=f"the fit as USD (mesh, camera, ARKit controls, plate card): {p}")
    return rows


def _clip(frames, select=None, camera=None, colorspace=None):
    from .clips import Clip
    if isinstance(frames, (list, tuple)):
        if len(frames) == 1:
            return open_clip(frames[0], select, camera, colorspace)
        folder = {Path(f).parent for f in frames}
        clip = open_clip(folder.pop(), None, camera, colorspace) if len(folder) == 1 else None
        if clip is None or clip.kind != "folder":
            raise InvfaceError("a list of plates must lie in one folder; pass the folder or a video")
        names = [Path(f).stem for f in frames]
        clip.indices = [clip.names.index(n) for n in names]
        clip.names = names
        return clip
    return frames if isinstance(frames, Clip) else open_clip(frames, select, camera, colorspace)
