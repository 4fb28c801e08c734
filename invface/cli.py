"""The ``invface`` command line. InvfaceErrors print as one line and exit with status 2."""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from .errors import InvfaceError


def _progress(msg):
    print(f"  .. {msg}", flush=True)


def _print_summary(model, seconds):
    s = model.summary()
    print(f"surface: {s['surface_vertices']} vertices, {s['surface_triangles']} triangles; "
          f"blendshapes: {s['blendshapes']}; skin embedding: {s['skin_embedding']}")
    print(f"flesh:   {s['vertices']} vertices, {s['tets']} tets, volume {s['volume_m3'] * 1e6:.0f} cm^3; "
          f"fixed: {s['fixed_cranium']} cranium, {s['fixed_jaw']} jaw")
    print(f"quality: min dihedral {s['min_dihedral_deg']:.2f} deg, max dihedral {s['max_dihedral_deg']:.1f} deg, "
          f"radius ratio min {s['min_radius_ratio']:.3f} / mean {s['mean_radius_ratio']:.3f}, inverted {s['inverted']}")
    print(f"muscles: {s['muscles']} ({s['muscle_tets']} muscle tets); landmarks: {s['landmarks']}; curves: {s['curves']}")
    print(f"time:    {seconds:.1f} s")


def cmd_build_model(args):
    from . import template
    from .model import FaceModel
    t0 = time.perf_counter()
    if args.neutral:
        return _build_from_scan(args, t0)
    if args.template or not args.input:
        print(f"building the template head (resolution {args.resolution:g})", flush=True)
        model = template.build(resolution=args.resolution, force=args.force, progress=_progress)
    else:
        model = FaceModel.load(args.input)
    if args.output:
        model.save(args.output)
        print(f"wrote {args.output}")
    _print_summary(model, time.perf_counter() - t0)
    if args.preview:
        from .report.preview import write_previews
        paths = write_previews(model, args.preview)
        print(f"previews: {len(paths)} images in {args.preview} (contact sheet: {paths[-1]})")
    return 0


def _build_from_scan(args, t0):
    """build-model --neutral: morph the template onto the actor's scan (paper 001)."""
    import json

    from . import template
    from .morph.build import build_model
    if not args.output:
        raise InvfaceError("build-model --neutral needs -o/--output for the new model (.npz)")
    tpl = template.build(resolution=args.resolution, progress=_progress)
    model, result = build_model(args.neutral, blendshapes=args.blendshapes, template=tpl, unit=args.unit,
                                expressions=args.expressions, progress=_progress)
    model.save(args.output)
    st = result.stats
    print(f"wrote {args.output}")
    print(f"scan unit {st['unit']} (x{st['scale']:g} to metres); symmetry error {st['symmetry_error_mm']:.2f} mm; "
          f"alignment residual {st['alignment_residual_mm']:.2f} mm")
    print(f"skin to scan: mean {st['surface_to_target_mm']['mean']:.3f} mm, max {st['surface_to_target_mm']['max']:.2f} mm; "
          f"{100 * st['snapped_fraction']:.1f}% of the template skin on the scan")
    print("stage seconds: " + json.dumps(result.seconds))
    _print_summary(model, time.perf_counter() - t0)
    if args.preview:
        from .report.morph import write_morph_preview
        from .report.preview import write_previews
        sheet = write_morph_preview(model, result, args.preview, template=tpl)
        write_previews(model, args.preview)
        print(f"previews in {args.preview} (morph sheet: {sheet})")
    return 0


def _load_model(path, resolution):
    from . import template
    from .model import FaceModel
    if path:
        return FaceModel.load(path)
    return template.build(resolution=resolution, progress=_progress)


def _read_activations(path):
    """{muscle: activation} and optional jaw (6,) from a JSON file {"activations": {...}, "jaw": [...]}
    (a plain {muscle: value} mapping is accepted too)."""
    from .jsonfile import read_object
    data = read_object(path, what="activations file")
    acts = data.get("activations", {k: v for k, v in data.items() if k != "jaw"})
    if not isinstance(acts, dict):
        raise InvfaceError(f"{path}: 'activations' must be an object {{muscle name: value}}")
    return acts, data.get("jaw")


