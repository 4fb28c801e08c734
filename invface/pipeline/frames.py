"""The frame loop of a sequence: each frame fitted in order, written as it finishes, skipped
when finished before from the same inputs. Each frame's curve stage starts where the last two
unflagged frames point: their controls and pose carried on at constant velocity (``predict``),
clamped to the controls' box; its temporal term still pulls towards the last unflagged frame,
whose shading correction its shading stages start from (``fit.plate.fit_plate``). A resumed
run's first frame, and a Dask chunk's, start from the record of the frame before (no
prediction, no correction).

A frame is flagged (``fit.json`` "flagged", the curves file's "flagged" column, the report)
when its curve RMS is far above the frames before it (``FLAG_RMS_RATIO`` times their median
and ``FLAG_RMS_PX`` more) or its lip volume changes by more than ``FLAG_LIP_VOLUME``: a hand
over the mouth, a lost track. It does not start the next frame, and the curves file gives it
the controls interpolated from its unflagged neighbours.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InvfaceError
from .plates import _say, fit_frame, model_kinds
from .runs import finished_record, frame_hash, start_from

FLAG_RMS_RATIO = 3.0     # curve RMS above this many times the median of the previous frames ...
FLAG_RMS_PX = 4.0        # ... and above it by this many px
FLAG_LIP_VOLUME = 0.20   # |lip volume change| above this (simulation: within 3 %; the rig at a true smile: 10 %)
FLAG_WINDOW = 8          # previous unflagged frames the median is taken over
PREDICT_GAP = 2.0        # a prediction reaches at most this many times the gap between its two frames


def predict(vector, before, last, index):
    """The fit vector z (size,) expected at frame ``index`` from two earlier frames' fits
    ``before`` and ``last`` ((frame index, z) each, in order): z moving at constant velocity
    per frame, clamped to the controls' box (``FitVector.bounds``). None when the two frames
    are not in order before ``index`` or ``index`` lies more than ``PREDICT_GAP`` of their gap
    beyond the last (a long gap, after flagged frames, says nothing about the velocity)."""
    (i0, z0), (i1, z1) = before, last
    if not i0 < i1 < index or index - i1 > PREDICT_GAP * (i1 - i0):
        return None
    lo, hi = vector.bounds()
    return np.clip(z1 + (z1 - z0) * (index - i1) / (i1 - i0), lo, hi)


def flag_reason(rms, lip_volume, previous):
    """Why a frame's fit is implausible ('' when it is not): its curve RMS (px) against the
    unflagged previous frames' RMS (list), its lip volume change (fraction)."""
    why = []
    if len(previous) >= 2:
        med = float(np.median(previous[-FLAG_WINDOW:]))
        if rms > FLAG_RMS_RATIO * med and rms > med + FLAG_RMS_PX:
            why.append(f"curve RMS {rms:.1f} px against a median of {med:.1f} px over the frames before")
    if abs(lip_volume) > FLAG_LIP_VOLUME:
        why.append(f"lip volume change {100 * lip_volume:+.1f} %")
    return "; ".join(why)


