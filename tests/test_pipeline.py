"""The session layer (invface.pipeline), the fit vector's layout, the surface-model registry
and the gradient-only path's single adjoint product."""
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

import invface
from conftest import SMALL_RESOLUTION
from invface.errors import ControlsError, InvfaceError
from invface.model import FitVector

ROOT = Path(__file__).resolve().parents[1]


def test_fit_vector_packs_names_bounds_and_dicts(small_expressive_model):
    m = small_expressive_model
    vec = FitVector.of(m)
    K = len(m.blendshape_names)
    assert (vec.K, vec.P, vec.size) == (K, K + 6, K + 12) and len(vec.names) == vec.size
    p = np.linspace(0, 1, vec.P)
    z = vec.pack(p, [0.1, 0.2, 0.3], [0.01, 0.02, 0.03])
    q, rot, tr = vec.unpack(z)
    assert np.array_equal(q, p) and np.array_equal(rot, [0.1, 0.2, 0.3]) and np.array_equal(tr, [0.01, 0.02, 0.03])
    assert vec.names[vec.K] == "jaw_rx" and vec.names[-1] == "translation_z"
    lo, hi = vec.bounds()
    assert np.all(lo[vec.weights] == 0) and np.all(hi[vec.weights] == 1)
    assert hi[vec.jaw][0] == pytest.approx(0.6) and np.all(np.isinf(lo[vec.pose]))
    d = vec.to_dict(z)
    assert set(d) == {"weights", "jaw", "rotation", "translation", "arkit", "arkit_unsupported", "eyes"}
    assert len(d["weights"]) == K and len(d["arkit"]) == 52
    from invface.model.gaze import eye_angles                                    # each eye's yaw, pitch (rad)
    assert d["eyes"] == {s: {"yaw": pytest.approx(a[0], abs=1e-6), "pitch": pytest.approx(a[1], abs=1e-6)}
                         for s, a in eye_angles(m.blendshape_names, p[:K]).items()}
    assert abs(d["eyes"]["L"]["yaw"]) > 0.01                                      # the eyeLook weights turn them
    np.testing.assert_allclose(vec.from_dict(d), z, atol=1e-6)                 # to_dict rounds to 1e-6
    c = vec.to_controls(z)
    np.testing.assert_allclose(vec.from_controls(c), z, atol=1e-12)
    assert vec.hinge(vec.with_hinge(z, 0.3)) == 0.3
    with pytest.raises(ControlsError, match="expected"):
        vec.unpack(z[:-1])
    with pytest.raises(ControlsError, match="truth.json.*unknown blendshape 'smile'"):
        vec.from_dict({"weights": {"smile": 1.0}}, what="truth.json")


def test_surface_models_come_from_a_registry(small_model):
    from invface.model import register_surface_model
    m = small_model

    class Doubled:
        def __init__(self, model):
            self.rig = model.surface_model("blendshape")

        def surface(self, p):
            return 2 * self.rig.surface(p)
    register_surface_model("doubled", Doubled)
    try:
        np.testing.assert_allclose(m.surface(kind="doubled"), 2 * m.neutral)
        with pytest.raises(InvfaceError, match="'blendshape' or 'simulation' or 'doubled'"):
            m.surface_model("muscles")
    finally:
        from invface.model import facemodel
        facemodel._SURFACE_MODELS.pop("doubled")
        m._surface_models.pop("doubled", None)


