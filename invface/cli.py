"""The ``invface`` command line. Bad input (InvfaceError, an OS error on a file, OpenCV's refusal,
memory) prints as one line and exits with status 2; an internal error as one line and status 1
(``invface --debug`` shows the traceback)."""
from __future__ import annotations

import argparse
import functools
import json
import math
import os
import sys
import time
from pathlib import Path

from .errors import InvfaceError


def _progress(msg):
    print(f"  .. {msg}", flush=True)


def _events(event):
    """A session-layer progress callback that prints step messages (fits' iterations go to bars)."""
    if "message" in event:
        _progress(event["message"])


def _bar(desc, total=None, unit="it"):
    """A progress bar on a terminal; nothing in a log file (no carriage-return updates there)."""
    from tqdm import tqdm
    return tqdm(total=total, desc=desc, unit=unit, leave=False, disable=not sys.stderr.isatty())


class _FitBars:
    """Progress events of fits -> one bar per (frame, kind), step messages printed."""

    def __init__(self):
        self.bars = {}

    def __call__(self, event):
        if "message" in event:
            _progress(event["message"])
            return
        if "done" in event:             # frames finished on a Dask cluster
            if "frames" not in self.bars:
                self.close()
                self.bars = {"frames": _bar("frames", total=event["total"], unit="frame")}
            bar = self.bars["frames"]
            bar.update(event["done"] - bar.n)
            elapsed = bar.format_dict.get("elapsed") or 0.0
            if bar.n and elapsed > 0:           # tqdm's own ETA is on the bar; the pace as a VFX user reads it
                bar.set_postfix_str(f"{60.0 * bar.n / elapsed:.1f} frames/min")
            return
        key = (event.get("frame", ""), event.get("kind", ""))
        if key not in self.bars:
            for bar in self.bars.values():
                bar.close()
            self.bars = {key: _bar(" ".join(k for k in key if k) + " fit", unit="eval")}
        bar = self.bars[key]
        bar.update(1)
        stage = event.get("stage", "") + (f" ({event['pass']})" if "pass" in event else "")
        bar.set_postfix(stage=stage, cost=f"{event.get('cost', 0):.4g}")

    def close(self):
        for bar in self.bars.values():
            bar.close()
        self.bars = {}


def cmd_build_model(args):
    from .pipeline import ModelBuild, build_model, load_model
    _fresh_output(args.output, args.overwrite)
    _fresh_output(args.preview, args.overwrite, "--preview", folder=True)
    if args.neutral:
        if not args.output:
            raise InvfaceError("build-model --neutral needs -o/--output for the new model (.npz)")
        from .morph.build import BuildFailed
        try:
            build = build_model(args.neutral, blendshapes=args.blendshapes, unit=args.unit,
                                expressions=args.expressions, resolution=args.resolution, progress=_events)
        except BuildFailed as e:
            if not args.preview:
                raise
            from .report.morph import write_failure_preview
            path = write_failure_preview(e.found, args.preview)
            raise InvfaceError(f"{e}" + (f"; the scan as aligned, with what was found, is drawn in {path}"
                                         if path else "")) from None
        print("stage seconds: " + json.dumps({k: v for k, v in build.seconds.items() if k != "total"}))
    elif args.template or not args.input:
        print(f"building the template head (resolution {args.resolution:g})", flush=True)
        build = build_model(resolution=args.resolution, force=args.force, progress=_events)
    else:
        t0 = time.perf_counter()
        build = ModelBuild(load_model(args.input), seconds={"total": time.perf_counter() - t0})
    if args.output:
        build.save(args.output)
        print(f"wrote {args.output}")
    print("\n".join(build.describe()))
    if args.preview:
        paths = build.save(None, preview=args.preview)
        print(f"previews: {len(paths)} images in {args.preview} (contact sheet: {paths[-1]})")
    return 0


def _fresh_output(path, overwrite, option="-o", folder=False):
    """One rule for every verb's output, checked before any work: an existing output (a file,
    or a folder that holds anything) is refused unless --overwrite, and so is one whose folder
    cannot be made or written (a file in the way, no write permission)."""
    if path is None:
        return
    p = Path(path)
    if (p.is_dir() and any(p.iterdir())) if folder else p.exists():
        if not overwrite:
            raise InvfaceError(f"{option} {p}: already exists" + (" and is not empty" if folder else "")
                               + f"; pass --overwrite to replace it, or give another {option}")
    elif not folder and p.is_dir():
        raise InvfaceError(f"{option} {p}: is a folder; give a file name")
    for q in [p if folder else p.parent, *(p if folder else p.parent).parents]:
        if q.exists():
            if not q.is_dir():
                raise InvfaceError(f"{option} {p}: a file stands where a folder is needed ({q})")
            if not os.access(q, os.W_OK):
                raise InvfaceError(f"{option} {p}: the folder {q} is not writable")
            break


def _load_model(path, resolution):
    from .pipeline import load_model
    return load_model(path, resolution, progress=_events)


def _read_activations(path):
    """{muscle: activation} and optional jaw (6,) from a JSON file {"activations": {...}, "jaw": [...]}
    (a plain {muscle: value} mapping is accepted too)."""
    from .io.jsonfile import read_object
    data = read_object(path, what="activations file")
    acts = data.get("activations", {k: v for k, v in data.items() if k != "jaw"})
    if not isinstance(acts, dict):
        raise InvfaceError(f"{path}: 'activations' must be an object {{muscle name: value}}")
    return acts, data.get("jaw")


def _named_values(items, option):
    """{NAME: float} from repeated NAME=NUMBER options."""
    out = {}
    for item in items or []:
        name, _, value = item.partition("=")
        try:
            out[name] = float(value)
        except ValueError:
            raise InvfaceError(f"{option} {item}: expected NAME=NUMBER") from None
    return out