def fit_frames(model, clip, calibration, out=None, kinds=("blendshape",), start=0, stop=None, starts=None,
               curves=None, inputs="", skip=True, record=None, keep=False, progress=None, on_kind=None,
               on_frame=None, **options):
    """Fit the clip's frames at positions [start, stop) in order, each warm-started from the
    last unflagged one (``starts``: {kind: start} for the first; a record from ``start_from``
    or a PlateFit) and, after two unflagged frames, from their ``predict``ion, writing each
    kind of each frame to out/<frame>/<kind>/ (out/ for a clip of one frame) as it finishes
    with its ``input_hash``; with ``skip`` frames already finished from the same inputs are
    read, not fitted; ``record``: more keys for fit.json;
    ``keep``: each summary's "fit" holds the frame's FrameFit (None when skipped).
    A frame of a longer clip that cannot be fitted at all (no face found, no kind finished)
    is reported in its summary's "error" and the run goes on. A sequence frame's page has the
    plate, render and curve pictures only (``invface report`` on its folder adds the rest).
    ``fit_frame`` options (iterations, shading, lam_curves, solver, title, notes). Returns one summary dict per
    frame: {name, index, time, skipped, kinds: {kind: {curve_rms_px, flagged}}, failed, error}."""
    from ..fit.landmarks import LandmarkTracker
    from ..model.controls import FitVector
    kinds = model_kinds(kinds)
    chain = _Chain(FitVector.of(model), dict(starts or {}), kinds)
    rows = []
    single = len(clip) == 1
    with LandmarkTracker(options.get("face", 0)) as tracker:
        for frame in clip.frames(start, stop):
            folder = None if out is None else Path(out) if single else Path(out) / frame.name
            h = frame_hash(frame.digest, inputs)
            done = _finished_before(folder, kinds, h) if skip else {}
            row = {"name": frame.name, "index": frame.index, "time": frame.time, "skipped": sorted(done),
                   "kinds": {}, "failed": {}}
            for k, rec in done.items():
                chain.take(k, frame.index, rec.get("curve_rms_px"), rec.get("flagged", ""), row,
                           start_from(model, rec))
            todo = tuple(k for k in kinds if k not in done)
            if not todo:
                _say(progress, message=f"{frame.name}: finished before from the same inputs, skipped")
                rows.append(row)
                if on_frame is not None:
                    on_frame(None, folder, row)
                continue
            _say(progress, message=f"frame {frame.name} (t = {frame.time:.2f} s)")
            stamp = {"input_hash": h, "run_inputs": inputs, "frame": frame.index, "time": frame.time}
            try:
                ff = fit_frame(model, frame.plate, calibration, curves, kinds=todo, starts=chain.starts,
                               guesses=chain.guesses(frame.index), progress=progress,
                               on_kind=chain.finisher(stamp, record, folder, on_kind),
                               detector=_detector(tracker, frame.time), crop=single, **options)
            except InvfaceError as e:
                if single:
                    raise
                row["error"] = str(e)
                _say(progress, message=f"{frame.name}: not fitted: {e}")
                rows.append(row)
                continue
            if folder is not None and ff.fits:
                ff.save(folder, quick=not single)
            for k, fit in ff.fits.items():
                chain.take(k, frame.index, fit.curve_rms_px, ff.record[k]["flagged"], row, fit)
            row["failed"] = dict(ff.failed)
            if keep:
                row["fit"] = ff
            rows.append(row)
            if on_frame is not None:
                on_frame(ff, folder, row)
    return rows


def _finished_before(folder, kinds, input_hash):
    """{kind: fit.json record} of the kinds finished in ``folder`` from the same inputs."""
    if folder is None:
        return {}
    done = {k: finished_record(folder, k, input_hash) for k in kinds}
    return {k: r for k, r in done.items() if r is not None}


def _detector(tracker, t):
    """The landmark detector of a frame at time ``t`` (s): the clip's ``LandmarkTracker``, its
    peer ARKit scores kept on the function (``find_curves`` reads them)."""
    def detector(image, name):
        points = tracker(image, t, name)
        detector.scores = tracker.scores
        return points
    return detector


class _Chain:
    """What carries from frame to frame: each kind's warm start (the last unflagged frame's fit
    or record), the fit vectors of its last two unflagged frames (``predict``'s) and the curve
    RMS of its unflagged frames (``flag_reason``'s history)."""

    def __init__(self, vector, starts, kinds):
        self.vector, self.starts = vector, starts
        self.history = {k: [] for k in kinds}
        self.track = {k: [] for k in kinds}

    def take(self, kind, index, rms, flagged, row, start):
        """Record a finished kind of frame ``index`` in its summary ``row``; an unflagged one
        starts the next frame (``start``: a PlateFit or ``start_from``'s record)."""
        row["kinds"][kind] = {"curve_rms_px": rms, "flagged": flagged}
        if not flagged:
            self.starts[kind] = start
            self.history[kind].append(rms if rms is not None else 0.0)
            z = self.vector.pack(start.p, start.rotation, start.translation)
            self.track[kind] = [*self.track[kind][-1:], (index, z)]

    def guesses(self, index):
        """{kind: z (size,)} where frame ``index``'s fit starts, for the kinds with two
        unflagged frames before it that ``predict`` can carry on."""
        guesses = {k: predict(self.vector, *t, index) for k, t in self.track.items() if len(t) == 2}
        return {k: z for k, z in guesses.items() if z is not None}

    def finisher(self, stamp, record, folder, on_kind):
        """``fit_frame``'s on_kind for one frame: flag the kind's fit (``flag_reason``), put
        ``stamp`` (input hash, frame, time), the flag and ``record`` in its fit.json, write it
        to ``folder`` and call the caller's ``on_kind``."""
        def finished(ff, kind):
            fit = ff.fits[kind]
            why = flag_reason(fit.curve_rms_px, fit.lip_volume_change, self.history[kind])
            ff.record[kind] = {**stamp, "flagged": why, **(record or {})}
            if why:
                ff.warnings.append(f"{ff.name} {kind}: flagged: {why}; the next frame does not start from it")
            if folder is not None:
                ff.save_kind(folder, kind)
            if on_kind is not None:
                on_kind(ff, kind)
        return finished