def cmd_simulate(args):
    """Pose the model by muscle activations (and jaw), or by blendshape weights through the
    blendshape-driven muscle simulation; report the solve, render a preview."""
    import numpy as np

    from .sim.quasistatic import Simulator
    acts, jaw = _read_activations(args.activations) if args.activations else ({}, None)
    for item in args.set or []:
        name, _, value = item.partition("=")
        acts[name] = value
    if args.jaw is not None:
        jaw = [args.jaw, 0, 0, 0, 0, 0]
    model = _load_model(args.model, args.resolution)
    progress = lambda i, r: print(f"  .. Newton {i}: relative residual {r:.2e}", flush=True)  # noqa: E731
    if args.weight:
        if acts:
            raise InvfaceError("give muscle activations (--activations/--set) or blendshape weights "
                               "(--weight), not both: with weights the activations follow from the tracks")
        weights = {}
        for item in args.weight:
            name, _, value = item.partition("=")
            try:
                weights[name] = float(value)
            except ValueError:
                raise InvfaceError(f"--weight {item}: expected NAME=NUMBER") from None
        ds = model.surface_model("simulation")
        p = model.parameters({"weights": weights, "jaw": jaw if jaw is not None else np.zeros(6)})
        r = ds.solve(p, warm=None, progress=progress)
        res, sim, x = r.sim, ds.sim, ds.surface_of(r)
        a = r.tracks.activations
        top = [i for i in np.argsort(-a) if a[i] > 0.01][:8]
        print("muscle activations from the tracks: "
              + (", ".join(f"{model.muscles[i].name} {a[i]:.2f}" for i in top) or "none"))
    else:
        sim = Simulator(model)
        res = sim.solve(acts, jaw=jaw, progress=progress)
        x = sim.surface(res)
    print(res.report())
    d = np.linalg.norm(x - model.neutral, axis=1)
    dv = sim.volume_change(res)
    print(f"skin displacement: max {d.max() * 1000:.2f} mm, mean {d.mean() * 1000:.2f} mm; "
          f"flesh volume change {dv * 100:+.3f} %")
    if args.output:
        _save_mesh(args.output, x, model.triangles)
        print(f"wrote {args.output}")
    if args.preview:
        _write_pose_preview(model, x, args.preview)
        print(f"wrote {args.preview}")
    return 0


def _save_mesh(path, vertices, faces):
    import os

    import trimesh
    path = Path(path)
    tmp = path.with_name(path.stem + ".tmp" + path.suffix)
    trimesh.Trimesh(vertices, faces, process=False).export(tmp)
    os.replace(tmp, path)


def _write_pose_preview(model, x, path):
    import os

    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    from .report.expressions import view_tiles
    img = np.concatenate([np.concatenate(view_tiles(model, v, 400, 16), 1) for v in (model.neutral, x)], 0)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.stem + ".tmp.png")
    plt.imsave(tmp, img)
    os.replace(tmp, path)


def _pose(values, option="--pose"):
    import numpy as np
    if values is None:
        return np.zeros(3), np.zeros(3)
    v = np.asarray(values, float)
    if v.shape != (6,) or not np.all(np.isfinite(v)):
        raise InvfaceError(f"{option} needs 6 finite numbers: rx ry rz (rad) tx ty tz (m)")
    return v[:3], v[3:]


def run_calibration(model, plate, out, rotation, translation, lam, max_iter, shape=None):
    """Eq. 14 on a loaded plate with a progress bar; writes out (.npz) and out's _compare.png.
    shape (V, 3) m: the unposed surface seen on the plate (default: the neutral)."""
    from tqdm import tqdm

    from .fit.calibrate import calibrate, comparison_image
    from .render.plates import write_image
    out = Path(out)
    bar = tqdm(total=max_iter, desc="calibrate lighting/albedo", unit="it", leave=False)

    def progress(h):
        bar.update(1)
        bar.set_postfix(rms=f"{h['rms']:.4f}")
    try:
        shape = model.neutral if shape is None else shape
        cal = calibrate(model.triangles, shape, plate.image, plate.camera, rotation,
                        translation, lam=lam, mask=plate.mask, max_iter=max_iter, progress=progress)
    finally:
        bar.close()
    cal.plate = plate.path
    out.parent.mkdir(parents=True, exist_ok=True)
    cal.save(out)
    h = cal.history[-1]
    compare = write_image(out.with_name(out.stem + "_compare.png"),
                          comparison_image(model.triangles, shape, cal, plate.image))
    print(f"calibrated in {len(cal.history)} iterations, {h['seconds']:.1f} s: pixel RMS {h['rms']:.4f} "
          f"(linear), light DC {cal.gamma[0].round(3).tolist()}")
    print(f"wrote {out} and {compare} (plate | render | 4x difference)")
    return cal