def cmd_simulate(args):
    """Pose the model by muscle activations (and jaw), or by blendshape weights through the
    blendshape-driven muscle simulation; report the solve, render a preview."""
    from .pipeline import simulate
    acts, jaw = _read_activations(args.activations) if args.activations else ({}, None)
    for item in args.set or []:
        name, _, value = item.partition("=")
        acts[name] = value
    if args.jaw is not None:
        jaw = [args.jaw, 0, 0, 0, 0, 0]
    weights = _named_values(args.weight, "--weight")
    if args.output:                    # before the solve: a doomed write costs no minutes
        from .io.meshes import MESH_EXTS
        if Path(args.output).suffix.lower() not in MESH_EXTS:
            raise InvfaceError(f"-o {args.output}: the simulated surface is written as a mesh: give a file ending "
                               + ", ".join(MESH_EXTS))
    _fresh_output(args.output, args.overwrite)
    _fresh_output(args.preview, args.overwrite, "--preview")
    if weights and acts:
        raise InvfaceError("give muscle activations (--activations/--set) or blendshape weights "
                           "(--weight), not both: with weights the activations follow from the tracks")
    model = _load_model(args.model, args.resolution)
    result = simulate(model, acts, jaw, weights,
                      progress=lambda i, r: print(f"  .. Newton {i}: relative residual {r:.2e}", flush=True))
    print("\n".join(result.describe()))
    if args.output:
        from .io.meshes import write_mesh
        write_mesh(args.output, result.surface, model.triangles)
        print(f"wrote {args.output}")
    if args.preview:
        from .report.expressions import write_pose_preview
        w = None if jaw is None else {"jaw": jaw}
        print(f"wrote {write_pose_preview(model, result.surface, args.preview, w=w)}")
    return 0


def _pose(values, option="--pose"):
    import numpy as np
    if values is None:
        return np.zeros(3), np.zeros(3)
    v = np.asarray(values, float)
    if v.shape != (6,) or not np.all(np.isfinite(v)):
        raise InvfaceError(f"{option} needs 6 finite numbers: rx ry rz (rad) tx ty tz (m)")
    return v[:3], v[3:]


def _calibrate(model, plate, out, max_iter, pose=None, curves=None, source="", lam=None, lam_curves=None,
               robust=0):
    """Eq. 14 with a progress bar; the pose given, or (pose None) from the plate's curves.
    Writes out (.npz) and its _compare.png; returns the PlateCalibration."""
    from .fit.lambdas import EQ14_LAMBDA
    from .pipeline import auto_calibrate, calibrate_plate
    bar = _bar("calibrate lighting/albedo", total=max_iter)

    def progress(h):
        if "message" in h:
            _progress(h["message"])
        else:
            bar.update(1)
            bar.set_postfix(rms=f"{h['rms']:.4f}")
    try:
        if pose is None:
            result = auto_calibrate(model, plate, curves, source, lam_curves=lam_curves, lam=lam, max_iter=max_iter,
                                    progress=progress, robust=robust)
        else:
            result = calibrate_plate(model, plate, *pose, lam=EQ14_LAMBDA if lam is None else lam,
                                     max_iter=max_iter, progress=progress, robust=robust)
    finally:
        bar.close()
    path, compare = result.save(out)
    print(f"{result.describe()}\nwrote {path} and {compare} (plate | render | 4x difference)")
    for w in result.warnings():
        print(f"warning: {w}", flush=True)
    return result


def cmd_calibrate(args):
    """Lighting and albedo calibration (Eq. 14) on a neutral plate."""
    from .pipeline import as_plate, find_curves
    _fresh_output(args.output, args.overwrite)
    from .fit.calibrate import ROBUST_ROUNDS
    robust = ROBUST_ROUNDS if args.robust else 0
    model = _load_model(args.model, args.resolution)
    plate = as_plate(args.plate, args.camera, args.colorspace)
    if args.auto_pose:
        if args.pose is not None:
            raise InvfaceError("give either --pose or --auto-pose, not both")
        curves, source = find_curves(model, plate, args.curves, crop=True)
        _calibrate(model, plate, args.output, args.max_iter, curves=curves, source=source, lam=args.lam,
                   lam_curves=args.curve_lambda, robust=robust)
    else:
        _calibrate(model, plate, args.output, args.max_iter, pose=_pose(args.pose), lam=args.lam, robust=robust)
    return 0


def cmd_camera_calibrate(args):
    """Camera intrinsics and distortion from checkerboard photographs."""
    from .render.checkerboard import calibrate
    _fresh_output(args.output, args.overwrite)
    try:
        inner = tuple(int(v) for v in args.board.lower().split("x"))
        assert len(inner) == 2 and min(inner) >= 2
    except (ValueError, AssertionError):
        raise InvfaceError(f"--board {args.board!r}: give inner corners as COLSxROWS, e.g. 9x6") from None
    cam, rms, used = calibrate(args.images, inner=inner, square=args.square,
                               distortion=not args.no_distortion)
    cam.save(args.output)
    print(f"board found in {len(used)} of {len(args.images)} images; reprojection RMS {rms:.3f} px")
    print(f"fx {cam.K[0, 0]:.1f} fy {cam.K[1, 1]:.1f} cx {cam.K[0, 2]:.1f} cy {cam.K[1, 2]:.1f} px; "
          f"dist {[round(float(d), 4) for d in cam.dist]}")
    print(f"wrote {args.output}")
    return 0


