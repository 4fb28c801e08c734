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
          f"blendshapes: {s['blendshapes']}")
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
        raise InvfaceError("building a model from a scan (--neutral) needs the morph pipeline (paper 001), "
                           "which this version does not include yet; use --template")
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


def run_calibration(model, plate, out, rotation, translation, lam, max_iter):
    """Eq. 14 on a loaded plate with a progress bar; writes out (.npz) and out's _compare.png."""
    from tqdm import tqdm

    from .fit.calibrate import calibrate, comparison_image
    from .render.plates import write_image
    out = Path(out)
    bar = tqdm(total=max_iter, desc="calibrate lighting/albedo", unit="it", leave=False)

    def progress(h):
        bar.update(1)
        bar.set_postfix(rms=f"{h['rms']:.4f}")
    try:
        cal = calibrate(model.triangles, model.neutral, plate.image, plate.camera, rotation,
                        translation, lam=lam, mask=plate.mask, max_iter=max_iter, progress=progress)
    finally:
        bar.close()
    cal.plate = plate.path
    out.parent.mkdir(parents=True, exist_ok=True)
    cal.save(out)
    h = cal.history[-1]
    compare = write_image(out.with_name(out.stem + "_compare.png"),
                          comparison_image(model.triangles, model.neutral, cal, plate.image))
    print(f"calibrated in {len(cal.history)} iterations, {h['seconds']:.1f} s: pixel RMS {h['rms']:.4f} "
          f"(linear), light DC {cal.gamma[0].round(3).tolist()}")
    print(f"wrote {out} and {compare} (plate | render | 4x difference)")
    return cal


def cmd_calibrate(args):
    """Lighting and albedo calibration (Eq. 14) on a neutral plate."""
    from .render.plates import load_plate
    model = _load_model(args.model, args.resolution)
    plate = load_plate(args.plate, camera=args.camera)
    rotation, translation = _pose(args.pose)
    run_calibration(model, plate, args.output, rotation, translation, args.lam, args.max_iter)
    return 0


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


def _read_scan(path):
    """(vertices (S,3), faces (G,3)) of an OBJ/PLY scan, in metres."""
    import numpy as np
    import trimesh
    path = Path(path)
    if not path.is_file():
        raise InvfaceError(f"{path}: scan file not found")
    try:
        mesh = trimesh.load(path, process=False, force="mesh")
    except Exception as e:  # noqa: BLE001 - trimesh raises many kinds
        raise InvfaceError(f"{path}: not a readable mesh ({e})") from None
    if len(getattr(mesh, "vertices", [])) == 0 or len(getattr(mesh, "faces", [])) == 0:
        raise InvfaceError(f"{path}: the file holds no triangle mesh")
    return np.asarray(mesh.vertices, float), np.asarray(mesh.faces, np.int64)


def cmd_fit_scan(args):
    """Fit controls and pose to a 3D scan (Eq. 13); write fit.json and the fitted mesh."""
    from tqdm import tqdm

    from .fit.scan import fit_scan
    model = _load_model(args.model, args.resolution)
    V, F = _read_scan(args.scan)
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
    summary = fit.summary(model)
    summary.update(scan=str(args.scan), mode=args.mode, lam=args.lam,
                   seconds=time.perf_counter() - t0, history=fit.history)
    tmp = out / "fit.json.tmp"
    tmp.write_text(json.dumps(summary, indent=1))
    tmp.replace(out / "fit.json")
    _save_mesh(out / "fitted.ply", fit.surface, model.triangles)
    e = summary["error_mm"]
    print(f"{args.model_kind} fit: {summary['iterations']} iterations ({fit.status}), "
          f"{summary['seconds']:.1f} s; error median {e['median']:.3f} mm, max {e['max']:.3f} mm; "
          f"{summary['nonzero_weights']} non-zero weights")
    top = sorted(summary["weights"].items(), key=lambda kv: -kv[1])[:5]
    print("largest weights: " + ", ".join(f"{k} {v:.3f}" for k, v in top))
    if fit.activations:
        top = sorted(fit.activations.items(), key=lambda kv: -kv[1])[:5]
        print("strongest muscles: " + ", ".join(f"{k} {v:.3f}" for k, v in top))
    print(f"wrote {out / 'fit.json'} and {out / 'fitted.ply'}")
    return 0


def cmd_demo(args):
    """Until fitting lands: build the template, pose the jaw, write previews."""
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
    _demo_calibration(model, out)
    return 0


def _demo_calibration(model, out):
    """Render a synthetic neutral plate with a known light and albedo, calibrate on it."""
    import numpy as np

    from .render.camera import Camera
    from .render.plates import Plate, write_image
    from .render.shading import vertex_normals, irradiance
    from .render.synthetic import render_plate, skin_albedo, studio_light
    print("lighting/albedo calibration (Eq. 14) on a synthetic neutral plate", flush=True)
    cam = Camera.front_view(720, 540)
    rot, tr = np.array([0.03, -0.12, 0.0]), np.array([0.0, 0.0, 0.0])
    gamma, albedo = studio_light(), skin_albedo(model)
    image, _ = render_plate(model, model.neutral, cam, gamma, albedo, rot, tr)
    plate_path = write_image(out / "plates" / "neutral.exr", image)
    cam.save(out / "plates" / "neutral.json")
    cal = run_calibration(model, Plate(image=image, camera=cam, path=str(plate_path)),
                          out / "calib.npz", rot, tr, 2500.0, 30)
    from .model.rig import euler_xyz
    n = vertex_normals(model.neutral @ euler_xyz(rot).T + tr, model.triangles)
    E, Ef = irradiance(n, gamma), irradiance(n, cal.gamma)
    k = albedo.mean(0) / cal.albedo.mean(0)
    print(f"against the truth: irradiance {100 * np.sqrt(np.mean((E - Ef) ** 2) / np.mean(E ** 2)):.2f} % RMS, "
          f"albedo {100 * np.sqrt(np.mean((cal.albedo * k - albedo) ** 2) / np.mean(albedo ** 2)):.2f} % RMS "
          "(all vertices, up to the light/albedo scale)")


def build_parser():
    p = argparse.ArgumentParser(prog="invface", description="Anatomically based, differentiable face capture.")
    sub = p.add_subparsers(dest="command", required=True)
    b = sub.add_parser("build-model", help="build (or inspect) a FaceModel bundle")
    b.add_argument("input", nargs="?", help="an existing bundle to summarise/preview")
    b.add_argument("--template", action="store_true", help="the built-in template head (default)")
    b.add_argument("--neutral", help="the actor's neutral scan (OBJ/PLY) to morph the template onto")
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