def test_layers_import_downwards_only():
    """The model layer and the dogleg do not import the simulation; nothing below the CLI
    imports it, and benches and tests use the library (DESIGN.md, import direction)."""
    code = ("import sys, invface, invface.model, invface.fit.dogleg, invface.model.pose; "
            "print([m for m in sys.modules if m.startswith('invface.sim') or m.startswith('invface.cli')])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0 and out.stdout.strip() == "[]", out.stdout + out.stderr
    users = [str(f.relative_to(ROOT)) for folder in ("bench", "tests", "invface") for f in (ROOT / folder).rglob("*.py")
             if re.search(r"^\s*(from invface\.cli import|import invface\.cli|from invface import cli|from \.+cli import)",
                           f.read_text(), re.M)]
    # the tests of the CLI itself: its verbs, its error path, its bad-input corpus, its reference
    # and examples, its refusal of an unsafe --scheduler
    assert sorted(users) == ["tests/test_bad_inputs.py", "tests/test_cli.py", "tests/test_cluster_security.py",
                             "tests/test_docs.py", "tests/test_error_path.py"], users


def _sim_scene(m):
    from invface.fit.samples import sample_camera
    from invface.render.synthetic import render_plate, skin_albedo, studio_light
    cam = sample_camera(180, 135)
    vec = FitVector.of(m)
    z = vec.from_dict({"weights": {"mouthSmileLeft": 0.5, "browInnerUp": 0.3}, "jaw": [0.03, 0, 0, 0, 0, 0],
                       "rotation": [0.02, -0.05, 0.0], "translation": [0.001, 0.0, 0.002]})
    g, a = studio_light(), skin_albedo(m)
    p, rot, tr = vec.unpack(z)
    plate, _ = render_plate(m, m.surface(vec.to_controls(z)), cam, g, a, rot, tr, spp=8, noise=0.0)
    return cam, vec, z, g, a, plate


def test_gradient_only_path_takes_one_adjoint_product(small_expressive_model):
    """ShadingObjective's (cost, gradient) for L-BFGS: through the Dr.Jit bridge, the
    simulation's surface_vjp once per evaluation and never its Jacobian; the gradient is the
    dogleg path's J^T r of the same render (curves, prior and a sequence's temporal term
    included)."""
    from invface.fit.curves import PLATE_CURVES, curve_points, projection_jacobian
    from invface.model.pose import posed_surface
    from invface.fit.shading import ShadingObjective
    m = small_expressive_model
    cam, vec, z, g, a, plate = _sim_scene(m)
    sm = m.surface_model("simulation")
    xr = posed_surface(sm, z, vec)[1]
    curves = {c: projection_jacobian(cam, curve_points(m, c, xr))[0] + 0.7 for c in PLATE_CURVES}
    previous = z + 0.5 * vec.scales() * np.sin(np.arange(vec.size))
    obj = ShadingObjective(m, sm, cam, plate, g, a, vec.unpack(z)[0] * 0.9, curves, lam1=1e-3, spp=8,
                           previous=previous, temporal=0.02)
    z1 = z.copy()
    z1[vec.weights] *= 0.8
    calls = {"vjp": 0, "jacobian": 0}
    vjp, jac = sm.surface_vjp, sm.surface_jacobian

    def count_vjp(*args):
        calls["vjp"] += 1
        return vjp(*args)

    def count_jac(*args):
        calls["jacobian"] += 1
        return jac(*args)
    sm.surface_vjp, sm.surface_jacobian = count_vjp, count_jac
    try:
        f, grad = obj(z1)
        assert calls == {"vjp": 1, "jacobian": 0}
        ne = obj.normal_equations(z1)
        assert ne.cost == pytest.approx(f, rel=1e-5)
        np.testing.assert_allclose(grad, ne.gradient, rtol=2e-3, atol=2e-3 * np.abs(ne.gradient).max())
    finally:
        sm.surface_vjp, sm.surface_jacobian = vjp, jac
    assert obj.terms["curves"] > 0 and obj.terms["prior"] > 0
    assert obj.terms["temporal"] == pytest.approx(0.01 * np.sum(((z1 - previous) / vec.scales()) ** 2))


def test_readme_from_python_script_runs(small_expressive_model, tmp_path):
    """The README's "From Python" script, as written, on the small head and its own sample
    plates (rendered here at 360x270, as plates/ holds the default head's; output in tmp):
    calibration and both kinds' fits, their files, and named results near the truth."""
    import json

    from invface.fit.samples import write_sample_plates
    text = (ROOT / "README.md").read_text()
    code = re.search(r"## From Python.*?```python\n(.*?)```", text, re.S).group(1)
    assert len(code.strip().splitlines()) <= 12
    write_sample_plates(small_expressive_model, tmp_path / "plates", names=["neutral", "smile_simulation"],
                        size=(360, 270))
    code = code.replace("invface.build_model()", f"invface.build_model(resolution={SMALL_RESOLUTION})")
    code = code.replace('"out/', f'"{tmp_path}/out/').replace('"plates/', f'"{tmp_path}/plates/')
    scope = {}
    exec(compile(code, "README.md", "exec"), scope)
    fit, calib = scope["fit"], scope["calib"]
    for f in ("calib.npz", "calib_compare.png", "smile/index.html", "smile/blendshape/fit.json",
              "smile/simulation/fit.npz"):
        assert (tmp_path / "out" / f).is_file(), f
    sim = fit["simulation"]
    assert calib.pose is not None and calib.rms < 0.05, calib.rms
    # the truth: mouthSmileLeft 0.7, _R 0.6, cheekRaise 0.3 (zygomaticus major active); two runs
    # measured 0.35 + 0.25 and 0.40 + 0.25 (the fit trades some of it for dimpler)
    assert sim.weights["mouthSmileLeft"] + sim.weights["mouthSmileRight"] > 0.4, sim.weights
    assert sim.activations["zygomaticus_major_L"] > 0.05, sim.activations
    saved = json.loads((tmp_path / "out/smile/simulation/fit.json").read_text())
    assert saved["weights"] == sim.weights and saved["truth"]["median_mm"] == fit.truth["simulation"]["median_mm"]
    assert set(fit.truth) == {"blendshape", "simulation"}
    assert all(t["shape_median_mm"] < 0.5 for t in fit.truth.values()), fit.truth


def test_pipeline_refuses_unknown_kinds_and_one_curves_file_for_a_sequence(small_model, tmp_path):
    from invface.pipeline import fit_sequence, model_kinds
    assert model_kinds("both") == ("blendshape", "simulation")
    with pytest.raises(InvfaceError, match="unknown model kind"):
        model_kinds("muscles")
    with pytest.raises(InvfaceError, match="one curves file names one plate"):
        fit_sequence(small_model, [ROOT / "plates/neutral.png"] * 2, None, curves="c.json")
    with pytest.raises(InvfaceError, match="pose must be 'auto' or"):
        invface.calibrate(ROOT / "plates/neutral.png", model=small_model, pose="frontal")
    assert set(invface.__all__) >= {"build_model", "fit_scan", "fit_plate", "calibrate"}
    with pytest.raises(AttributeError):
        invface.fit_everything


def _failing_simulation(monkeypatch, kinds=("simulation",)):
    """Make fit.plate.fit_plate raise SimulationError for ``kinds`` (the others run)."""
    import invface.fit.plate as plate_module
    from invface.errors import SimulationError
    real = plate_module.fit_plate

    def fit_plate(model, plate, calibration, curves, kind="blendshape", **options):
        if kind in kinds:
            raise SimulationError("Newton did NOT converge in 40 iterations (test)")
        return real(model, plate, calibration, curves, kind=kind, **options)
    monkeypatch.setattr(plate_module, "fit_plate", fit_plate)


def test_a_kind_that_cannot_finish_is_recorded_and_the_others_are_written(small_expressive_model, tmp_path,
                                                                          monkeypatch):
    import json

    from invface.fit.calibrate import Calibration
    from invface.fit.samples import write_sample_plates
    from invface.pipeline import fit_sequence
    from invface.render.synthetic import skin_albedo, studio_light
    m = small_expressive_model
    path, = write_sample_plates(m, tmp_path / "plates", names=["smile_blendshape"], size=(240, 180))
    cal = Calibration(gamma=studio_light(), albedo=skin_albedo(m))
    _failing_simulation(monkeypatch)
    frame = fit_sequence(m, [path], cal, tmp_path / "out", kinds="both", shading=False)[0]["fit"]
    assert set(frame.fits) == {"blendshape"} and "did NOT converge" in frame.failed["simulation"]
    saved = json.loads((tmp_path / "out/blendshape/fit.json").read_text())
    assert any("simulation model's fit did not finish: Newton did NOT" in n for n in saved["notes"])
    assert not (tmp_path / "out/simulation").exists()
    assert "simulation model&#x27;s fit did not finish" in (tmp_path / "out/index.html").read_text()
    # no kind finishes: nothing is written, and saving names why
    _failing_simulation(monkeypatch, kinds=("blendshape", "simulation"))
    frame = fit_sequence(m, [path], cal, tmp_path / "none", kinds="both", shading=False)[0]["fit"]
    from invface.report.runs import earlier_fits
    assert frame.fits == {} and earlier_fits(tmp_path / "none") == []
    with pytest.raises(InvfaceError, match="no model kind finished: blendshape: Newton did NOT"):
        frame.save(tmp_path / "none")


def test_subpackages_are_attributes_and_a_bare_import_stays_light():
    """After ``import invface`` the subpackages and their modules are reachable as attributes
    (imported then), and the bare import loads neither Mitsuba nor Dr.Jit."""
    code = ("import sys, invface; light = 'mitsuba' not in sys.modules and 'drjit' not in sys.modules; "
            "ok = callable(invface.pipeline.find_curves) and callable(invface.report.fit.write_report) "
            "and callable(invface.render.renderer.FaceRenderer) and callable(invface.sim.quasistatic.Simulator) "
            "and callable(invface.io.export) and callable(invface.fit.shading.fit_shading); print(light, ok)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT)
    assert out.stdout.split() == ["True", "True"], out.stdout + out.stderr