def cmd_fit_scan(args):
    """Fit controls and pose to a 3D scan (Eq. 13); write fit.json and the fitted mesh."""
    from .pipeline import fit_scan
    _fresh_output(args.output, args.overwrite, folder=True)
    model = _load_model(args.model, args.resolution)
    bar = _bar(f"fit {args.model_kind} model to scan")
    try:
        result = fit_scan(args.scan, model, kind=args.model_kind, mode=args.mode, lam=args.lam,
                          max_iter=args.max_iter, unit=args.unit,
                          progress=lambda h: (bar.update(1), bar.set_postfix(cost=f"{h['cost']:.3g}")))
    finally:
        bar.close()
    page = result.save(args.output)
    print("\n".join(result.describe()))
    out = Path(args.output)
    print(f"wrote {out / 'fit.json'}, {out / 'fitted.ply'} and the report {page}")
    return 0


def _fit_frames(model, clip, cal, kinds, out, options, curves=None, force=False, workers=None, scheduler=None,
                run=None, security=None, exports=("csv", "usd"), usd_ascii=False):
    """Fit a clip's frames (``pipeline.sequence.fit_sequence``) with bars, a line per finished
    kind and the report paths; on a Dask cluster with ``workers`` or ``scheduler``. run: more
    keys for run.json (what the calibration was made from); exports: the formats written at the
    end (``pipeline.outputs.EXPORT_FORMATS``; the rigs from ``model``)."""
    from .pipeline import open_clip
    from .pipeline.outputs import sequence_summary
    from .pipeline.sequence import fit_sequence
    clip = open_clip(clip)
    bars = _FitBars()
    skipped = []

    def kind_done(frame, kind):
        bars.close()
        print(frame.describe(kind), flush=True)

    def frame_done(frame, folder, row):
        bars.close()
        if frame is None:
            skipped.append(row["name"])
            return
        for w in frame.warnings:
            print(f"warning: {w}", flush=True)
        for kind, why in frame.failed.items():
            print(f"{frame.name} {kind}: did not finish: {why}", flush=True)
        if frame.fits and len(clip) == 1:
            print(f"report: {folder / 'index.html'}")
    started = time.perf_counter()
    try:
        rows = fit_sequence(model, clip, cal, out, kinds, curves=curves, progress=bars, on_kind=kind_done,
                            on_frame=frame_done, force=force, keep=False, workers=workers, scheduler=scheduler,
                            extra=run, security=security, exports=exports, usd_ascii=usd_ascii, **options)
    finally:
        bars.close()
    distributed = (workers or scheduler) and len(clip) > 1
    for r in rows:
        if r.get("error"):
            print(f"warning: {r['name']}: not fitted: {r['error']}", flush=True)
        elif distributed:          # the workers' fits print nothing here
            for kind, k in r["kinds"].items():
                print(f"{r['name']} {kind}: curves {k['curve_rms_px']:.2f} px RMS"
                      + (f"; flagged: {k['flagged']}" if k["flagged"] else ""))
    if skipped:
        print(f"{len(skipped)} frame(s) finished before from the same inputs were skipped: "
              + ", ".join(skipped[:5]) + (" ..." if len(skipped) > 5 else ""))
    if len(clip) > 1:
        for line in sequence_summary(out, kinds, rows, len(rows) - len(skipped), time.perf_counter() - started):
            print(line)
    if not any(r["kinds"] for r in rows):      # exit non-zero only when no frame has any kind at all
        first = rows[0] if rows else {}
        raise InvfaceError(first.get("error") or f"{first.get('name', clip.source)}: no model kind finished: "
                           + "; ".join(f"{k}: {why}" for k, why in first.get("failed", {}).items()))
    rigs = [f for f in exports if f in ("usdskel", "gltf")]
    if rigs and out is not None:
        from .pipeline.outputs import export
        for path in export(out, rigs, model=model, usd_ascii=usd_ascii):
            print(f"the rig animated by the fit: {path}", flush=True)


def cmd_fit_plate(args):
    """Fit controls and pose to a plate, or to each frame of a video, sequence or folder."""
    from .fit.calibrate import Calibration
    from .pipeline import model_kinds, open_clip
    from .pipeline.session import prepare_run, shot_frame
    security = None
    if args.scheduler:                 # refused before any work: a plain-TCP address beyond loopback
        from .pipeline.distributed import scheduler_security
        security = scheduler_security(args.scheduler, args.tls_ca, args.tls_cert, args.tls_key, args.insecure)
    model = _load_model(args.model, args.resolution)
    # a given calibration is read before any work (the identity keeps the vertex count)
    given = Calibration.load(args.calib, vertex_count=len(model.neutral)) if args.calib else None
    clip = open_clip(args.plate, args.frames, args.camera, args.colorspace)
    print(clip.describe(), flush=True)
    kinds = model_kinds(args.model_kind)
    out = Path(args.output) if args.output else Path("reports") / "fit-plate" / Path(args.plate).stem
    identity = not args.no_identity
    shot = None
    if given is None or identity:
        over_shot = len(clip) > 1 and args.neutral_from == "shot"
        whole = open_clip(args.plate, None, args.camera, args.colorspace) if over_shot else None
        shot = shot_frame(model, clip, whole, args.neutral_frame, args.curves, args.face, args.curve_lambda,
                          progress=_events)

    def calibrate(model, plate, path, curves, source):          # with the bar; its warnings go to the notes
        return _calibrate(model, plate, path, 30, curves=curves, source=source, lam_curves=args.curve_lambda)

    model, cal, run = prepare_run(model, shot, out, given, identity, args.restart, args.curve_lambda, calibrate,
                                  progress=_events, identity_space=args.identity_space)
    options = dict(iterations=args.iterations, shading=not args.no_shading, lam_curves=args.curve_lambda,
                   solver=args.solver, temporal=args.temporal, temporal_shading=args.temporal_shading)
    if args.face:
        options["face"] = args.face
    _fit_frames(model, clip, cal, kinds, out, options, curves=args.curves, force=args.restart,
                workers=args.workers, scheduler=args.scheduler, run=run, security=security, exports=args.export,
                usd_ascii=args.usd_ascii)
    return 0


