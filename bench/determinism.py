"""Is a plate fit a deterministic function of its inputs? The curve stage (Eq. 15) and the
first shading normal equations (Eq. 16) on the sample plate ``smile_blendshape``, printed to
full precision, and the normal equations evaluated twice at the same point.

    python bench/determinism.py

Run against two versions of the code, the printed figures tell whether a change moved the
numerics; the two evaluations at one point show the renderer's own run-to-run difference
(Dr.Jit's parallel reductions are not bitwise reproducible), which the dogleg's accept/reject
decisions turn into different paths.
"""
from __future__ import annotations

import tempfile

import numpy as np

import invface
from invface.fit.calibrate import Calibration
from invface.fit.curves import fit_curves, read_curves
from invface.fit.samples import write_sample_plates
from invface.fit.shading import ShadingObjective, face_window
from invface.model.rig import euler_xyz
from invface.render.plates import load_plate
from invface.render.synthetic import skin_albedo, studio_light


def main():
    np.set_printoptions(precision=17)
    model = invface.template.build()
    cal = Calibration(gamma=studio_light(), albedo=skin_albedo(model))
    with tempfile.TemporaryDirectory() as tmp:
        path, = write_sample_plates(model, tmp, names=["smile_blendshape"])
        plate = load_plate(path)
        curves = read_curves(path.with_name(path.stem + ".curves.json"), model)
    cf = fit_curves(model, plate.camera, curves)
    print(f"curve stage: rotation {cf.rotation}, translation {cf.translation}, RMS {cf.rms_px!r} px")
    sm = model.surface_model("blendshape")
    xr = sm.surface(cf.p) @ euler_xyz(cf.rotation).T + cf.translation
    obj = ShadingObjective(model, sm, plate.camera, plate.image, cal.gamma, cal.albedo, cf.p, curves,
                           window=face_window(plate.camera, xr))
    z = np.r_[cf.p, cf.rotation, cf.translation]
    for k in range(2):
        ne = obj.normal_equations(z)
        print(f"normal equations, evaluation {k + 1}: cost {ne.cost!r}, gradient[:3] {ne.gradient[:3]}, "
              f"H[0, :3] {ne.hessian[0, :3]}")


if __name__ == "__main__":
    main()
