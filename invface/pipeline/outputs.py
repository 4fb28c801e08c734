"""A sequence's outputs, made from its frames' fit.json records: the animation curves
(curves.csv / curves.json), one overlay MP4 per kind and the sequence page."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..io.fitrecords import read_fit_json
from ..io.images import linear_to_srgb
from ..io.jsonfile import write_object
from ..io.tables import write_csv
from ..io.video import VideoWriter


def sequence_records(out, kinds):
    """{kind: [fit.json dicts in frame order]} of a sequence folder (frames ordered by their
    'frame' index, else by name)."""
    recs = {}
    for kind in kinds:
        found = []
        for f in sorted(Path(out).glob(f"*/{kind}/fit.json")):
            found.append(dict(read_fit_json(f), _name=f.parent.parent.name))
        recs[kind] = sorted(found, key=lambda r: (r.get("frame", 0), r["_name"]))
    return recs


def curve_rows(records):
    """The animation curves of one kind's frame records: a list of {column: value} with frame,
    time, name, flagged, weight_*, jaw_*, rotation_*, translation_*, activation_*, arkit_* (the 52
    ARKit controls, ``model.arkit``). A flagged
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
        row.update({f"arkit_{k}": v for k, v in r.get("arkit", {}).items()})
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
    table = [[k, *[r.get(c, "") for c in all_cols]] for k, rows in per_kind.items() for r in rows]
    path = write_csv(Path(out) / "curves.csv", ["kind", *all_cols], table)
    return path, Path(out) / "curves.json"