def cmd_report(args):
    """(Re)write the HTML report of a fit folder."""
    from .report.fit import write_report
    from .report.sequence import sequence_frames, write_sequence_report
    run = Path(args.run)
    single = (run / "fit.json").is_file() or any(run.glob("*/fit.json"))
    print(f"report: {write_report(run) if single or not sequence_frames(run) else write_sequence_report(run)}")
    return 0


def cmd_export(args):
    """Write an existing fit run's exports (``pipeline.outputs.export``)."""
    from .pipeline.outputs import export
    for path in export(args.run, [f.strip() for f in args.format.split(",") if f.strip()], fps=args.fps,
                       model=args.model, usd_ascii=args.usd_ascii):
        print(f"wrote {path}")
    return 0


def cmd_demo(args):
    """Build the template, write previews and expression sheets, then calibrate and fit a plate."""
    from .pipeline import build_model
    out = Path(args.output)
    _fresh_output(out, args.overwrite, folder=True)
    print("invface demo: building the built-in anatomical head", flush=True)
    build = build_model(progress=_events)
    model = build.model
    print("\n".join(build.describe()))
    paths = build.save(out / "template_head.npz", preview=out / "preview")[1:]
    if model.blendshape_names:
        from .report.expressions import write_expression_sheet
        print(f"expression contact sheet: {write_expression_sheet(model, out / 'expressions.png')}")
        print("the same shapes through the blendshape-driven muscle simulation", flush=True)
        sheet = write_expression_sheet(model, out / "expressions_simulation.png", kind="simulation",
                                       progress=_progress)
        print(f"simulation contact sheet: {sheet}")
    from .io.jsonfile import write_object
    write_object(out / "summary.json", model.summary(), indent=2)
    print(f"wrote {out / 'template_head.npz'}, {len(paths)} preview images; open {paths[-1]}")
    _demo_fit(model, out)
    from .report.demo import write_demo_index
    print(f"the demo's page, linking all of it: {write_demo_index(out)}")
    return 0


def cmd_samples(args):
    """Inputs to try every recipe on, with no downloads: scikit-image's astronaut portrait (public
    domain) as a photo; the built-in head rendered as a clip and as sample plates, each with its
    truth; and the head's skin, made wider and smiling, as a scan to build an actor from."""
    import numpy as np
    from skimage.data import astronaut
    from .fit.samples import write_sample_clip, write_sample_plates
    from .io.images import write_display_image
    from .io.meshes import write_mesh
    out = Path(args.output)
    _fresh_output(out, args.overwrite, folder=True)
    photo = write_display_image(out / "photo.png", astronaut())
    print(f"a photo: {photo} (scikit-image's astronaut, public domain)", flush=True)
    model = _load_model(None, args.resolution)
    plates = write_sample_plates(model, out / "plates", progress=_progress)
    print(f"sample plates with known controls, light and albedo: {len(plates)} in {out / 'plates'} "
          "(NAME.truth.json beside each)", flush=True)
    _, clip = write_sample_clip(model, out / "clip", n=args.frames, progress=_progress)
    print(f"a clip of {args.frames} frames with its truth per frame: {clip}", flush=True)
    skin = model.surface({"mouthSmileLeft": 0.5, "mouthSmileRight": 0.5}, kind="blendshape")
    scan = skin * np.array([1.05, 0.98, 1.0])                  # another face: wider, a little shorter
    print(f"a scan (the head's skin made wider and smiling, in metres): {write_mesh(out / 'scan.obj', scan, model.triangles)}")
    return 0


def _demo_fit(model, out):
    """Sample plates with known controls; calibrate on the neutral one (Eq. 14), fit the
    simulation-made smile with both model kinds (Eq. 15-16), write the report."""
    from .fit.samples import write_sample_plates
    from .io.jsonfile import read_object
    from .pipeline import as_plate
    folder = out / "plates"
    print("rendering sample plates (known controls, light and albedo)", flush=True)
    neutral, smile = write_sample_plates(model, folder, names=["neutral", "smile_simulation"], progress=_progress)
    truth = read_object(folder / "neutral.truth.json", what="ground-truth file")
    print("lighting/albedo calibration (Eq. 14) on the neutral plate", flush=True)
    cal = _calibrate(model, as_plate(neutral), out / "calib.npz", 30,
                     pose=(truth["rotation"], truth["translation"])).calibration
    print("fitting the smile plate (made by the muscle simulation) with both models", flush=True)
    _fit_frames(model, smile, cal, ("blendshape", "simulation"), out / "fit-smile",
                {"title": "invface demo: a simulation-made smile fitted by both models"}, force=True)


CURVE_LAMBDA_HELP = ("weight regulariser lambda_1 of the curve fit, Eq. 15 (px^2; default: the paper's 3600 "
                     "scaled with the face's size, 3600 (d / 224)^2 for a face d px between the outer eye "
                     "corners, 224 on the sample plates)")
COLORSPACE_HELP = ("the plate files' colour space, converted to linear Rec.709 for Eq. 14/16: sRGB, linear, "
                   "Cineon, or a colour space of OpenColorIO's ACES studio config (ACEScct, ACEScg, "
                   "'ARRI LogC3 (EI800)', 'S-Log3 S-Gamut3', ...; docs/formats.md); default: sRGB for "
                   "8/16-bit integer files and video, linear for float files (EXR), the DPX header's "
                   "transfer for DPX (Cineon log when it says printing density, log or nothing)")


def _number(cast, low=None, strict=False):
    """An argparse type: a finite number of ``cast`` (int or float) at least ``low`` (above it
    when ``strict``); argparse names the option when it refuses one."""
    def check(text):
        try:
            v = cast(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {'an integer' if cast is int else 'a number'}, not {text!r}")
        if cast is float and not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"must be a finite number, not {text}")
        if low is not None and (v <= low if strict else v < low):
            raise argparse.ArgumentTypeError(f"must be {'>' if strict else '>='} {low:g}, not {text}")
        return v
    return check


