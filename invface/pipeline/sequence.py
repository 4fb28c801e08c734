"""Fitting a plate sequence (a video, a folder of frames or one plate) frame by frame, with
checkpoints, resume, bad-frame flags and animation-curve output.

    clip = open_clip("take3.mp4", frames="0:72")
    frames = fit_sequence(model, clip, calibration, out="fit/take3", kinds="both")
    # fit/take3/<frame>/<kind>/fit.json, fit.npz and index.html, as each finishes
    # fit/take3/curves.csv, curves.json, overlay_<kind>.mp4 and index.html at the end

Each frame starts from its predecessor's controls and pose (the last frame that was not
flagged). Every kind of every frame is written atomically as it finishes, its ``fit.json``
carrying ``input_hash``: the SHA-1 of the frame's pixels and camera, the model, the
calibration and the fit options. A rerun of the same command into the same folder skips
the frames whose hash matches (``restart`` starts over); a run with other inputs is
refused. ``pipeline.distributed.fit_sequence_distributed`` runs the same per-frame code on a
Dask cluster, chunk by chunk.

A frame is flagged (``fit.json`` "flagged", the curves file's "flagged" column, the report)
when its curve RMS is far above the frames before it (``FLAG_RMS_RATIO`` times their median
and ``FLAG_RMS_PX`` more) or its lip volume changes by more than ``FLAG_LIP_VOLUME``: a hand
over the mouth, a lost track. It does not start the next frame, and the curves file gives it
the controls interpolated from its unflagged neighbours.
"""
from __future__ import annotations

import csv
import hashlib
import io
import json
import os
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ..errors import InvfaceError
from ..fit.lambdas import EQ16_TEMPORAL, TEMPORAL_LAMBDA
from ..jsonfile import write_object
from .clips import open_clip
from .plates import _say, fit_frame, model_kinds

RUN_FILE = "run.json"
FLAG_RMS_RATIO = 3.0     # curve RMS above this many times the median of the previous frames ...
FLAG_RMS_PX = 4.0        # ... and above it by this many px
FLAG_LIP_VOLUME = 0.20   # |lip volume change| above this (simulation: within 3 %; the rig at a true smile: 10 %)
FLAG_WINDOW = 8          # previous unflagged frames the median is taken over


def _sha(*parts):
    h = hashlib.sha1()
    for p in parts:
        h.update(np.ascontiguousarray(p).tobytes() if isinstance(p, np.ndarray) else str(p).encode())
    return h.hexdigest()[:16]


def run_hash(model, calibration, options):
    """The SHA-1 (16 hex) of what a frame's fit depends on besides its pixels: the model
    (neutral, blendshapes, tets), the calibration (light, albedo) and the fit options (dict)."""
    cal = getattr(calibration, "calibration", calibration)
    return _sha(np.asarray(model.neutral, float), np.asarray(model.blendshapes, float), np.asarray(model.tets),
                np.asarray(cal.gamma, float), np.asarray(cal.albedo, float),
                json.dumps(options, sort_keys=True, default=str))


def read_run(out):
    """out/run.json as a dict ({} when absent or unreadable)."""
    try:
        return json.loads((Path(out) / RUN_FILE).read_text())
    except (OSError, ValueError):
        return {}


def start_run(out, frames, kinds, force=False, inputs=None, extra=None):
    """Claim the output folder for a fit run. One with an earlier run's fits is resumed when
    its run.json records the same ``inputs`` hash (``run_hash``): the finished frames stay and
    True is returned; otherwise it is refused (InvfaceError) unless ``force``, which removes
    the fits (the kind folders with a fit.json) and the report pages, nothing else. Then
    out/run.json {frames, kinds, inputs, finished: false, **extra} is written; the reports read
    it to name what a stopped run left out."""
    import shutil
    from ..report.runs import earlier_fits
    out = Path(out)
    old = earlier_fits(out)
    resume = bool(old) and not force and inputs is not None and read_run(out).get("inputs") == inputs
    if old and not force and not resume:
        raise InvfaceError(f"{out}: holds an earlier run's fits ({len(old)} fit.json, e.g. {old[0]}) made from "
                           "other inputs; pass --restart to replace them, or choose another output folder")
    if not resume:
        for f in old:
            shutil.rmtree(f.parent)
        for page in [*out.glob("index.html"), *out.glob("*/index.html"), *out.glob("weights_*.png"),
                     *out.glob("activations_*.png")]:
            page.unlink()
    out.mkdir(parents=True, exist_ok=True)
    write_object(out / RUN_FILE, {"frames": list(frames), "kinds": list(kinds), "inputs": inputs,
                                  "finished": False, **(extra or {})})
    return resume


