"""The gradient-only path of shape from shading (``invface fit-plate --solver lbfgs``): seconds
per evaluation of Eq. 16's cost and gradient, for both model kinds.

    python bench/lbfgs.py [--resolution 1] [--evaluations 6]

On the sample plate ``smile_simulation`` (720x540, true light and albedo, its curve file),
the objective (``fit.shading.ShadingObjective.__call__``, what L-BFGS-B calls) is evaluated
at points stepping away from the truth (each a new solve for the simulation, warm from the
last). Before this bench's commit the gradient took the surface model's full Jacobian
(K+12 tangent solves for the simulation); now it is one adjoint product through the Dr.Jit
bridge. Prints seconds per evaluation (median over the evaluations, the first one left out:
it compiles the kernels), split into the forward solve (the simulation's Newton solve, warm
from the last point; the rig's evaluation) and the rest (render, backward pass, the
surface model's derivative), and the gradient's size.
"""
from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np

import invface
from invface.fit.calibrate import Calibration
from invface.fit.curves import read_curves
from invface.fit.plate import read_truth
from invface.fit.samples import write_sample_plates
from invface.fit.shading import ShadingObjective, face_window
from invface.model.rig import euler_xyz
from invface.render.plates import load_plate
from invface.render.synthetic import skin_albedo, studio_light


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolution", type=float, default=1.0)
    ap.add_argument("--evaluations", type=int, default=6)
    a = ap.parse_args()
    model = invface.template.build(resolution=a.resolution)
    cal = Calibration(gamma=studio_light(), albedo=skin_albedo(model))
    with tempfile.TemporaryDirectory() as tmp:
        path, = write_sample_plates(model, tmp, names=["smile_simulation"])
        plate = load_plate(path)
        curves = read_curves(path.with_name(path.stem + ".curves.json"), model)
        truth = read_truth(path.with_name(path.stem + ".truth.json"), model)[1]
    rot, tr = np.asarray(truth["rotation"]), np.asarray(truth["translation"])
    p = model.parameters({"weights": truth["weights"], "jaw": truth["jaw"]})
    rng = np.random.default_rng(0)
    # the evaluation points: the truth's weights, each moved by up to 0.02 (within [0, 1])
    points = [p] + [model.parameters({"weights": {n: float(np.clip(truth["weights"].get(n, 0) + rng.normal(0, 0.02),
                                                                    0, 1)) for n in model.blendshape_names},
                                      "jaw": truth["jaw"]}) for _ in range(a.evaluations)]
    print(f"head: {len(model.neutral)} vertices, {len(model.tets)} tets, {len(p)} controls; plate {plate.camera.size}")
    for kind in ("blendshape", "simulation"):
        sm = model.surface_model(kind)
        window = face_window(plate.camera, sm.surface(p) @ euler_xyz(rot).T + tr)
        obj = ShadingObjective(model, sm, plate.camera, plate.image, cal.gamma, cal.albedo, p, curves,
                               mask=plate.mask, window=window)
        times, solves, norms = [], [], []
        for q in points:
            t0 = time.perf_counter()
            sm.surface(q)            # the forward solve, kept by the model for the evaluation
            t1 = time.perf_counter()
            _, g = obj(np.r_[q, rot, tr])
            times.append(time.perf_counter() - t0)
            solves.append(t1 - t0)
            norms.append(float(np.linalg.norm(g)))
        rest = np.subtract(times, solves)[1:]
        print(f"{kind:>11}: {np.median(times[1:]):.2f} s per evaluation, of which the forward solve "
              f"{np.median(solves[1:]):.2f} s and render + gradient {np.median(rest):.2f} s (min {rest.min():.2f}, "
              f"max {rest.max():.2f}); |gradient| median {np.median(norms):.4g}", flush=True)


if __name__ == "__main__":
    main()