class _DefaultsHelp(argparse.RawDescriptionHelpFormatter):
    """Help that states each option's default: appended as "(default: X)" where the option has a
    value for it and its text does not describe the default already."""

    def _get_help_string(self, action):
        text = action.help or ""
        if action.default in (None, False, argparse.SUPPRESS) or "default" in text.lower():
            return text
        return text + " (default: %(default)s)"


POSITIVE = _number(float, 0, strict=True)
NON_NEGATIVE = _number(float, 0)
FINITE = _number(float)
COUNT = _number(int, 1)
NON_NEGATIVE_INT = _number(int, 0)


def EXPORTS(text):
    """argparse type: comma-separated export formats (``pipeline.outputs.EXPORT_FORMATS``)."""
    from .pipeline.outputs import EXPORT_FORMATS
    formats = tuple(f.strip().lower() for f in text.split(",") if f.strip())
    bad = [f for f in formats if f not in EXPORT_FORMATS]
    if bad or not formats:
        raise argparse.ArgumentTypeError(f"{text!r}: use one or more of {', '.join(EXPORT_FORMATS)}")
    return formats


def COLORSPACE(text):
    """argparse type: a colour-space name (``io.colorspaces.resolve``), checked before any work."""
    from .io.colorspaces import resolve
    try:
        return resolve(text)
    except InvfaceError as e:
        raise argparse.ArgumentTypeError(f"{text!r}: " + str(e).split(": ", 1)[1]) from None


def build_parser():
    """The CLI's parser: one sub-command per verb (``_add_*``), each with its worked example
    (``EXAMPLES``) under its help."""
    p = argparse.ArgumentParser(prog="invface", description="Anatomically based, differentiable face capture.")
    from . import __version__
    p.add_argument("--version", action="version", version=f"invface {__version__}")
    p.add_argument("--debug", action="store_true", help="show tracebacks and native libraries' log lines "
                                                        "(also INVFACE_DEBUG=1)")
    # every verb's help states its defaults
    verb = functools.partial(argparse.ArgumentParser, formatter_class=_DefaultsHelp)
    sub = p.add_subparsers(dest="command", required=True, parser_class=verb)
    _add_build_model(sub)
    _add_simulate(sub)
    _add_calibrate(sub)
    _add_fit_scan(sub)
    _add_fit_plate(sub)
    _add_report_and_export(sub)
    _add_camera(sub, verb)
    _add_demo_and_samples(sub)
    for words, example in EXAMPLES.items():
        parser = sub.choices[words[0]]
        for w in words[1:]:
            parser = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction)).choices[w]
        parser.epilog = "example:\n" + "\n".join("  " + line for line in example)
    return p


def _model_options(parser):
    """--model and --resolution: which FaceModel a verb uses."""
    parser.add_argument("--model", help="a FaceModel bundle (default: the built-in template)")
    parser.add_argument("--resolution", type=POSITIVE, default=1.0,
                        help="template size factor when no --model (dimensionless; 1 = ~35k tets)")


def _add_build_model(sub):
    """The build-model verb."""
    b = sub.add_parser("build-model", help="build (or inspect) a FaceModel bundle")
    b.add_argument("input", nargs="?", help="an existing bundle to summarise/preview")
    b.add_argument("--template", action="store_true", help="the built-in template head (default)")
    b.add_argument("--neutral", help="the actor's neutral scan (OBJ/PLY) to morph the template onto")
    b.add_argument("--blendshapes", metavar="DIR", help="the actor's blendshapes (OBJ/PLY, the neutral's topology)")
    b.add_argument("--unit", choices=["m", "cm", "mm"],
                   help="the scan's unit (default: found from the face's size; a scan whose face fits no unit is "
                        "scaled to an adult face)")
    b.add_argument("--expressions", choices=["copy", "simulate", "none"], default="copy",
                   help="without --blendshapes: carry the template's 52 ARKit shapes onto the actor (copy), "
                        "simulate the template's older FACS-style action units on the new anatomy, or none. "
                        "With --blendshapes named in ARKit's or ICT-FaceKit's style, the controls the folder "
                        "lacks are filled from the template")
    b.add_argument("--resolution", type=POSITIVE, default=1.0, help="template size factor (dimensionless; 1 = ~35k tets)")
    b.add_argument("--force", action="store_true", help="regenerate instead of using the cache")
    b.add_argument("-o", "--output", help="write the bundle here (.npz)")
    b.add_argument("--overwrite", action="store_true", help="replace an existing output (refused otherwise)")
    b.add_argument("--preview", metavar="DIR", help="write preview images into DIR")
    b.set_defaults(func=cmd_build_model)


def _add_simulate(sub):
    """The simulate verb."""
    s = sub.add_parser("simulate", help="pose the model by muscle activations or blendshape-driven tracks "
                                        "(quasistatic simulation)")
    _model_options(s)
    s.add_argument("--activations", help='JSON file: {"activations": {"zygomaticus_major_L": 0.8, ...}, "jaw": [6]}')
    s.add_argument("--set", action="append", metavar="MUSCLE=A", help="set one activation (repeatable)")
    s.add_argument("--weight", action="append", metavar="SHAPE=W",
                   help="blendshape weight driving the muscle tracks (repeatable; paper 000 Sec. 6)")
    s.add_argument("--jaw", type=FINITE, help="jaw opening angle (rad) about the hinge; default: closed, or as the weights' tracks set it")
    s.add_argument("-o", "--output", help="write the posed skin mesh (OBJ/PLY)")
    s.add_argument("--overwrite", action="store_true", help="replace an existing output (refused otherwise)")
    s.add_argument("--preview", help="write a PNG: neutral (top) and posed (bottom), front and 3/4")
    s.set_defaults(func=cmd_simulate)