def finish_run(out):
    """Mark out/run.json finished."""
    write_object(Path(out) / RUN_FILE, dict(read_run(out), finished=True))


def frame_hash(digest, inputs):
    """A frame's input hash: its pixel digest and the run's ``run_hash``."""
    return _sha(digest, inputs)


def fit_record(folder, kind):
    """The kind's fit.json in a frame folder as a dict (None when absent or unreadable)."""
    try:
        return json.loads((Path(folder) / kind / "fit.json").read_text())
    except (OSError, ValueError):
        return None


def finished_record(folder, kind, input_hash):
    """The kind's fit.json in a frame folder (a dict) when it was made from the same inputs,
    else None."""
    rec = fit_record(folder, kind)
    return rec if rec is not None and rec.get("input_hash") == input_hash else None


def start_from(model, record):
    """A warm start (p, rotation, translation) from a fit.json record."""
    from ..model.controls import FitVector
    vec = FitVector.of(model)
    p, rot, tr = vec.unpack(vec.from_dict(record, what="fit.json"))
    return SimpleNamespace(p=p, rotation=rot, translation=tr)


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
    or a PlateFit), writing each kind of each frame to out/<frame>/<kind>/ (out/ for a clip
    of one frame) as it finishes with its ``input_hash``; with ``skip`` frames already
    finished from the same inputs are read, not fitted; ``record``: more keys for fit.json;
    ``keep``: each summary's "fit" holds the frame's FrameFit (None when skipped).
    A frame of a longer clip that cannot be fitted at all (no face found, no kind finished)
    is reported in its summary's "error" and the run goes on. A sequence frame's page has the
    plate, render and curve pictures only (``invface report`` on its folder adds the rest).
    ``fit_frame`` options (iterations, shading, lam_curves, solver, title, notes). Returns one summary dict per
    frame: {name, index, time, skipped, kinds: {kind: {curve_rms_px, flagged}}, failed, error}."""
    from ..fit.landmarks import LandmarkTracker
    kinds = model_kinds(kinds)
    starts = dict(starts or {})
    history = {k: [] for k in kinds}
    rows = []
    single = len(clip) == 1
    with LandmarkTracker() as tracker:
        for frame in clip.frames(start, stop):
            folder = None if out is None else Path(out) if single else Path(out) / frame.name
            h = frame_hash(frame.digest, inputs)
            done = {k: finished_record(folder, k, h) for k in kinds} if (skip and folder is not None) else {}
            done = {k: r for k, r in done.items() if r is not None}
            row = {"name": frame.name, "index": frame.index, "time": frame.time, "skipped": sorted(done),
                   "kinds": {}, "failed": {}}
            for k, rec in done.items():
                row["kinds"][k] = {"curve_rms_px": rec.get("curve_rms_px"), "flagged": rec.get("flagged", "")}
                if not rec.get("flagged"):
                    starts[k] = start_from(model, rec)
                    history[k].append(rec.get("curve_rms_px", 0.0))
            todo = tuple(k for k in kinds if k not in done)
            if not todo:
                _say(progress, message=f"{frame.name}: finished before from the same inputs, skipped")
                rows.append(row)
                if on_frame is not None:
                    on_frame(None, folder, row)
                continue
            _say(progress, message=f"frame {frame.name} (t = {frame.time:.2f} s)")

            def detector(image, name, t=frame.time):
                return tracker(image, t, name)

            def finished(ff, kind, folder=folder):
                fit = ff.fits[kind]
                why = flag_reason(fit.curve_rms_px, fit.lip_volume_change, history[kind])
                ff.record[kind] = {"input_hash": h, "run_inputs": inputs, "frame": frame.index, "time": frame.time,
                                   "flagged": why, **(record or {})}
                if why:
                    ff.warnings.append(f"{ff.name} {kind}: flagged: {why}; the next frame does not start from it")
                if folder is not None:
                    ff.save_kind(folder, kind)
                if on_kind is not None:
                    on_kind(ff, kind)
            try:
                ff = fit_frame(model, frame.plate, calibration, curves, kinds=todo, starts=starts,
                               progress=progress, on_kind=finished, detector=detector, **options)
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
                why = ff.record[k]["flagged"]
                row["kinds"][k] = {"curve_rms_px": fit.curve_rms_px, "flagged": why}
                if not why:
                    starts[k] = fit
                    history[k].append(fit.curve_rms_px)
            row["failed"] = dict(ff.failed)
            if keep:
                row["fit"] = ff
            rows.append(row)
            if on_frame is not None:
                on_frame(ff, folder, row)
    return rows


def fit_sequence(model, frames, calibration, out=None, kinds=("blendshape",), curves=None, progress=None,
                 on_kind=None, on_frame=None, force=False, camera=None, select=None, keep=True, workers=None,
                 scheduler=None, extra=None, **options):
    """Fit a plate sequence in order (``fit_frames``). frames: a Clip, a
    video, folder or image path (``open_clip``, with ``select`` "START:STOP[:STEP]" and
    ``camera``), or a list of plate paths; curves: for a single plate only (a sequence takes
    FRAME.curves.json beside each frame, or the detector, tracking frame to frame); out:
    see ``fit_frames``; an out folder with an earlier run's fits is resumed when they were
    made from the same inputs, refused otherwise unless ``force`` (``start_run``); then the
    sequence outputs (``write_sequence_outputs``); ``workers`` or ``scheduler``: on a Dask
    cluster (``distributed.fit_sequence_distributed``; needs ``out``); ``extra``: more keys for
    run.json. progress receives the fits' events, {"message": ...} for each step (a resumed
    run, the sequence files written) and, on a cluster, {"done": frames, "total": frames}.
    Returns the per-frame summaries of ``fit_frames``, each with its FrameFit as "fit" when
    fitted on this process and ``keep`` (a long clip's fits are on disk: their renders would
    fill the memory)."""
    clip = _clip(frames, select, camera)
    if curves is not None and len(clip) > 1:
        raise InvfaceError("one curves file names one plate; in a sequence put FRAME.curves.json beside each "
                           "frame (or let the detector find each frame's curves)")
    kinds = model_kinds(kinds)
    options.setdefault("temporal", TEMPORAL_LAMBDA)
    options.setdefault("temporal_shading", EQ16_TEMPORAL)
    inputs = run_hash(model, calibration, dict(options, curves=str(curves) if curves is not None else None))
    if out is not None and start_run(out, clip.names if len(clip) > 1 else [], kinds, force, inputs, extra):
        _say(progress, message=f"{out}: resuming the run there (same inputs): its finished frames are skipped")
    if (workers or scheduler) and len(clip) > 1:
        from .distributed import fit_sequence_distributed
        rows = fit_sequence_distributed(model, clip, calibration, out, kinds, inputs=inputs, workers=workers or 1,
                                        scheduler=scheduler, progress=progress, **options)
    else:
        rows = fit_frames(model, clip, calibration, out, kinds, curves=curves, inputs=inputs, keep=keep,
                          progress=progress, on_kind=on_kind, on_frame=on_frame, **options)
    if out is not None:
        finish_run(out)
        if len(clip) > 1:
            paths = write_sequence_outputs(out, kinds, fps=clip.fps)
            _say(progress, message="animation curves: " + ", ".join(str(p) for p in paths[:2]))
            if len(paths) > 3:
                _say(progress, message="overlay video(s) (plate | render | wipe): "
                                       + ", ".join(str(p) for p in paths[2:-1]))
            _say(progress, message=f"sequence report: {paths[-1]}")
    return rows


def _clip(frames, select=None, camera=None):
    from .clips import Clip
    if isinstance(frames, (list, tuple)):
        if len(frames) == 1:
            return open_clip(frames[0], select, camera)
        folder = {Path(f).parent for f in frames}
        clip = open_clip(folder.pop(), None, camera) if len(folder) == 1 else None
        if clip is None or clip.kind != "folder":
            raise InvfaceError("a list of plates must lie in one folder; pass the folder or a video")
        names = [Path(f).stem for f in frames]
        clip.indices = [clip.names.index(n) for n in names]
        clip.names = names
        return clip
    return frames if isinstance(frames, Clip) else open_clip(frames, select, camera)


def sequence_records(out, kinds):
    """{kind: [fit.json dicts in frame order]} of a sequence folder (frames ordered by their
    'frame' index, else by name)."""
    recs = {}
    for kind in kinds:
        found = []
        for f in sorted(Path(out).glob(f"*/{kind}/fit.json")):
            try:
                found.append(dict(json.loads(f.read_text()), _name=f.parent.parent.name))
            except ValueError:
                continue
        recs[kind] = sorted(found, key=lambda r: (r.get("frame", 0), r["_name"]))
    return recs


def curve_rows(records):
    """The animation curves of one kind's frame records: a list of {column: value} with frame,
    time, name, flagged, weight_*, jaw_*, rotation_*, translation_*, activation_*. A flagged
    frame's controls are interpolated (linearly in time) from its nearest unflagged neighbours."""
    from ..model.rig import JAW_NAMES
    rows = []
    for r in records:
        row = {"frame": r.get("frame", len(rows)), "time": r.get("time", float(len(rows))), "name": r["_name"],
               "flagged": r.get("flagged", "")}
        row.update({f"weight_{k}": v for k, v in r.get("weights", {}).items()})
        row.update({n: v for n, v in zip(JAW_NAMES, r.get("jaw", []))})
        row.update({f"rotation_{a}": v for a, v in zip("xyz", r.get("rotation", []))})
        row.update({f"translation_{a}": v for a, v in zip("xyz", r.get("translation", []))})
        row.update({f"activation_{k}": v for k, v in r.get("activations", {}).items()})
        rows.append(row)
    good = [i for i, r in enumerate(rows) if not r["flagged"]]
    if good and len(good) < len(rows):
        t = np.array([r["time"] for r in rows], float)
        cols = [c for c in rows[0] if c not in ("frame", "time", "name", "flagged")]
        for c in cols:
            v = np.array([rows[i].get(c, 0.0) for i in good], float)
            for i, r in enumerate(rows):
                if r["flagged"]:
                    r[c] = float(np.interp(t[i], t[good], v))
    return rows