def cmd_calibrate(args):
    """Lighting and albedo calibration (Eq. 14) on a neutral plate."""
    from .render.plates import load_plate
    model = _load_model(args.model, args.resolution)
    plate = load_plate(args.plate, camera=args.camera)
    shape = model.neutral
    if args.auto_pose:
        if args.pose is not None:
            raise InvfaceError("give either --pose or --auto-pose, not both")
        shape, rotation, translation = pose_from_curves(model, plate, args.curves, args.curve_lambda)
    else:
        rotation, translation = _pose(args.pose)
    run_calibration(model, plate, args.output, rotation, translation, args.lam, args.max_iter, shape)
    return 0


def pose_from_curves(model, plate, curves_path, lam):
    """Pose and expression from the plate's curves (Eq. 15, blendshape rig) for a plate whose
    pose is unknown (a photo): (unposed surface (V, 3) m, rotation (3,) rad, translation (3,) m)."""
    import numpy as np

    from .fit.curves import fit_curves
    curves, source = plate_curves(model, plate, curves_path)
    cf = fit_curves(model, plate.camera, curves, kind="blendshape", lam=lam)
    top = sorted(zip(model.blendshape_names, cf.p), key=lambda kv: -kv[1])[:4]
    print(f"pose from {len(curves)} curves ({source}): {cf.rms_px:.2f} px RMS, rotation "
          f"{np.round(cf.rotation, 3).tolist()} rad, translation {np.round(cf.translation, 3).tolist()} m; "
          "expression " + ", ".join(f"{k} {v:.2f}" for k, v in top))
    return model.surface_model("blendshape").surface(cf.p), cf.rotation, cf.translation


def cmd_camera_calibrate(args):
    """Camera intrinsics and distortion from checkerboard photographs."""
    from .render.checkerboard import calibrate
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
    from tqdm import tqdm

    from .fit.scan import fit_scan, write_scan_fit
    from .mesh.meshfile import read_mesh
    model = _load_model(args.model, args.resolution)
    V, F = read_mesh(args.scan)  # metres
    out = Path(args.output)
    out.mkdir(parents=True, exist_ok=True)
    bar = tqdm(desc=f"fit {args.model_kind} model to scan", unit="it", leave=False)
    t0 = time.perf_counter()
    try:
        fit = fit_scan(model, V, F, kind=args.model_kind, mode=args.mode, lam=args.lam,
                       max_iter=args.max_iter, progress=lambda h: (bar.update(1), bar.set_postfix(
                           cost=f"{h['cost']:.3g}")))
    finally:
        bar.close()
    summary = write_scan_fit(out, model, fit, scan=str(args.scan), mode=args.mode, lam=args.lam,
                             seconds=time.perf_counter() - t0)
    _save_mesh(out / "fitted.ply", fit.surface, model.triangles)
    from .report.fit import write_report
    page = write_report(out, title=f"invface scan fit: {Path(args.scan).name}")
    e = summary["error_mm"]
    print(f"{args.model_kind} fit: {summary['iterations']} iterations ({fit.status}), "
          f"{summary['seconds']:.1f} s; error median {e['median']:.3f} mm, max {e['max']:.3f} mm; "
          f"{summary['nonzero_weights']} non-zero weights")
    top = sorted(summary["weights"].items(), key=lambda kv: -kv[1])[:5]
    print("largest weights: " + ", ".join(f"{k} {v:.3f}" for k, v in top))
    if fit.activations:
        top = sorted(fit.activations.items(), key=lambda kv: -kv[1])[:5]
        print("strongest muscles: " + ", ".join(f"{k} {v:.3f}" for k, v in top))
    print(f"wrote {out / 'fit.json'}, {out / 'fitted.ply'} and the report {page}")
    return 0