def _add_calibrate(sub):
    """The calibrate verb (Eq. 14)."""
    c = sub.add_parser("calibrate", help="solve SH lighting and per-vertex albedo on a neutral plate (Eq. 14)")
    c.add_argument("plate", help="plate image (EXR, DPX, TIFF, PNG, JPEG, ...; see --colorspace)")
    c.add_argument("--colorspace", type=COLORSPACE, help=COLORSPACE_HELP)
    c.add_argument("--camera", help="JSON camera file (default: PLATE.json beside the plate, else the "
                                    "front view)")
    _model_options(c)
    c.add_argument("--pose", type=FINITE, nargs=6, metavar=("RX", "RY", "RZ", "TX", "TY", "TZ"),
                   help="rigid head pose: Euler XYZ (rad) and translation (m); default identity")
    c.add_argument("--auto-pose", action="store_true",
                   help="pose (and expression) from the plate's curves first, for a plate of unknown pose")
    c.add_argument("--curves", help="plate curve file (JSON) for --auto-pose; default PLATE.curves.json "
                   "beside the plate, else the landmark detector")
    c.add_argument("--curve-lambda", type=NON_NEGATIVE, help=CURVE_LAMBDA_HELP)
    c.add_argument("--lam", type=NON_NEGATIVE, help="albedo smoothness weight lambda of Eq. 14 (dimensionless: linear light^2 per albedo difference^2; default: the paper's "
                                             "2500; with --auto-pose scaled with the face's size like lambda_1)")
    c.add_argument("--max-iter", type=COUNT, default=30, help="Gauss-Newton iterations at most")
    c.add_argument("--robust", action="store_true",
                   help="for a plate with something over the face (a hand, hair): after a stiff first solve, "
                        "pixels the face's light and albedo cannot explain weigh less (two reweighted solves); "
                        "on clean real photos it also takes brows and lips out of the albedo")
    c.add_argument("-o", "--output", default="calib.npz", help="calibration file to write (.npz)")
    c.add_argument("--overwrite", action="store_true", help="replace an existing output (refused otherwise)")
    c.set_defaults(func=cmd_calibrate)


def _add_fit_scan(sub):
    """The fit-scan verb (Eq. 13)."""
    from .fit.lambdas import EQ13_LAMBDA
    fs = sub.add_parser("fit-scan", help="fit controls and rigid pose to a 3D scan (Eq. 13)")
    fs.add_argument("scan", help="scan mesh (OBJ/PLY, model frame: +Y up, face along +Z)")
    fs.add_argument("--unit", choices=["m", "cm", "mm"], help="the scan's unit (default: found from its size)")
    _model_options(fs)
    fs.add_argument("--model-kind", choices=["blendshape", "simulation"], default="blendshape",
                    help="blendshape: the rig alone (paper 000 Eq. 1-2, fast); simulation: the muscle-driven flesh")
    fs.add_argument("--mode", choices=["correspondence", "nearest"], default="correspondence",
                    help="correspondence: same topology as the model; nearest: any mesh, point-to-plane")
    fs.add_argument("--lam", type=NON_NEGATIVE, default=EQ13_LAMBDA, help="weight regulariser lambda of Eq. 13 (m^2 per unit weight^2, the residuals being in m; paper: 1e-6)")
    fs.add_argument("--max-iter", type=COUNT, default=50, help="dogleg iterations at most (per round)")
    fs.add_argument("-o", "--output", default="reports/fit-scan", help="output folder")
    fs.add_argument("--overwrite", action="store_true", help="replace an existing output (refused otherwise)")
    fs.set_defaults(func=cmd_fit_scan)


