"""The dogleg's image Jacobian: the analytic one (visibility held fixed, ``render.jacobian``)
against Dr.Jit's forward mode, on a sample plate's face window.

    python bench/image_jacobian.py [--resolution 1] [--samples 1] [--repeat 3] [--json F]

Prints, for the posed default head at 720x540 (a smile, the jaw at 0.08 rad, the head turned),
the window, the column count, and the median of ``--repeat`` calls of: the analytic
linearisation (one ray cast), its product with all columns (seconds and per column), the analytic
rows as the dogleg takes them (``ShadingObjective.analytic_jacobian``: masked and through the
pyramid), and the forward-mode rows (``forward_jacobian``, 2 spp, the same pyramid).
"""
from __future__ import annotations

import argparse
import time

import numpy as np
from _common import add_json_option, write_json

import invface
from invface.fit.samples import sample_camera, skin_albedo, studio_light
from invface.fit.shading import ShadingObjective, face_window
from invface.model.controls import FitVector
from invface.model.pose import posed_jacobian, posed_parts


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolution", type=float, default=1.0)
    ap.add_argument("--samples", type=int, default=1, help="analytic rays per pixel and axis")
    ap.add_argument("--repeat", type=int, default=3)
    add_json_option(ap)
    a = ap.parse_args()
    m = invface.template.build(resolution=a.resolution)
    cam = sample_camera(720, 540)
    vec = FitVector.of(m)
    p = m.parameters({"weights": {"mouthSmileLeft": 0.5, "browInnerUp": 0.4}, "jaw": [0.08, 0, 0, 0, 0, 0]})
    z = vec.pack(p, np.array([0.05, -0.15, 0.02]), np.array([0.002, -0.001, 0.01]))
    sm = m.surface_model("blendshape")
    xr, J = posed_jacobian(sm, z, vec)
    parts = posed_parts(m, z, vec)
    plate = np.full((cam.height, cam.width, 3), 0.3, np.float32)
    window = face_window(cam, xr)
    obj = ShadingObjective(m, sm, cam, plate, studio_light(), skin_albedo(m), np.zeros(vec.P), window=window,
                           jacobian="analytic", jacobian_samples=a.samples)
    obj._render(xr, parts)
    print(f"head: {len(xr)} vertices; window {window}; {len(J)} columns; {a.samples}x{a.samples} rays per pixel")
    lin_s, apply_s, rows_s, fwd_s = [], [], [], []
    for _ in range(a.repeat):
        t = time.perf_counter()
        lin = obj.raster.linearise(xr, obj.gamma, obj.albedo, parts_x=parts, image=obj._rgb)
        lin_s.append(time.perf_counter() - t)
        t = time.perf_counter()
        lin.apply(np.moveaxis(J, 0, 2))
        apply_s.append(time.perf_counter() - t)
        t = time.perf_counter()
        obj.analytic_jacobian(xr, J, parts, obj._rgb)
        rows_s.append(time.perf_counter() - t)
        t = time.perf_counter()
        obj.forward_jacobian(xr, J, parts_x=parts)
        fwd_s.append(time.perf_counter() - t)
    med = lambda v: float(np.median(v))
    n = len(J)
    print(f"analytic: linearise {med(lin_s):.3f} s, apply {med(apply_s):.3f} s ({1e3 * med(apply_s) / n:.1f} ms a column)")
    print(f"analytic rows as the fit takes them (linearise, apply, mask and pyramid): {med(rows_s):.3f} s")
    print(f"forward mode rows (mask and pyramid included): {med(fwd_s):.3f} s ({1e3 * med(fwd_s) / n:.1f} ms a column)")
    write_json(a.json, {"columns": n, "samples": a.samples, "linearise_s": med(lin_s), "apply_s": med(apply_s),
                        "analytic_rows_s": med(rows_s), "forward_s": med(fwd_s), "forward_ms_per_column": 1e3 * med(fwd_s) / n,
                        "analytic_ms_per_column": 1e3 * med(apply_s) / n})


if __name__ == "__main__":
    main()