def jitter(rows):
    """Frame-to-frame jitter of one kind's curve rows (``curve_rows``): the RMS over frames and
    entries of the second difference of the controls and pose in ``FitVector.scales()`` units
    (0.1 weight, 0.01 rad, 1 mm); nan with fewer than 3 frames. A smooth motion sampled
    finely has little; a fit that flickers between answers has much."""
    from ..model.controls import JAW_SCALES, ROTATION_SCALE, TRANSLATION_SCALE, WEIGHT_SCALE
    from ..model.rig import JAW_NAMES
    if len(rows) < 3:
        return float("nan")
    cols = [c for c in rows[0] if c.startswith("weight_")]
    scale = [WEIGHT_SCALE] * len(cols) + list(JAW_SCALES) + [ROTATION_SCALE] * 3 + [TRANSLATION_SCALE] * 3
    cols += JAW_NAMES + [f"rotation_{a}" for a in "xyz"] + [f"translation_{a}" for a in "xyz"]
    z = np.array([[float(r.get(c, 0.0)) for c in cols] for r in rows]) / np.array(scale)
    return float(np.sqrt(np.mean(np.diff(z, 2, axis=0) ** 2)))


def write_curves_files(out, kinds):
    """out/curves.csv (one row per kind and frame: kind, frame, time, name, flagged, then every
    control, pose and activation) and out/curves.json ({kind: {columns: [...], rows: [[...]]}}),
    each written atomically. Returns both paths."""
    per_kind = {k: curve_rows(v) for k, v in sequence_records(out, kinds).items() if v}
    columns = {k: list(dict.fromkeys(c for r in rows for c in r)) for k, rows in per_kind.items()}
    data = {k: {"columns": columns[k], "rows": [[r.get(c, "") for c in columns[k]] for r in rows]}
            for k, rows in per_kind.items()}
    write_object(Path(out) / "curves.json", data)
    all_cols = list(dict.fromkeys(c for cols in columns.values() for c in cols))
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(["kind", *all_cols])
    for k, rows in per_kind.items():
        for r in rows:
            w.writerow([k, *[r.get(c, "") for c in all_cols]])
    path = Path(out) / "curves.csv"
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(buf.getvalue())
    os.replace(tmp, path)
    return path, Path(out) / "curves.json"