def _add_fit_plate(sub):
    """The fit-plate verb (Eq. 15-16, a photo, a sequence or a clip)."""
    from .fit.lambdas import EQ16_TEMPORAL, TEMPORAL_LAMBDA
    fp = sub.add_parser("fit-plate", help="fit controls and pose to a film plate: curves (Eq. 15), then "
                                          "shape from shading (Eq. 16); a folder is a sequence")
    fp.add_argument("plate", help="plate image (EXR, DPX, TIFF, PNG, JPEG, ...), a numbered sequence "
                                  "(shot.####.dpx, shot.%%04d.exr), a video (MP4/MOV/AVI/MKV) or a folder of frames: "
                                  "a sequence, each frame started from the two before it")
    fp.add_argument("--frames", help="frames to fit: FIRST-LAST[xSTEP] in the source's own frame numbers, both ends "
                                     "included as in VFX ranges (e.g. 1001-1072x2), or START:STOP[:STEP] positions "
                                     "(Python slice, end left out, e.g. 0:72:2), or one position; default all")
    fp.add_argument("--colorspace", type=COLORSPACE, help=COLORSPACE_HELP)
    fp.add_argument("--export", type=EXPORTS, default=("csv", "usd"), metavar="FORMATS",
                    help="what the run writes for the user's pipeline, comma-separated: csv (Live Link Face, "
                         "arkit_<kind>.csv), usd (the take: face_<kind>.usd with the camera and the plate card), "
                         "usdskel (the rig in UsdSkel, rig_<kind>.usd), gltf (the rig, rig_<kind>.glb); "
                         "default csv,usd; 'invface export' writes them later")
    fp.add_argument("--usd-ascii", action="store_true", help="write the USD files as text (.usda), not binary (.usd)")
    fp.add_argument("--neutral-frame", type=NON_NEGATIVE_INT, help="frame number to calibrate on when no --calib "
                    "(default: the most neutral-looking of 8 frames spread over --neutral-from)")
    fp.add_argument("--neutral-from", choices=["selection", "shot"], default="selection",
                    help="where the calibration and identity frame is looked for: the frames --frames selects, or "
                         "the whole shot (for a selection where something covers the face or the eyes are shut; "
                         "a neutral frame from elsewhere can fit a selection of broad expressions worse)")
    fp.add_argument("--temporal", type=NON_NEGATIVE, default=TEMPORAL_LAMBDA,
                    help="weight of the temporal term between consecutive frames (px^2 per 0.1 weight, 0.01 rad "
                         f"or 1 mm; scaled with the face like lambda_1; default {TEMPORAL_LAMBDA:g}, 0 = off)")
    fp.add_argument("--temporal-shading", type=NON_NEGATIVE, default=EQ16_TEMPORAL,
                    help="the temporal term's weight in shape from shading (Eq. 16), as a share of --temporal "
                         f"(linear light per px^2; default {EQ16_TEMPORAL:g}, 0 = curve stage only)")
    fp.add_argument("--workers", type=COUNT, help="fit frames on a local Dask cluster of this many processes "
                                                "(contiguous chunks, one per worker; default: this process)")
    fp.add_argument("--scheduler", help="address of a running Dask scheduler to fit on: tls://HOST:8786 with "
                                        "--tls-ca/--tls-cert/--tls-key (or Dask's TLS config), or tcp:// on this "
                                        "machine; its workers must see the output folder")
    fp.add_argument("--tls-ca", help="with a tls:// --scheduler: the CA certificate (PEM) that signed the cluster's")
    fp.add_argument("--tls-cert", help="with a tls:// --scheduler: this client's certificate (PEM)")
    fp.add_argument("--tls-key", help="with a tls:// --scheduler: this client's private key (PEM)")
    fp.add_argument("--insecure", action="store_true",
                    help="allow a plain tcp:// --scheduler on another machine (data travels pickled: anyone who "
                         "can reach the scheduler can run code here; only on a network you trust)")
    fp.add_argument("--calib", help="calibration from 'invface calibrate' (.npz); default: calibrate on the "
                                    "(first) plate itself, posed from its curves, and write DIR/calib.npz")
    fp.add_argument("--curves", help="plate curve file (JSON); default PLATE.curves.json beside the plate, "
                                     "else the automatic landmark detector")
    fp.add_argument("--face", type=NON_NEGATIVE_INT, default=0,
                    help="which face the detector fits when the plate shows several (an index from 0): 0 the first found (the whole "
                         "frame first, then crops around face proposals, largest first), 1 the next, ...")
    fp.add_argument("--camera", help="JSON camera file (default: PLATE.json beside the plate, else the front view)")
    _model_options(fp)
    fp.add_argument("--model-kind", choices=["blendshape", "simulation", "both"], default="blendshape",
                    help="blendshape: the rig alone (paper 000 Eq. 1-2, fast); simulation: the muscle-driven flesh "
                    "(lips keep their volume, contacts hold); both: each, compared in the report")
    fp.add_argument("--curve-lambda", type=NON_NEGATIVE, help=CURVE_LAMBDA_HELP)
    fp.add_argument("--iterations", type=NON_NEGATIVE_INT, default=25, help="shape-from-shading iterations at most")
    fp.add_argument("--solver", choices=["dogleg", "lbfgs"], default="dogleg",
                    help="shape-from-shading solver: the paper's dogleg (Gauss-Newton on forward-mode "
                         "image Jacobians) or L-BFGS-B on adjoint gradients (for many controls)")
    fp.add_argument("--no-shading", action="store_true", help="curves only (Eq. 15)")
    fp.add_argument("--no-identity", action="store_true",
                    help="fit with the model as it is (default: its neutral first adapted to the actor, its "
                         "proportions and a smooth field, from the curves of the photo or of a sequence's "
                         "calibration frame, written to DIR/actor.npz)")
    fp.add_argument("--identity-space", action="store_true",
                    help="start the actor's identity in the face-shape space (ICT-FaceKit's 20 identity shapes), "
                         "then the proportions and the field; in a clip, shared by the frames looked at for the "
                         "calibration that show the head from another side (0.1 rad apart); a trial: see "
                         "bench/identity_3d.py for how near the true face it comes in 3D")
    fp.add_argument("--restart", "--force", dest="restart", action="store_true",
                    help="start over: replace an earlier run's fits in the output folder (a rerun with the same "
                         "inputs otherwise resumes it, skipping the frames already fitted)")
    fp.add_argument("-o", "--output", help="report folder (default reports/fit-plate/PLATE)")
    fp.set_defaults(func=cmd_fit_plate)


def _add_report_and_export(sub):
    """The report and export verbs, which read a run written earlier."""
    rp = sub.add_parser("report", help="(re)write the HTML report of a fit folder")
    rp.add_argument("run", help="folder with fit.json (or sub-folders with one each)")
    rp.set_defaults(func=cmd_report)
    ex = sub.add_parser("export", help="write an existing fit run's exports into its folder: the Live Link Face CSV "
                                       "of ARKit's 52 controls, the take in USD, the rig in UsdSkel or glTF")
    ex.add_argument("run", help="a fit-plate output folder")
    ex.add_argument("--format", default="csv", help="comma-separated formats: csv (arkit_<kind>.csv: Live Link Face "
                    "CSV), usd (face_<kind>.usd: the fitted face's points per frame in cm, +Y up, the solved "
                    "camera and the ARKit controls as animated attributes), usdskel (rig_<kind>.usd: the "
                    "model's blendshape rig in UsdSkel, its shapes by ARKit's names, animated by the fit), "
                    "gltf (rig_<kind>.glb: the same rig as glTF 2.0 morph targets and a skin) (default: %(default)s)")
    ex.add_argument("--model", help="for usdskel and gltf: the model bundle the run was fitted with (default: the run's "
                    "actor.npz, else the built-in head)")
    ex.add_argument("--usd-ascii", action="store_true", help="write the USD files as text (.usda), not binary (.usd)")
    ex.add_argument("--fps", type=POSITIVE, help="the clip's frame rate (frames per second) for the timecodes "
                    "(default: the run's, else 24)")
    ex.set_defaults(func=cmd_export)