PLATE_SUFFIXES = (".png", ".jpg", ".jpeg", ".exr")


def plate_curves(model, plate, curves_path):
    """The plate's curves: --curves, else PLATE.curves.json beside it, else the detector (whose
    face oval then becomes the plate's mask when it has none)."""
    from .fit.curves import read_curves
    from .fit.landmarks import curves_from_landmarks, detect_landmarks, face_mask
    from .render.plates import linear_to_srgb
    path = Path(plate.path)
    side = path.with_name(path.stem + ".curves.json")
    if curves_path is None and side.is_file():
        curves_path = side
    if curves_path is not None:
        return read_curves(curves_path, model, image_size=plate.camera.size), str(curves_path)
    points = detect_landmarks(linear_to_srgb(plate.image), name=str(path))
    if plate.mask is None:
        plate.mask = face_mask(points, *plate.image.shape[:2])
    return curves_from_landmarks(points), "landmark detector"


def fit_plate_frame(model, plate, cal, curves, kinds, out, starts=None, iterations=25, shading=True,
                    source="", title=None, lam_curves=3600.0, notes=(), solver="dogleg"):
    """Fit one plate with each model kind, write out/<kind>/fit.{json,npz} and out/index.html;
    notes: lines for the report. Returns {kind: PlateFit}."""
    import numpy as np
    from tqdm import tqdm

    from .fit.plate import fit_plate, read_truth, vertex_errors, write_plate_fit
    from .report.fit import write_report
    path = Path(plate.path)
    truth_path = path.with_name(path.stem + ".truth.json")
    truth = read_truth(truth_path, model) if truth_path.is_file() else None
    fits = {}
    for kind in kinds:
        bar = tqdm(desc=f"{path.name}: {kind} fit", unit="eval", leave=False)

        def progress(h, bar=bar):
            bar.update(1)
            stage = h.get("stage", "") + (f" ({h['pass']})" if "pass" in h else "")
            bar.set_postfix(stage=stage, cost=f"{h.get('cost', 0):.4g}")
        try:
            fit = fit_plate(model, plate, cal, curves, kind=kind, start=(starts or {}).get(kind),
                            shading=shading, max_iter_shading=iterations, lam_curves=lam_curves,
                            solver=solver, progress=progress)
        finally:
            bar.close()
        extra = {"curves_from": source, "curve_lambda": lam_curves, "solver": solver, "notes": list(notes)}
        if source == "landmark detector":
            extra["notes"].insert(0, "Curves from the automatic landmark detector (MediaPipe Face Landmarker); "
                                     "its face oval masks the shading term.")
        line, posed = "", None
        if truth is not None:
            posed, shape = vertex_errors(model, fit, *truth)
            extra["truth"] = {"file": str(truth_path), "made_by": truth[1]["kind"],
                              "median_mm": float(np.median(posed) * 1000), "max_mm": float(posed.max() * 1000),
                              "shape_median_mm": float(np.median(shape) * 1000),
                              "shape_max_mm": float(shape.max() * 1000)}
            line = (f"; vertex error vs truth: median {extra['truth']['median_mm']:.3f} mm posed, "
                    f"{extra['truth']['shape_median_mm']:.3f} mm shape")
        folder = out / kind
        write_plate_fit(folder, model, fit, plate, curves, extra=extra, vertex_error=posed)
        print(f"{path.name} {kind}: {fit.seconds['total']:.1f} s, curves {fit.curve_rms_px:.2f} px RMS, "
              f"image RMS {fit.image_rms:.4f}, {int(np.sum(fit.p[:len(model.blendshape_names)] > 1e-2))} "
              f"non-zero weights, lip volume {100 * fit.lip_volume_change:+.2f} %{line}", flush=True)
        fits[kind] = fit
    page = write_report(out, title=title or f"invface plate fit: {path.name}")
    print(f"report: {page}")
    return fits


