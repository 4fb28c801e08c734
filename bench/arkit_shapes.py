"""Does each ARKit control mean what ARKit means, in the simulation kind (issue 59)?

    python bench/arkit_shapes.py [--resolution 1] [--only mouthRollUpper,...] [--json FILE]
                                 [--pictures DIR]

Per control of the built-in head, the displacement field that the simulation kind produces at
weight 1.0 (with the shape's paired jaw, as the rig plays it) is correlated with ICT-FaceKit's
same-named shape carried onto the template (``template/data/arkit_ict.npz``, what the
blendshape kind plays). Pearson correlation over the x, y, z offsets of the face's vertices
(``morph.build.face_vertices``); the magnitude ratio |sim| / |ICT| over the same vertices; the
simulation's volume change and Newton iterations. mouthClose is a corrective that means
something only with the jaw open: it is measured at jawOpen 0.5 (its paired jaw and its
weight halved), as the difference that mouthClose 1.0 makes there. eyeBlinkLeft/Right are
the template's own kinematic blinks: they are correlated with ICT's eyeBlink too, and the
``rig`` column correlates every control with the blendshape kind's own shape.

``--pictures DIR`` also writes the contact sheets of every control at 1.0 in both kinds
(``controls_blendshape.png``, ``controls_simulation.png``) and close-ups of the lips' controls
(``lips_closeup.png``: rows neutral, roll lower, roll upper, press, funnel, pucker, mouthClose
over jawOpen; columns rig front and 3/4, simulation front and 3/4).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from _common import add_json_option, write_json

import invface
from invface.morph.build import face_vertices
from invface.sim.driven import DrivenSimulation
from invface.template import arkit_shapes


def correlation(a, b):
    a, b = a.ravel() - a.mean(), b.ravel() - b.mean()
    return float(a @ b / max(np.linalg.norm(a) * np.linalg.norm(b), 1e-30))


LIP_CONTROLS = ("mouthRollLower", "mouthRollUpper", "mouthPressLeft", "mouthFunnel", "mouthPucker", "mouthClose",
                "tongueOut")


def write_pictures(model, out):
    """The two contact sheets and the lips' close-ups into the folder ``out``."""
    import imageio.v2 as imageio
    from invface.render.preview import look_at_camera, render_meshes, to_srgb8
    from invface.report.expressions import blendshape_pose, write_expression_sheet
    from invface.report.preview import SKIN, parts_meshes
    out.mkdir(parents=True, exist_ok=True)
    for kind in ("blendshape", "simulation"):
        print("wrote", write_expression_sheet(model, out / f"controls_{kind}.png", size=200, kind=kind, cols=8))
    target = np.array([0.0, -0.035, 0.1])
    rows = []
    for n in ("neutral",) + LIP_CONTROLS:
        w = None if n == "neutral" else blendshape_pose(model, n)
        tiles = []
        for kind in ("blendshape", "simulation"):
            x = model.neutral if w is None else model.surface(w, kind=kind)
            for eye in ((0.0, -0.025, 0.45), (0.25, -0.015, 0.38)):
                cam = look_at_camera(np.array(eye), target, fov=11, width=260, height=200, spp=16)
                tiles.append(to_srgb8(render_meshes([(x, model.triangles, SKIN)] + parts_meshes(model, w), cam)))
        rows.append(np.concatenate(tiles, 1))
    imageio.imwrite(out / "lips_closeup.png", np.concatenate(rows, 0))
    print("wrote", out / "lips_closeup.png")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolution", type=float, default=1.0)
    ap.add_argument("--only", help="comma-separated controls")
    ap.add_argument("--pictures", type=Path, help="also write the contact sheets and lip close-ups here")
    add_json_option(ap)
    a = ap.parse_args()
    model = invface.template.build(resolution=a.resolution)
    shapes = arkit_shapes.load()
    ict = dict(zip(shapes["names"], arkit_shapes.carry(shapes, model.neutral, model.triangles)))
    ds = DrivenSimulation(model)
    names = model.blendshape_names
    jaws = model.meta["blendshape_jaw"]
    face = face_vertices(model)
    rest = ds.surface_of(ds.solve(np.zeros(len(names) + 6), warm=None))

    def sim_at(weights, jaw):
        r = ds.solve(model.parameters({"weights": weights, "jaw": jaw}), warm=None)
        return ds.surface_of(r), r

    rig = model.surface_model("blendshape")

    def rig_at(weights, jaw):
        return rig.surface(model.parameters({"weights": weights, "jaw": jaw}))

    rows = {}
    # tongueOut moves the tongue part, not the skin: ICT-FaceKit has no such shape to compare
    todo = a.only.split(",") if a.only else [n for n in names if n != arkit_shapes.TONGUE]
    print(f"{'control':20s} {'corr':>6s} {'rig':>6s} {'|sim|/|ICT|':>11s} {'ICT max mm':>10s} {'vol %':>6s} {'iters':>5s} {'s':>5s}")
    for n in todo:
        t = time.perf_counter()
        jaw = np.asarray(jaws.get(n, np.zeros(6)), float)
        if n == "mouthClose":
            j = 0.5 * np.asarray(jaws["jawOpen"], float)
            base_w = {"jawOpen": 0.5}
            xs0, _ = sim_at(base_w, j)
            xs1, r = sim_at({**base_w, n: 1.0}, j)
            sim = xs1 - xs0
            ref = own = rig_at({**base_w, n: 1.0}, j) - rig_at(base_w, j)
        else:
            xs, r = sim_at({n: 1.0}, jaw)
            sim = xs - rest
            own = rig_at({n: 1.0}, jaw) - model.neutral
            ref = own if np.any(jaw) else ict[n]      # a jaw shape's offsets are pre-skinning
        c = correlation(sim[face], ref[face])
        c_rig = correlation(sim[face], own[face])
        ratio = float(np.linalg.norm(sim[face]) / max(np.linalg.norm(ref[face]), 1e-30))
        vol = ds.sim.volume_change(r.sim) * 100
        secs = time.perf_counter() - t
        rows[n] = {"correlation": round(c, 3), "correlation_with_rig": round(c_rig, 3), "magnitude_ratio": round(ratio, 3),
                   "ict_max_mm": round(float(np.linalg.norm(ref, axis=1).max() * 1000), 2),
                   "volume_change_pct": round(float(vol), 3), "iterations": r.sim.iterations, "seconds": round(secs, 1)}
        print(f"{n:20s} {c:6.3f} {c_rig:6.3f} {ratio:11.2f} {rows[n]['ict_max_mm']:10.1f} {vol:6.2f} {r.sim.iterations:5d} {secs:5.1f}",
              flush=True)
    low = sorted(k for k, v in rows.items() if v["correlation"] < 0.8)
    print(f"{len(rows) - len(low)} of {len(rows)} controls correlate >= 0.8; below: {', '.join(low) or 'none'}")
    write_json(a.json, {"resolution": a.resolution, "controls": rows, "below_0.8": low})
    if a.pictures:
        write_pictures(model, a.pictures)


if __name__ == "__main__":
    main()
