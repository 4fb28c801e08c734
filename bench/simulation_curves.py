"""Eq. 15 solved through the simulation itself, against the rig, on a finished photo fit (issue 26).

    python bench/simulation_curves.py DIR [--iterations 30]

DIR is a ``fit-plate PHOTO --model-kind both -o DIR`` output (its ``actor.npz`` and the
blendshape kind's ``fit.npz``/``fit.json``). From the rig's final controls and pose, with the
pose held, the curve fit (``fit.curves.fit_curves``, Eq. 15 at the run's lambda_1) runs with
each model kind; prints seconds, the curve RMS and each lip curve's RMS (px). It asks whether
the simulation's lips can reach the plate's curves at all (a model limit) or only did not in
the shading stage (a weight or a stage the fit lacks).
"""
import argparse
import json
import time
from pathlib import Path

import numpy as np

import invface
from invface.fit.curves import fit_curves
from invface.render.camera import Camera


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("folder")
    ap.add_argument("--iterations", type=int, default=30)
    a = ap.parse_args()
    out = Path(a.folder)
    model = invface.FaceModel.load(out / "actor.npz")
    z = np.load(out / "blendshape" / "fit.npz")
    summary = json.loads((out / "blendshape" / "fit.json").read_text())
    names = [str(s) for s in z["curve_names"]]
    curves = {k: z[f"curve_{i}"] for i, k in enumerate(names)}
    cam = Camera.from_dict(json.loads(str(z["camera"])))
    rot, tr = np.array(summary["rotation"]), np.array(summary["translation"])
    for kind in ("blendshape", "simulation"):
        t = time.perf_counter()
        cf = fit_curves(model, cam, curves, kind=kind, lam=summary["curve_lambda"], p0=z["p"], rotation=rot,
                        translation=tr, solve_pose=False, max_iter=a.iterations)
        lips = "  ".join(f"{k} {np.sqrt(np.mean(v ** 2)):.2f}" for k, v in sorted(cf.residual_px.items()) if "lip" in k)
        print(f"{kind:10s} {time.perf_counter() - t:6.1f} s  curve RMS {cf.rms_px:.2f} px  ({lips})  {cf.status}",
              flush=True)


if __name__ == "__main__":
    main()