def _add_camera(sub, verb):
    """The camera verb and its calibrate tool."""
    cam = sub.add_parser("camera", help="camera tools")
    camsub = cam.add_subparsers(dest="camera_command", required=True, parser_class=verb)
    cc = camsub.add_parser("calibrate", help="intrinsics and distortion from checkerboard images (OpenCV)")
    cc.add_argument("images", nargs="+", help="checkerboard photographs")
    cc.add_argument("--board", default="9x6", help="inner corners COLSxROWS (default 9x6)")
    cc.add_argument("--square", type=POSITIVE, default=0.025, help="square size in metres")
    cc.add_argument("--no-distortion", action="store_true", help="fit K only")
    cc.add_argument("-o", "--output", default="camera.json", help="JSON camera file to write")
    cc.add_argument("--overwrite", action="store_true", help="replace an existing output (refused otherwise)")
    cc.set_defaults(func=cmd_camera_calibrate)


def _add_demo_and_samples(sub):
    """The demo and samples verbs."""
    d = sub.add_parser("demo", help="run the main job on the built-in model")
    d.add_argument("-o", "--out", "--output", dest="output", default="reports/demo", help="output folder")
    d.add_argument("--overwrite", action="store_true", help="replace an existing output (refused otherwise)")
    d.set_defaults(func=cmd_demo)
    sa = sub.add_parser("samples", help="write inputs to try invface on, with no downloads: a photo, a clip "
                                        "and sample plates with known truth, and a scan")
    sa.add_argument("output", nargs="?", default="samples", help="folder to write them into")
    sa.add_argument("--resolution", type=POSITIVE, default=1.0, help="template size factor (dimensionless) of the head that "
                                                                     "renders the clip, the plates and the scan")
    sa.add_argument("--frames", type=COUNT, default=24, help="the clip's length in frames (at 24 fps)")
    sa.add_argument("--overwrite", action="store_true", help="replace an existing output (refused otherwise)")
    sa.set_defaults(func=cmd_samples)


# one worked example per verb, shown under its --help and in docs/cli.md
EXAMPLES = {
    ("build-model",): ["invface build-model --neutral scan.obj -o actor.npz --preview actor",
                       "invface build-model actor.npz --preview actor     # summarise an existing bundle"],
    ("simulate",): ["invface simulate --weight mouthSmileLeft=0.8 --weight jawOpen=0.3 -o smile.obj --preview smile.png"],
    ("calibrate",): ["invface calibrate plates/neutral.png -o calib.npz"],
    ("fit-scan",): ["invface fit-scan expression.obj --model actor.npz --mode nearest --model-kind simulation -o fit"],
    ("fit-plate",): ["invface fit-plate photo.jpg --model-kind both -o fit",
                     "invface fit-plate clip.mp4 --frames 0:240 --model-kind both --workers 2 -o take"],
    ("report",): ["invface report fit"],
    ("export",): ["invface export take --format csv,usd,usdskel,gltf"],
    ("camera", "calibrate"): ["invface camera calibrate board/*.jpg --board 9x6 --square 0.025 -o camera.json"],
    ("demo",): ["invface demo -o reports/demo"],
    ("samples",): ["invface samples samples     # then: invface fit-plate samples/photo.png -o fit"],
}


def _os_error(e):
    """One line for an OSError: the file it names and what to do."""
    import errno
    where = e.filename if e.filename is not None else "a file"
    fix = {errno.EACCES: "it is not writable (or readable) by you: choose another folder or fix its permissions",
           errno.EPERM: "the operation is not permitted there: choose another folder",
           errno.EROFS: "it is on a read-only file system: choose another folder",
           errno.ENOSPC: "the disk is full: free some space or write elsewhere",
           errno.EFBIG: "the file would be larger than allowed (disk quota or ulimit -f): write elsewhere",
           errno.ENOENT: "no such file or folder: check the path",
           errno.ENOTDIR: "a part of the path is a file, not a folder: check the path",
           errno.EEXIST: "a file stands where a folder is needed: choose another output path",
           errno.EISDIR: "it is a folder, not a file: give a file"}.get(e.errno, e.strerror or str(e))
    return f"{where}: {fix}"


def main(argv=None):
    """Run the CLI: exit 0 on success, 2 with one line naming the input or option and the fix
    for bad input (InvfaceError, OSError, MemoryError, OpenCV's refusals), 1 with one line for
    an internal error (a bug; ``--debug`` or INVFACE_DEBUG=1 shows its traceback)."""
    try:
        args = build_parser().parse_args(argv)
    except SystemExit as e:            # argparse's refusal (its last line names the option) or --help
        return e.code if isinstance(e.code, int) else 2
    if getattr(args, "debug", False):
        os.environ["INVFACE_DEBUG"] = "1"
    from ._env import debugging
    try:
        return args.func(args)
    except InvfaceError as e:
        print(f"invface: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        if debugging():
            raise
        print(f"invface: error: {_os_error(e)}", file=sys.stderr)
        return 2
    except MemoryError:
        if debugging():
            raise
        print("invface: error: out of memory: use a smaller --resolution, a smaller image or fewer --workers",
              file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("invface: interrupted", file=sys.stderr)
        return 130
    except Exception as e:                                     # noqa: BLE001 - the last line of defence
        if debugging():
            raise
        if type(e).__module__.split(".")[0] == "cv2":                # cv2.error: an input OpenCV refused
            print(f"invface: error: OpenCV refused the input: {str(e).strip().splitlines()[-1]}", file=sys.stderr)
            return 2
        print(f"invface: internal error: {type(e).__name__}: {e} (this is a bug: rerun with --debug, or "
              "INVFACE_DEBUG=1, for the traceback)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
