"""Fitting benchmark: seconds per 3D scan fit (Eq. 13) and per plate frame (Eq. 15-16) for
both model kinds.

    python bench/fit.py [--resolution 1 | --model FILE.npz] [--plates smile_blendshape,smile_simulation]
                        [--no-scan]

A synthetic scan is made by the model itself (random controls, 30 % of the weights active,
jaw 0.08 rad, rotation ~0.1 rad, a few mm of translation) and fitted from the neutral start
with lambda = 1e-8 (noise-free scan) and the paper's 1e-6. Prints seconds, dogleg
iterations, the largest control error and the surface error.
Plate fits: the sample plates (``fit.samples.SAMPLES``, 720x540, rendered here) with
their curve files and the true light and albedo; prints seconds per stage and the median
vertex error against the truth (posed; its parts along the camera rays, depth, and across
them, in plane; shape only), non-zero weights and lip volume change. ``--plates all``: every
sample plate but the neutral one.
"""
from __future__ import annotations

import argparse
import time

import numpy as np
from _common import add_json_option, write_json

import invface
from invface.model.pose import pose_points, unpose_points
from invface.fit.scan import fit_scan
from invface.model import FitVector


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolution", type=float, default=1.0)
    ap.add_argument("--model", help="a FaceModel bundle instead of the template at --resolution")
    ap.add_argument("--plates", default="smile_blendshape,smile_simulation",
                    help="sample plates to fit (comma-separated; '' skips plate fits)")
    ap.add_argument("--no-scan", action="store_true", help="skip the scan fits")
    ap.add_argument("--jacobian", choices=("hybrid", "analytic", "forward"),
                    help="the dogleg's image Jacobian (default: fit.shading.JACOBIAN)")
    add_json_option(ap)
    a = ap.parse_args()
    if a.jacobian:
        from invface.fit import shading
        shading.JACOBIAN = a.jacobian
    model = invface.FaceModel.load(a.model) if a.model else invface.template.build(resolution=a.resolution)
    vec = FitVector.of(model)
    rng = np.random.default_rng(0)
    p = vec.controls_vector(np.where(rng.random(vec.K) < 0.3, rng.uniform(0.2, 0.8, vec.K), 0), [0.08, 0, 0, 0, 0, 0])
    rot, tr = np.array([0.05, -0.1, 0.02]), np.array([0.003, -0.002, 0.005])
    print(f"head: {len(model.neutral)} vertices, {len(model.tets)} tets, K = {vec.K}")
    if a.plates:
        from invface.fit.samples import SAMPLES
        rows = plates(model, [n for n in SAMPLES if n != "neutral"] if a.plates == "all" else a.plates.split(","))
        write_json(a.json, {"jacobian": a.jacobian or "default", "plates": rows})
    if a.no_scan:
        return
    print(f"{'model':>11} {'lambda':>7} {'seconds':>8} {'its':>4} {'max |dp|':>9} {'max err mm':>10}")
    for kind in ("blendshape", "simulation"):
        scan = pose_points(model.surface_model(kind).surface(p), rot, tr)
        for lam in (1e-8, 1e-6):
            model.forget_surface_models()          # cold: no warm start from the scan's solve
            t0 = time.perf_counter()
            fit = fit_scan(model, scan, kind=kind, lam=lam)
            sec = time.perf_counter() - t0
            print(f"{kind:>11} {lam:7.0e} {sec:8.2f} {len(fit.history):4d} {np.abs(fit.p - p).max():9.2e} "
                  f"{fit.error.max() * 1000:10.4f}", flush=True)
    # path dependence: the true controls solved warm (from the last fit's state) vs cold
    warm = model.surface_model("simulation").surface(p)
    cold = unpose_points(scan, rot, tr)
    d = np.linalg.norm(warm - cold, axis=1) * 1000
    print(f"simulation at the true controls, warm vs cold start: max {d.max():.3f} mm "
          f"(vertex {int(d.argmax())}), median {np.median(d):.4f} mm")


def plates(model, names):
    import tempfile

    from invface.fit.calibrate import Calibration
    from invface.fit.curves import read_curves
    from invface.fit.plate import depth_errors, fit_plate, read_truth, vertex_errors
    from invface.render.plates import load_plate
    from invface.fit.samples import write_sample_plates
    from invface.render.synthetic import skin_albedo, studio_light
    cal = Calibration(gamma=studio_light(), albedo=skin_albedo(model))
    rows = []
    print(f"{'plate':>18} {'model':>11} {'curves s':>8} {'shading s':>9} {'total s':>8} "
          f"{'posed mm':>8} {'depth mm':>8} {'plane mm':>8} {'shape mm':>8} {'max mm':>7} {'weights':>7} {'lip vol':>8}")
    with tempfile.TemporaryDirectory() as tmp:
        for path in write_sample_plates(model, tmp, names=names):
            plate = load_plate(path)
            curves = read_curves(path.with_name(path.stem + ".curves.json"), model)
            truth = read_truth(path.with_name(path.stem + ".truth.json"), model)
            for kind in ("blendshape", "simulation"):
                model.forget_surface_models()
                fit = fit_plate(model, plate, cal, curves, kind=kind)
                posed, shape = vertex_errors(model, fit, *truth)
                depth, across = depth_errors(fit.surface, truth[0], plate.camera)
                sh = sum(v for k, v in fit.seconds.items() if k.startswith("shading"))
                print(f"{path.stem:>18} {kind:>11} {fit.seconds['curves']:8.1f} {sh:9.1f} "
                      f"{fit.seconds['total']:8.1f} {np.median(posed) * 1000:8.3f} {np.median(depth) * 1000:8.3f} "
                      f"{np.median(across) * 1000:8.3f} {np.median(shape) * 1000:8.3f} "
                      f"{shape.max() * 1000:7.2f} {fit.nonzero_weights:7d} "
                      f"{100 * fit.lip_volume_change:+7.2f}%", flush=True)
                rows.append({"plate": path.stem, "kind": kind, "curves_s": fit.seconds["curves"], "shading_s": sh,
                             "total_s": fit.seconds["total"], "posed_mm": float(np.median(posed) * 1000),
                             "depth_mm": float(np.median(depth) * 1000), "plane_mm": float(np.median(across) * 1000),
                             "shape_mm": float(np.median(shape) * 1000), "lip_volume": fit.lip_volume_change})
    return rows


if __name__ == "__main__":
    main()