def cmd_fit_plate(args):
    """Fit controls and pose to a plate, or to each frame of a folder (sequence mode)."""
    from .fit.calibrate import Calibration
    from .render.plates import load_plate
    model = _load_model(args.model, args.resolution)
    src = Path(args.plate)
    if src.is_dir():
        frames = sorted(f for f in src.iterdir() if f.suffix.lower() in PLATE_SUFFIXES)
        if not frames:
            raise InvfaceError(f"{src}: no plate images ({', '.join(PLATE_SUFFIXES)}) in this folder")
    elif src.is_file():
        frames = [src]
    else:
        raise InvfaceError(f"{src}: plate not found")
    if args.curves and len(frames) > 1:
        raise InvfaceError("--curves names one file; in sequence mode put FRAME.curves.json beside each frame")
    cal = Calibration.load(args.calib, vertex_count=len(model.neutral))
    kinds = ["blendshape", "simulation"] if args.model_kind == "both" else [args.model_kind]
    out = Path(args.output) if args.output else Path("reports") / "fit-plate" / src.stem
    starts = None
    for frame in frames:
        plate = load_plate(frame, camera=args.camera)
        curves, source = plate_curves(model, plate, args.curves)
        folder = out / frame.stem if len(frames) > 1 else out
        starts = fit_plate_frame(model, plate, cal, curves, kinds, folder, starts, args.iterations,
                                 not args.no_shading, source, lam_curves=args.curve_lambda, solver=args.solver)
    if len(frames) > 1:
        from .report.sequence import write_sequence_report
        print(f"sequence report: {write_sequence_report(out)}")
    return 0


def cmd_report(args):
    """(Re)write the HTML report of a fit folder."""
    from .report.fit import write_report
    from .report.sequence import sequence_frames, write_sequence_report
    run = Path(args.run)
    single = (run / "fit.json").is_file() or any(run.glob("*/fit.json"))
    print(f"report: {write_report(run) if single or not sequence_frames(run) else write_sequence_report(run)}")
    return 0


def cmd_demo(args):
    """Build the template, write previews and expression sheets, then calibrate and fit a plate."""
    from . import template
    from .report.preview import write_previews
    out = Path(args.out)
    t0 = time.perf_counter()
    print("invface demo: building the built-in anatomical head", flush=True)
    model = template.build(progress=_progress)
    _print_summary(model, time.perf_counter() - t0)
    model.save(out / "template_head.npz")
    paths = write_previews(model, out / "preview")
    if model.blendshape_names:
        from .report.expressions import write_expression_sheet
        print(f"expression contact sheet: {write_expression_sheet(model, out / 'expressions.png')}")
        print("the same shapes through the blendshape-driven muscle simulation", flush=True)
        sheet = write_expression_sheet(model, out / "expressions_simulation.png", kind="simulation",
                                       progress=lambda msg: print(f"  .. {msg}", flush=True))
        print(f"simulation contact sheet: {sheet}")
    (out / "summary.json").write_text(json.dumps(model.summary(), indent=2))
    print(f"wrote {out / 'template_head.npz'}, {len(paths)} preview images; open {paths[-1]}")
    _demo_fit(model, out)
    return 0


def _demo_fit(model, out):
    """Sample plates with known controls; calibrate on the neutral one (Eq. 14), fit the
    simulation-made smile with both model kinds (Eq. 15-16), write the report."""
    import numpy as np

    from .render.plates import load_plate
    from .fit.samples import write_sample_plates
    folder = out / "plates"
    print("rendering sample plates (known controls, light and albedo)", flush=True)
    neutral, smile = write_sample_plates(model, folder, names=["neutral", "smile_simulation"],
                                         progress=lambda m: print(f"  .. {m}", flush=True))
    truth = json.loads((folder / "neutral.truth.json").read_text())
    print("lighting/albedo calibration (Eq. 14) on the neutral plate", flush=True)
    cal = run_calibration(model, load_plate(neutral), out / "calib.npz", np.asarray(truth["rotation"]),
                          np.asarray(truth["translation"]), 2500.0, 30)
    plate = load_plate(smile)
    curves, source = plate_curves(model, plate, None)
    print("fitting the smile plate (made by the muscle simulation) with both models", flush=True)
    fit_plate_frame(model, plate, cal, curves, ["blendshape", "simulation"], out / "fit-smile",
                    source=source, title="invface demo: a simulation-made smile fitted by both models")