def write_overlay_video(out, kind, fps=24.0, height=360):
    """out/overlay_<kind>.mp4: per frame, plate | render | wipe (plate left of the middle,
    render right of it), sRGB, each panel ``height`` px tall; written to a temporary file
    and renamed. None when the kind has no frames."""
    import cv2
    files = sorted(Path(out).glob(f"*/{kind}/fit.npz"))
    recs = {r["_name"]: r for r in sequence_records(out, [kind])[kind]}
    files = sorted(files, key=lambda f: (recs.get(f.parent.parent.name, {}).get("frame", 0), f.parent.parent.name))
    if not files:
        return None
    path = Path(out) / f"overlay_{kind}.mp4"
    with VideoWriter(path, fps) as video:
        for f in files:
            with np.load(f, allow_pickle=False) as d:
                plate, render = d["plate"], d["render"]
            h, w = plate.shape[:2]
            wipe = plate.copy()
            wipe[:, w // 2:] = render[:, w // 2:]
            panel = np.concatenate([plate, render, wipe], 1)
            img = (np.clip(linear_to_srgb(panel), 0, 1) * 255 + 0.5).astype(np.uint8)
            scale = height / h
            img = cv2.resize(img, (int(round(img.shape[1] * scale / 2)) * 2, height), interpolation=cv2.INTER_AREA)
            cv2.line(img, (img.shape[1] * 5 // 6, 0), (img.shape[1] * 5 // 6, height), (255, 255, 255), 1)
            video.write(img)
    return path


def write_arkit_csv(out, kinds, fps=24.0, single=False):
    """out/arkit_<kind>.csv per kind: the fit's 52 ARKit controls and head rotation in Live Link
    Face's CSV layout (``io.livelink``), a row per frame in frame order (one row for a single
    plate, whose fit.json is out/<kind>/fit.json). Returns the paths written."""
    from ..io.exporters import export
    from ..model.arkit import ARKIT_NAMES
    paths = []
    for kind in kinds:
        if single:
            f = Path(out) / kind / "fit.json"
            recs = [read_fit_json(f)] if f.is_file() else []
        else:
            recs = sequence_records(out, [kind])[kind]
        if not recs:
            continue
        frames = [{"frame": r.get("frame", i), "arkit": r.get("arkit", {}), "rotation": r.get("rotation", [0, 0, 0]),
                   "eyes": livelink_eyes(r.get("eyes"))} for i, r in enumerate(recs)]
        paths.append(export(Path(out) / f"arkit_{kind}.csv",
                            {"frames": frames, "arkit_names": ARKIT_NAMES, "fps": fps or 24.0}, format="livelink"))
    return paths


def livelink_eyes(eyes):
    """(6,) rad: Live Link Face's eye columns (left yaw, pitch, roll, right yaw, pitch, roll) from
    fit.json's "eyes" ({"L": {"yaw", "pitch"}, "R": ...}: ``model.gaze``; roll 0), zeros without it."""
    out = np.zeros(6)
    for i, s in enumerate(("L", "R")):
        e = (eyes or {}).get(s) or {}
        out[3 * i:3 * i + 2] = e.get("yaw", 0.0), e.get("pitch", 0.0)
    return out


def take_frames(run, kind, single, points=True):
    """The frames of one kind for a USD take (``io.usd.write_usd``): fit.json's values with each
    frame's posed surface from its fit.npz (``points``; else the first frame's alone) and the
    fit.json itself as "record", flagged frames left out (USD interpolates them), and the first
    frame's camera and triangles. Returns (frames, triangles, camera dict) or None."""
    if single:
        f = Path(run) / kind / "fit.json"
        recs = [dict(read_fit_json(f), _dir=str(f.parent))] if f.is_file() else []
    else:
        recs = [dict(r, _dir=str(Path(run) / r["_name"] / kind)) for r in sequence_records(run, [kind])[kind]]
    frames, tri, cam = [], None, None
    for i, r in enumerate(recs):
        npz = Path(r["_dir"]) / "fit.npz"
        if r.get("flagged") or not npz.is_file():
            continue
        with np.load(npz, allow_pickle=False) as d:
            surface = d["surface"] if points or tri is None else None
            if tri is None:
                tri, cam = d["triangles"], json.loads(str(d["camera"]))
        e = livelink_eyes(r.get("eyes"))
        frames.append({"frame": r.get("frame", i), "points": surface, "arkit": r.get("arkit", {}),
                       "activations": r.get("activations") or {},
                       "rotation": r.get("rotation", [0, 0, 0]), "translation": r.get("translation", [0, 0, 0]),
                       "eyes": e[[0, 1, 3, 4]], "record": r})
    return (frames, tri, cam) if frames else None


def write_usd_takes(out, kinds, fps=24.0, single=False, suffix=".usd"):
    """out/face_<kind><suffix> per kind (".usd" binary, ".usda" text): the take as a USD stage
    (``io.usd``), with the frames' plates (out/plates/<frame>.jpg, written once for all kinds)
    on a card behind the face. Returns the paths of the USD files."""
    from ..io.exporters import export
    paths, written = [], {}
    for kind in kinds:
        take = take_frames(out, kind, single)
        if take is not None:
            frames, tri, cam = take
            plates = plate_images(out, frames, written)
            sources = sorted({str(f["record"].get("plate", "")) for f in frames} - {""})
            paths.append(export(Path(out) / f"face_{kind}{suffix}",
                                {"frames": frames, "triangles": tri, "camera": cam, "fps": fps or 24.0,
                                 "plates": plates, "plate_sources": sources}))
    return paths


def plate_images(out, frames, written=None):
    """Write each frame's undistorted plate (its fit.npz's, sRGB JPEG) as out/plates/<frame>.jpg
    for a USD take's card; ``written`` ({frame number: path}) skips those already written.
    Returns {frame number: path relative to out}."""
    from ..io.images import write_display_image
    written = {} if written is None else written
    rel = {}
    for f in frames:
        r = f["record"]
        name = r.get("_name", "plate")
        path = Path("plates") / f"{name}.jpg"
        if f["frame"] not in written:
            with np.load(Path(r["_dir"]) / "fit.npz", allow_pickle=False) as d:
                if "plate" not in d:
                    continue
                write_display_image(Path(out) / path, linear_to_srgb(d["plate"]))
            written[f["frame"]] = path
        rel[f["frame"]] = written[f["frame"]].as_posix()
    return rel


def rig_frames(run, kind, single, model):
    """The frames of one kind for a rig (``io.usd.write_usd_rig``, ``io.gltf.write_glb``): each
    fit.json's weights by ``model``'s blendshape names, its jaw's transform and the head's pose,
    flagged frames left out; and the first frame's camera. Returns (frames, camera dict), None
    when the kind has no frames; InvfaceError when the fits were made with another model (their
    surfaces have another vertex count)."""
    from ..errors import InvfaceError
    from ..model.controls import FitVector
    from ..model.rig import euler_xyz
    take = take_frames(run, kind, single, points=False)
    if take is None:
        return None
    frames, _, cam = take
    if len(frames[0]["points"]) != len(model.neutral):
        raise InvfaceError(f"{run}: its {kind} fits have {len(frames[0]['points'])} vertices, the model "
                           f"{len(model.neutral)}: pass the model the run was fitted with (--model)")
    vec = FitVector.of(model)
    out = []
    for f in frames:
        p = vec.unpack(vec.from_dict(f["record"], what=f"{run} {kind} frame {f['frame']}"))[0]
        H = np.eye(4)
        H[:3, :3], H[:3, 3] = euler_xyz(np.asarray(f["rotation"], float)), np.asarray(f["translation"], float)
        out.append({"frame": f["frame"], "weights": p[vec.weights], "jaw_matrix": model.jaw_matrix(p[vec.jaw]),
                    "head_matrix": H})
    return out, cam


def write_rigs(out, kinds, model, fps=24.0, single=False, suffix=".usd"):
    """out/rig_<kind><suffix> per kind: the model's blendshape rig animated by the kind's fitted
    controls, in UsdSkel (".usd", ".usda" as text: ``io.usd.write_usd_rig``) or glTF (".glb": ``io.gltf.write_glb``).
    Returns the paths."""
    from ..io.exporters import export
    paths = []
    for kind in kinds:
        rig = rig_frames(out, kind, single, model)
        if rig is None:
            continue
        frames, cam = rig
        data = {"fps": fps or 24.0, "camera": cam, "neutral": model.neutral, "triangles": model.triangles,
                "names": list(model.blendshape_names), "deltas": model.blendshapes,
                "jaw_weights": model.jaw_weights, "frames": frames}
        path = Path(out) / f"rig_{kind}{suffix}"
        paths.append(export(path, data, format="usdskel") if suffix.startswith(".usd") else export(path, data))
    return paths


def write_sequence_outputs(out, kinds, fps=0.0, exports=("csv", "usd"), usd_suffix=".usd"):
    """The sequence's files from its frames' records: curves.csv/json, the Live Link Face CSV
    ("csv" in ``exports``), the USD take ("usd"; ``usd_suffix`` ".usda" for text), an overlay
    MP4 per kind, and the sequence page (index.html). Returns their paths."""
    from ..report.sequence import write_sequence_report
    paths = list(write_curves_files(out, kinds))
    paths += write_arkit_csv(out, kinds, fps or 24.0) if "csv" in exports else []
    paths += write_usd_takes(out, kinds, fps or 24.0, suffix=usd_suffix) if "usd" in exports else []
    paths += [p for k in kinds if (p := write_overlay_video(out, k, fps or 24.0)) is not None]
    paths.append(write_sequence_report(out))
    return paths


def sequence_summary(out, kinds, rows, fitted, seconds):
    """Lines that close a sequence's run: each kind's frame-to-frame jitter, the pace (frames
    fitted in ``seconds``, per minute), and the curve RMS over the frames ``rows``
    (``fit_frames``' summaries): median and worst."""
    import statistics
    lines = [f"{kind}: frame-to-frame jitter {jitter(curve_rows(recs)):.3f} (RMS second difference in units of "
             "0.1 weight, 0.01 rad, 1 mm)" for kind, recs in sequence_records(out, kinds).items() if len(recs) >= 3]
    if fitted and seconds > 0:
        lines.append(f"{fitted} frames fitted in {seconds:.0f} s: {60 * fitted / seconds:.1f} frames/min, "
                     f"{seconds / fitted:.1f} s a frame ({', '.join(kinds)}; outputs and reports included)")
    rms = [(k["curve_rms_px"], r["name"], kind) for r in rows for kind, k in r["kinds"].items()
           if k.get("curve_rms_px") is not None]
    if rms:
        worst = max(rms)
        lines.append(f"curve RMS over {len(rows)} frames: median {statistics.median(v[0] for v in rms):.2f} px; "
                     f"worst {worst[0]:.2f} px ({worst[1]}, {worst[2]})")
    return lines


EXPORT_FORMATS = ("csv", "usd", "usdskel", "gltf")


def usd_suffix(usd_ascii):
    """The USD files' suffix: ".usda" (text) with ``usd_ascii``, else ".usd" (binary crate)."""
    return ".usda" if usd_ascii else ".usd"


def export(run_dir, formats=("csv",), fps=None, model=None, usd_ascii=False):
    """Write an existing fit run's exports into its folder: "csv" is the Live Link Face CSV per
    kind (``write_arkit_csv``: arkit_<kind>.csv), "usd" the take as a USD stage per kind
    (``write_usd_takes``: face_<kind>.usd: the fitted face's points per frame, the solved camera,
    the ARKit controls), "usdskel" and "gltf" the model's rig animated by the fit (``write_rigs``:
    rig_<kind>.usd, rig_<kind>.glb). run_dir: a fit-plate output folder (a photo's, with
    <kind>/fit.json, or a sequence's, with <frame>/<kind>/fit.json); fps: the clip's frame rate
    (default run.json's, else 24); model: the model the run was fitted with (``run_model``);
    usd_ascii: the USD files as text (.usda) rather than binary (.usd).
    Returns the paths written; InvfaceError naming the folder when it holds no fit, or an
    unknown format."""
    from ..errors import InvfaceError
    from .runs import read_run
    run = Path(run_dir)
    formats = [formats] if isinstance(formats, str) else list(formats)
    for f in formats:
        if f not in EXPORT_FORMATS:
            raise InvfaceError(f"export format '{f}': use " + ", ".join(EXPORT_FORMATS))
    single = [k for k in ("blendshape", "simulation") if (run / k / "fit.json").is_file()]
    record = read_run(run)
    frames = record.get("frames") or []                   # a sequence's run.json lists its frames
    kinds = single or [k for k in ("blendshape", "simulation") if frames and any(run.glob(f"*/{k}/fit.json"))]
    if not kinds:
        raise InvfaceError(f"{run}: holds no fit (no <kind>/fit.json, nor a sequence's run.json with "
                           "<frame>/<kind>/fit.json): give a fit-plate output folder")
    rate = fps or record.get("fps") or 24.0
    paths = write_arkit_csv(run, kinds, rate, single=bool(single)) if "csv" in formats else []
    usd = usd_suffix(usd_ascii)
    paths += write_usd_takes(run, kinds, rate, single=bool(single), suffix=usd) if "usd" in formats else []
    rigs = [(f, suffix) for f, suffix in (("usdskel", usd), ("gltf", ".glb")) if f in formats]
    model = run_model(run, model) if rigs else None
    for _, suffix in rigs:
        paths += write_rigs(run, kinds, model, rate, single=bool(single), suffix=suffix)
    return paths


def run_model(run, model=None):
    """The model a run was fitted with: ``model`` (a FaceModel or a bundle path) when given, else
    the run's actor.npz (the identity-adapted head), else the built-in head."""
    from ..model.facemodel import FaceModel
    if model is not None:
        return model if isinstance(model, FaceModel) else FaceModel.load(model)
    actor = Path(run) / "actor.npz"
    if actor.is_file():
        return FaceModel.load(actor)
    from ..template import build
    return build()
