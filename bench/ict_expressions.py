"""ICT-FaceKit expressions as real 3D scan targets (issue 6): mm error per expression for the
blendshape and the simulation model of an actor built from the ICT neutral alone.

    python bench/ict_expressions.py [--resolution 1] [--only jawOpen,mouthSmile_L]
                                    [--simulation jawOpen,mouthSmile_L,...] [-o reports/ict-expressions]

1. The actor model: ``build_model(ICT neutral.obj, expressions="simulate")`` - the template
   morphed onto the ICT neutral (paper 001) and the template's action units re-simulated on
   the new anatomy. The ICT blendshapes are NOT imported: each ICT expression (neutral +
   delta, scan-derived, ARKit names) is an unseen scan of the actor.
2. Each expression scan is mapped into the model frame with ``model.scan_transform`` and fitted
   in ``nearest`` (point-to-plane) mode, Eq. 13, lambda 1e-6, controls and rigid pose.
3. Error: the distance from every scan vertex that the expression moves by more than 1 mm
   (among those the neutral model covers, within 2 mm: not the neck below the model, the
   ears or the back of the head) to the model surface, before the fit (the neutral model)
   and after; median and 95th percentile in mm. The blendshape model fits every expression; the simulation model the
   ``--simulation`` subset (its fits cost tangent solves).

The ICT data is not part of invface (../shared/data/ict-facekit, MIT licence); without it the
script says so and stops. An HTML report of every fitted expression is written (fit-scan's).
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np
from _common import SHARED

import invface
from invface.fit.scan import fit_scan, write_scan_fit
from invface.mesh.closest import closest_points
from invface.io.meshes import read_mesh
from invface.morph.build import build_model

ICT = SHARED / "ict-facekit"
MOVED = 0.001           # m: scan vertices the expression moves by more than this are measured
COVERED = 0.002         # m: ... and that lie this close to the neutral model (the part it covers)
SIMULATION = "jawOpen,mouthSmile_L,mouthPucker,mouthFunnel,browInnerUp_L,eyeBlink_L,mouthFrown_L,cheekPuff_L"


def errors_mm(points, surface, triangles):
    """Median and 95th percentile (mm) of the distances of points (n,3) to the surface."""
    d = closest_points(points, surface, triangles)[2] * 1000
    return float(np.median(d)), float(np.percentile(d, 95))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolution", type=float, default=1.0, help="template size factor")
    ap.add_argument("--only", default="", help="comma-separated ICT expressions (default: all 53)")
    ap.add_argument("--simulation", default=SIMULATION, help="expressions also fitted with the simulation model")
    ap.add_argument("-o", "--output", default="reports/ict-expressions")
    a = ap.parse_args()
    if not (ICT / "neutral.obj").is_file():
        sys.exit(f"ICT-FaceKit data not found at {ICT}: this benchmark needs ../shared/data/ict-facekit")
    out = Path(a.output)
    t = time.perf_counter()
    tpl = invface.template.build(resolution=a.resolution)
    model, res = build_model(ICT / "neutral.obj", template=tpl, expressions="simulate")
    print(f"actor model built in {time.perf_counter() - t:.1f} s: {len(model.neutral)} vertices, "
          f"{len(model.tets)} tets, {len(model.blendshape_names)} simulated expressions")
    V0, F = read_mesh(ICT / "neutral.obj")          # cm, as the file says; scan_transform has the scale
    data = np.load(ICT / "expressions.npz")
    names = [str(n) for n in data["names"]]
    wanted = a.only.split(",") if a.only else names
    sim = set(a.simulation.split(",")) if a.simulation else set()
    A = model.scan_transform
    scale = np.linalg.norm(A[:3, 0])                        # scan units -> m
    # the scan's part that the model covers (the morph snapped onto it): not the neck below
    # the model's boundary, the ears (boxed out) or the back of the head
    covered = closest_points(V0 @ A[:3, :3].T + A[:3, 3], model.neutral, model.triangles)[2] < COVERED
    rows = []
    print(f"{'expression':18s} {'before':>13s} {'blendshape':>13s} {'hinge':>5s} {'s':>6s} "
          f"{'simulation':>13s} {'hinge':>5s} {'s':>6s}   (median / 95% mm over the moving scan vertices; "
          "the fitted jaw hinge in degrees)")
    for name in wanted:
        if name not in names:
            sys.exit(f"unknown ICT expression '{name}'")
        delta = data["deltas"][names.index(name)]
        S = (V0 + delta) @ A[:3, :3].T + A[:3, 3]
        moving = S[(np.linalg.norm(delta, axis=1) * scale > MOVED) & covered]
        before = errors_mm(moving, model.neutral, model.triangles)
        row = {"expression": name, "moving_vertices": len(moving), "before_mm": before}
        for kind in ("blendshape", "simulation"):
            if kind == "simulation" and name not in sim:
                continue
            t = time.perf_counter()
            fit = fit_scan(model, S, F, kind=kind, mode="nearest")
            secs = time.perf_counter() - t
            after = errors_mm(moving, fit.surface, model.triangles)
            top = sorted(fit.weights.items(), key=lambda kv: -kv[1])[:3]
            row[kind] = {"after_mm": after, "seconds": secs, "nonzero": fit.summary()["nonzero_weights"],
                         "jaw_rad": float(fit.jaw[0]), "rotation_deg": float(np.degrees(np.linalg.norm(fit.rotation))),
                         "top": [(k, round(float(v), 3)) for k, v in top]}
            write_scan_fit(out / name / kind, model, fit, scan=f"ICT-FaceKit {name}", mode="nearest", lam=1e-6,
                           seconds=secs, notes=[f"error before the fit (neutral model): median {before[0]:.2f} mm, "
                                                f"95% {before[1]:.2f} mm"])
        cols = [f"{r['after_mm'][0]:5.2f} / {r['after_mm'][1]:5.2f} {np.degrees(r['jaw_rad']):5.1f} {r['seconds']:6.1f}"
                for r in (row["blendshape"], row.get("simulation")) if r]
        print(f"{name:18s} {before[0]:5.2f} / {before[1]:5.2f} " + " ".join(cols), flush=True)
        rows.append(row)
        from invface.report.fit import write_report
        write_report(out / name, title=f"invface: ICT-FaceKit {name} as a scan target")
    for kind in ("blendshape", "simulation"):
        r = [x for x in rows if kind in x]
        if r:
            med = np.array([[x["before_mm"][0], x[kind]["after_mm"][0]] for x in r])
            print(f"{kind}: {len(r)} expressions; median error over expressions {np.median(med[:, 0]):.2f} -> "
                  f"{np.median(med[:, 1]):.2f} mm; mean {np.mean([x[kind]['seconds'] for x in r]):.1f} s per fit")
    (out / "summary.json").write_text(json.dumps(rows, indent=1))
    print(f"wrote {out}/summary.json and a report per expression in {out}/<expression>/index.html")


if __name__ == "__main__":
    main()