def write_overlay_video(out, kind, fps=24.0, height=360):
    """out/overlay_<kind>.mp4: per frame, plate | render | wipe (plate left of the middle,
    render right of it), sRGB, each panel ``height`` px tall; written to a temporary file
    and renamed. None when the kind has no frames."""
    import cv2
    from ..render.plates import linear_to_srgb
    files = sorted(Path(out).glob(f"*/{kind}/fit.npz"))
    recs = {r["_name"]: r for r in sequence_records(out, [kind])[kind]}
    files = sorted(files, key=lambda f: (recs.get(f.parent.parent.name, {}).get("frame", 0), f.parent.parent.name))
    if not files:
        return None
    path = Path(out) / f"overlay_{kind}.mp4"
    tmp = path.with_name(f".overlay_{kind}.{os.getpid()}.tmp.mp4")
    writer = None
    try:
        for f in files:
            with np.load(f, allow_pickle=False) as d:
                plate, render = d["plate"], d["render"]
            h, w = plate.shape[:2]
            wipe = plate.copy()
            wipe[:, w // 2:] = render[:, w // 2:]
            panel = np.concatenate([plate, render, wipe], 1)
            img = (np.clip(linear_to_srgb(panel), 0, 1) * 255 + 0.5).astype(np.uint8)[..., ::-1]
            scale = height / h
            img = cv2.resize(img, (int(round(img.shape[1] * scale / 2)) * 2, height), interpolation=cv2.INTER_AREA)
            cv2.line(img, (img.shape[1] * 5 // 6, 0), (img.shape[1] * 5 // 6, height), (255, 255, 255), 1)
            if writer is None:
                writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"mp4v"), float(fps or 24.0),
                                         (img.shape[1], img.shape[0]))
                if not writer.isOpened():
                    raise InvfaceError(f"{path}: OpenCV cannot write MP4 video here")
            writer.write(img)
    finally:
        if writer is not None:
            writer.release()
    os.replace(tmp, path)
    return path


def write_sequence_outputs(out, kinds, fps=0.0):
    """The sequence's files from its frames' records: curves.csv/json, one overlay MP4 per
    kind and the sequence page (index.html). Returns their paths."""
    from ..report.sequence import write_sequence_report
    paths = list(write_curves_files(out, kinds))
    paths += [p for k in kinds if (p := write_overlay_video(out, k, fps or 24.0)) is not None]
    paths.append(write_sequence_report(out))
    return paths


def pick_neutral(model, clip, candidates=8, lam=None, progress=None):
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
            curves, source = find_curves(model, frame.plate)
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