CURVE_LAMBDA_HELP = ("weight regulariser lambda_1 of the curve fit, Eq. 15 (paper: 3600, px^2); the curve "
                     "residuals are pixels, so scale it with the face's size squared: 3600 (d / 224)^2 for "
                     "a face d px between the outer eye corners (224 on the sample plates)")


def build_parser():
    p = argparse.ArgumentParser(prog="invface", description="Anatomically based, differentiable face capture.")
    sub = p.add_subparsers(dest="command", required=True)
    b = sub.add_parser("build-model", help="build (or inspect) a FaceModel bundle")
    b.add_argument("input", nargs="?", help="an existing bundle to summarise/preview")
    b.add_argument("--template", action="store_true", help="the built-in template head (default)")
    b.add_argument("--neutral", help="the actor's neutral scan (OBJ/PLY) to morph the template onto")
    b.add_argument("--blendshapes", metavar="DIR", help="the actor's blendshapes (OBJ/PLY, the neutral's topology)")
    b.add_argument("--unit", choices=["m", "cm", "mm"], help="the scan's unit (default: found from its size)")
    b.add_argument("--expressions", choices=["simulate", "copy", "none"], default="simulate",
                   help="without --blendshapes: simulate the template's action units on the new anatomy "
                        "(default), copy the template's shapes, or none")
    b.add_argument("--resolution", type=float, default=1.0, help="template size factor (1 = ~35k tets)")
    b.add_argument("--force", action="store_true", help="regenerate instead of using the cache")
    b.add_argument("-o", "--output", help="write the bundle here (.npz)")
    b.add_argument("--preview", metavar="DIR", help="write preview images into DIR")
    b.set_defaults(func=cmd_build_model)
    s = sub.add_parser("simulate", help="pose the model by muscle activations or blendshape-driven tracks "
                                        "(quasistatic simulation)")
    s.add_argument("--model", help="a FaceModel bundle (default: the built-in template)")
    s.add_argument("--resolution", type=float, default=1.0, help="template size factor when no --model")
    s.add_argument("--activations", help='JSON file: {"activations": {"zygomaticus_major_L": 0.8, ...}, "jaw": [6]}')
    s.add_argument("--set", action="append", metavar="MUSCLE=A", help="set one activation (repeatable)")
    s.add_argument("--weight", action="append", metavar="SHAPE=W",
                   help="blendshape weight driving the muscle tracks (repeatable; paper 000 Sec. 6)")
    s.add_argument("--jaw", type=float, help="jaw opening angle (rad) about the hinge")
    s.add_argument("-o", "--output", help="write the posed skin mesh (OBJ/PLY)")
    s.add_argument("--preview", help="write a PNG: neutral (top) and posed (bottom), front and 3/4")
    s.set_defaults(func=cmd_simulate)
    c = sub.add_parser("calibrate", help="solve SH lighting and per-vertex albedo on a neutral plate (Eq. 14)")
    c.add_argument("plate", help="plate image (PNG/JPEG sRGB or linear EXR)")
    c.add_argument("--camera", help="JSON camera file (default: PLATE.json beside the plate, else the "
                                    "front view)")
    c.add_argument("--model", help="a FaceModel bundle (default: the built-in template)")
    c.add_argument("--resolution", type=float, default=1.0, help="template size factor when no --model")
    c.add_argument("--pose", type=float, nargs=6, metavar=("RX", "RY", "RZ", "TX", "TY", "TZ"),
                   help="rigid head pose: Euler XYZ (rad) and translation (m); default identity")
    c.add_argument("--auto-pose", action="store_true",
                   help="pose (and expression) from the plate's curves first, for a plate of unknown pose")
    c.add_argument("--curves", help="plate curve file (JSON) for --auto-pose; default PLATE.curves.json "
                   "beside the plate, else the landmark detector")
    c.add_argument("--curve-lambda", type=float, default=3600.0, help=CURVE_LAMBDA_HELP)
    c.add_argument("--lam", type=float, default=2500.0, help="albedo smoothness weight lambda (paper: 2500)")
    c.add_argument("--max-iter", type=int, default=30, help="Gauss-Newton iterations at most")
    c.add_argument("-o", "--output", default="calib.npz", help="calibration file to write (.npz)")
    c.set_defaults(func=cmd_calibrate)
    fs = sub.add_parser("fit-scan", help="fit controls and rigid pose to a 3D scan (Eq. 13)")
    fs.add_argument("scan", help="scan mesh (OBJ/PLY, metres, model frame: +Y up, face along +Z)")
    fs.add_argument("--model", help="a FaceModel bundle (default: the built-in template)")
    fs.add_argument("--resolution", type=float, default=1.0, help="template size factor when no --model")
    fs.add_argument("--model-kind", choices=["blendshape", "simulation"], default="blendshape")
    fs.add_argument("--mode", choices=["correspondence", "nearest"], default="correspondence",
                    help="correspondence: same topology as the model; nearest: any mesh, point-to-plane")
    fs.add_argument("--lam", type=float, default=1e-6, help="weight regulariser lambda (paper: 1e-6)")
    fs.add_argument("--max-iter", type=int, default=50, help="dogleg iterations at most (per round)")
    fs.add_argument("-o", "--output", default="reports/fit-scan", help="output folder")
    fs.set_defaults(func=cmd_fit_scan)
    fp = sub.add_parser("fit-plate", help="fit controls and pose to a film plate: curves (Eq. 15), then "
                                          "shape from shading (Eq. 16); a folder is a sequence")
    fp.add_argument("plate", help="plate image (PNG/JPEG/EXR), or a folder of frames (warm-started in order)")
    fp.add_argument("--calib", required=True, help="calibration from 'invface calibrate' (.npz)")
    fp.add_argument("--curves", help="plate curve file (JSON); default PLATE.curves.json beside the plate, "
                                     "else the automatic landmark detector")
    fp.add_argument("--camera", help="JSON camera file (default: PLATE.json beside the plate, else the front view)")
    fp.add_argument("--model", help="a FaceModel bundle (default: the built-in template)")
    fp.add_argument("--resolution", type=float, default=1.0, help="template size factor when no --model")
    fp.add_argument("--model-kind", choices=["blendshape", "simulation", "both"], default="blendshape")
    fp.add_argument("--curve-lambda", type=float, default=3600.0, help=CURVE_LAMBDA_HELP)
    fp.add_argument("--iterations", type=int, default=25, help="shape-from-shading iterations at most")
    fp.add_argument("--solver", choices=["dogleg", "lbfgs"], default="dogleg",
                    help="shape-from-shading solver: the paper's dogleg (Gauss-Newton on forward-mode "
                         "image Jacobians) or L-BFGS-B on adjoint gradients (for many controls)")
    fp.add_argument("--no-shading", action="store_true", help="curves only (Eq. 15)")
    fp.add_argument("-o", "--output", help="report folder (default reports/fit-plate/PLATE)")
    fp.set_defaults(func=cmd_fit_plate)
    rp = sub.add_parser("report", help="(re)write the HTML report of a fit folder")
    rp.add_argument("run", help="folder with fit.json (or sub-folders with one each)")
    rp.set_defaults(func=cmd_report)
    cam = sub.add_parser("camera", help="camera tools")
    camsub = cam.add_subparsers(dest="camera_command", required=True)
    cc = camsub.add_parser("calibrate", help="intrinsics and distortion from checkerboard images (OpenCV)")
    cc.add_argument("images", nargs="+", help="checkerboard photographs")
    cc.add_argument("--board", default="9x6", help="inner corners COLSxROWS (default 9x6)")
    cc.add_argument("--square", type=float, default=0.025, help="square size in metres")
    cc.add_argument("--no-distortion", action="store_true", help="fit K only")
    cc.add_argument("-o", "--output", default="camera.json", help="JSON camera file to write")
    cc.set_defaults(func=cmd_camera_calibrate)
    d = sub.add_parser("demo", help="run the main job on the built-in model")
    d.add_argument("--out", default="reports/demo", help="output folder")
    d.set_defaults(func=cmd_demo)
    return p


def main(argv=None):
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except InvfaceError as e:
        print(f"invface: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
