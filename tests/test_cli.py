import subprocess
import sys

import numpy as np
import pytest
import trimesh

from conftest import SMALL_RESOLUTION
from invface.errors import InvfaceError, MeshError


def run(*args, env=None):
    return subprocess.run([sys.executable, "-m", "invface.cli", *args], capture_output=True, text=True, env=env)


def test_build_model_writes_a_bundle_and_summary(small_model, tmp_path):
    out = tmp_path / "head.npz"
    r = run("build-model", "--template", "--resolution", str(SMALL_RESOLUTION), "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert "tets" in r.stdout and "min dihedral" in r.stdout and "muscles" in r.stdout
    with np.load(out, allow_pickle=False) as d:
        assert d["tets"].shape == small_model.tets.shape


def test_cli_reports_a_bad_bundle_in_one_line(tmp_path):
    bad = tmp_path / "broken.npz"
    bad.write_bytes(b"\x00" * 100)
    r = run("build-model", str(bad))
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "broken.npz" in lines[0] and "Traceback" not in r.stderr


def test_bad_resolution_is_a_clear_error():
    r = run("build-model", "--template", "--resolution", "1000")
    assert r.returncode == 2 and "resolution" in r.stderr and "Traceback" not in r.stderr


def test_calibrate_command_writes_calibration_and_comparison(small_expressive_model, tmp_path):
    from invface.fit.calibrate import Calibration
    from invface.render.camera import Camera
    from invface.render.plates import write_image
    from invface.render.synthetic import render_plate, skin_albedo, studio_light
    m = small_expressive_model
    cam = Camera.front_view(160, 120)
    image, _ = render_plate(m, m.neutral, cam, studio_light(), skin_albedo(m), spp=16)
    write_image(tmp_path / "neutral.png", image, bits=16)
    cam.save(tmp_path / "neutral.json")                       # the sidecar camera
    out = tmp_path / "calib.npz"
    r = run("calibrate", str(tmp_path / "neutral.png"), "--resolution", str(SMALL_RESOLUTION),
            "--max-iter", "10", "-o", str(out))
    assert r.returncode == 0, r.stderr
    assert "pixel RMS" in r.stdout
    assert "\r" not in r.stderr + r.stdout and "calibrate lighting" not in r.stderr   # no bar off a terminal
    cal = Calibration.load(out, vertex_count=len(m.neutral))
    assert cal.history[-1]["rms"] < 0.02 and cal.camera.size == (160, 120)
    assert (tmp_path / "calib_compare.png").stat().st_size > 1000
    # a camera of another size is refused in one line, naming the plate
    Camera.front_view(200, 120).save(tmp_path / "other.json")
    r = run("calibrate", str(tmp_path / "neutral.png"), "--camera", str(tmp_path / "other.json"),
            "--resolution", str(SMALL_RESOLUTION), "-o", str(out), "--overwrite")
    assert r.returncode == 2 and "neutral.png: plate is 160x120" in r.stderr and "Traceback" not in r.stderr


def test_calibrate_auto_pose_finds_the_pose_from_curves(small_expressive_model, tmp_path):
    """A plate of unknown pose: --auto-pose solves it from the curve file beside the plate
    (Eq. 15) before calibrating; --pose with it is refused."""
    from invface.fit.calibrate import Calibration
    from invface.fit.curves import PLATE_CURVES, curve_points, projection_jacobian, write_curves
    from invface.model.rig import euler_xyz
    from invface.render.camera import Camera
    from invface.render.plates import write_image
    from invface.render.synthetic import render_plate, skin_albedo, studio_light
    m = small_expressive_model
    cam = Camera.front_view(240, 180)
    rot, tr = np.array([0.05, -0.15, 0.02]), np.array([0.004, -0.003, 0.01])
    image, _ = render_plate(m, m.neutral, cam, studio_light(), skin_albedo(m), rot, tr, spp=16)
    write_image(tmp_path / "p.png", image, bits=16)
    xr = m.neutral @ euler_xyz(rot).T + tr
    names = PLATE_CURVES + ("nose_bridge", "nose_base", "jaw_line")
    write_curves(tmp_path / "p.curves.json", {n: projection_jacobian(cam, curve_points(m, n, xr))[0] for n in names})
    out = tmp_path / "calib.npz"
    args = ("--resolution", str(SMALL_RESOLUTION), "--max-iter", "5", "-o", str(out))
    r = run("calibrate", str(tmp_path / "p.png"), "--auto-pose", *args)
    assert r.returncode == 0, r.stderr
    assert "pose from 11 curves (" in r.stdout
    cal = Calibration.load(out, vertex_count=len(m.neutral))
    assert np.abs(cal.rotation - rot).max() < 0.01 and np.abs(cal.translation - tr).max() < 0.002
    r = run("calibrate", str(tmp_path / "p.png"), "--auto-pose", "--pose", *["0"] * 6, *args, "--overwrite")
    assert r.returncode == 2 and "--auto-pose" in r.stderr and "Traceback" not in r.stderr


def test_camera_calibrate_needs_the_board(tmp_path):
    from invface.render.plates import write_image
    for i in range(3):
        write_image(tmp_path / f"b{i}.png", np.full((40, 50, 3), 0.5, np.float32))
    r = run("camera", "calibrate", *[str(tmp_path / f"b{i}.png") for i in range(3)], "--board", "7x5",
            "-o", str(tmp_path / "cam.json"))
    assert r.returncode == 2 and "found in 0 of 3 images" in r.stderr and "Traceback" not in r.stderr


def test_fit_scan_command(small_expressive_model, tmp_path):
    import json
    import trimesh
    m = small_expressive_model
    x = m.surface({"mouthSmileLeft": 0.6, "jaw": [0.05, 0, 0, 0, 0, 0]})
    trimesh.Trimesh(x, m.triangles, process=False).export(tmp_path / "scan.ply")
    r = run("fit-scan", str(tmp_path / "scan.ply"), "--resolution", str(SMALL_RESOLUTION),
            "--lam", "1e-8", "-o", str(tmp_path / "out"))
    assert r.returncode == 0, r.stderr
    fit = json.loads((tmp_path / "out" / "fit.json").read_text())
    assert abs(fit["weights"]["mouthSmileLeft"] - 0.6) < 1e-3 and fit["error_mm"]["max"] < 0.01
    assert (tmp_path / "out" / "fitted.ply").exists()
    assert fit["scan_unit"] == "m" and "scan unit: m (found from its size)" in r.stdout
    # the same scan in millimetres: found, said, and fitted as well (was 82 m off, exit 0)
    trimesh.Trimesh(x * 1000, m.triangles, process=False).export(tmp_path / "scan_mm.ply")
    r = run("fit-scan", str(tmp_path / "scan_mm.ply"), "--resolution", str(SMALL_RESOLUTION),
            "--lam", "1e-8", "-o", str(tmp_path / "out_mm"))
    assert r.returncode == 0, r.stderr
    assert "scan unit: mm (found from its size)" in r.stdout
    fit = json.loads((tmp_path / "out_mm" / "fit.json").read_text())
    assert fit["scan_unit"] == "mm" and fit["error_mm"]["max"] < 0.01
    trimesh.Trimesh(x * 1e5, m.triangles, process=False).export(tmp_path / "scan_huge.ply")
    r = run("fit-scan", str(tmp_path / "scan_huge.ply"), "--resolution", str(SMALL_RESOLUTION))
    assert r.returncode == 2 and "scan_huge.ply" in r.stderr and "no head size" in r.stderr
    (tmp_path / "junk.ply").write_bytes(b"not a mesh at all")
    r = run("fit-scan", str(tmp_path / "junk.ply"), "--resolution", str(SMALL_RESOLUTION))
    assert r.returncode == 2 and "junk.ply" in r.stderr and "Traceback" not in r.stderr
    trimesh.Trimesh(x[:-10], m.triangles[:100], process=False).export(tmp_path / "other.ply")
    r = run("fit-scan", str(tmp_path / "other.ply"), "--resolution", str(SMALL_RESOLUTION))
    assert r.returncode == 2 and "--mode nearest" in r.stderr and "Traceback" not in r.stderr


def test_fit_plate_command_rejects_black_plates_and_unknown_curves(small_expressive_model, tmp_path):
    import json

    from invface.fit.calibrate import Calibration
    from invface.render.plates import write_image
    from invface.render.synthetic import skin_albedo, studio_light
    m = small_expressive_model
    Calibration(gamma=studio_light(), albedo=skin_albedo(m)).save(tmp_path / "calib.npz")
    write_image(tmp_path / "black.png", np.zeros((60, 80, 3), np.float32))
    (tmp_path / "black.curves.json").write_text(json.dumps({"curves": {"lip_outer_upper": [[1, 2], [3, 4]]}}))
    args = ("--calib", str(tmp_path / "calib.npz"), "--resolution", str(SMALL_RESOLUTION))
    r = run("fit-plate", str(tmp_path / "black.png"), *args)
    assert r.returncode == 2 and "black.png" in r.stderr and "black" in r.stderr and "Traceback" not in r.stderr
    (tmp_path / "bad.json").write_text(json.dumps({"curves": {"left_ear": [[1, 2], [3, 4]]}}))
    r = run("fit-plate", str(tmp_path / "black.png"), "--curves", str(tmp_path / "bad.json"), *args)
    assert r.returncode == 2 and "left_ear" in r.stderr and "Traceback" not in r.stderr
    r = run("fit-plate", str(tmp_path / "missing.png"), *args)
    assert r.returncode == 2 and "not found" in r.stderr


def test_fit_plate_on_a_folder_fits_the_frames_and_writes_the_sequence_page(small_expressive_model, tmp_path):
    import json

    from invface.fit.calibrate import Calibration
    from invface.fit.samples import write_sample_plates
    from invface.render.synthetic import skin_albedo, studio_light
    m = small_expressive_model
    Calibration(gamma=studio_light(), albedo=skin_albedo(m)).save(tmp_path / "calib.npz")
    write_sample_plates(m, tmp_path / "shot", names=["neutral", "smile_blendshape"], size=(320, 240))
    out = tmp_path / "out"
    r = run("fit-plate", str(tmp_path / "shot"), "--calib", str(tmp_path / "calib.npz"),
            "--resolution", str(SMALL_RESOLUTION), "--iterations", "8", "--curve-lambda", "400", "-o", str(out))
    assert r.returncode == 0, r.stderr
    fits = {f: json.loads((out / f / "blendshape" / "fit.json").read_text()) for f in ("neutral", "smile_blendshape")}
    w = {f: s["weights"]["mouthSmileLeft"] for f, s in fits.items()}
    assert w["smile_blendshape"] > w["neutral"] + 0.2          # the truth: 0.7 and 0
    from invface.model.arkit import ARKIT_NAMES                 # every fit says it in ARKit too
    assert all(list(s["arkit"]) == list(ARKIT_NAMES) for s in fits.values())
    assert fits["smile_blendshape"]["arkit"]["mouthSmileLeft"] == pytest.approx(w["smile_blendshape"], abs=1e-6)
    from invface.io.livelink import read_livelink_csv      # and as a Live Link Face CSV, a row per frame
    rows = read_livelink_csv(out / "arkit_blendshape.csv")
    assert [r["MouthSmileLeft"] for r in rows] == pytest.approx([fits[f]["arkit"]["mouthSmileLeft"]
                                                                 for f in ("neutral", "smile_blendshape")], abs=1e-6)
    from pxr import Usd, UsdGeom                           # and as a USD take, a sample per frame
    stage = Usd.Stage.Open(str(out / "face_blendshape.usd"))
    face = stage.GetPrimAtPath("/Capture/Face")
    assert len(UsdGeom.Mesh(face).GetPointsAttr().GetTimeSamples()) == 2
    assert [face.GetAttribute("arkit:mouthSmileLeft").Get(t) for t in (0, 1)] == pytest.approx(
        [fits[f]["arkit"]["mouthSmileLeft"] for f in ("neutral", "smile_blendshape")], abs=1e-6)
    # each frame is compared with its truth file (NAME.truth.json beside the plate)
    assert all(s["truth"]["shape_median_mm"] < 0.5 for s in fits.values()), [s["truth"] for s in fits.values()]
    page = (out / "index.html").read_text()
    assert "weights_blendshape.png" in page and (out / "weights_blendshape.png").is_file()
    import re                                                # every picture says what it shows
    for p in [out / "index.html", *out.glob("*/index.html")]:
        tags = re.findall(r"<img[^>]*>", p.read_text())
        assert tags and all(re.search(r'alt="[^"]+"', t) for t in tags), p
    assert 'href="smile_blendshape/index.html"' in page and (out / "smile_blendshape" / "index.html").is_file()
    (out / "index.html").unlink()
    r = run("report", str(out))                       # the report verb rewrites the sequence page
    assert r.returncode == 0, r.stderr
    assert "2 frames" in (out / "index.html").read_text()


def test_cli_simulate(small_expressive_model, tmp_path, capsys):
    from invface.cli import main
    m = small_expressive_model
    path = tmp_path / "m.npz"
    m.save(path)
    acts = tmp_path / "smile.json"
    acts.write_text('{"activations": {"zygomaticus_major_L": 0.7}, "jaw": [0.05, 0, 0, 0, 0, 0]}')
    rc = main(["simulate", "--model", str(path), "--activations", str(acts), "-o", str(tmp_path / "x.obj"),
               "--preview", str(tmp_path / "p.png")])
    out = capsys.readouterr().out
    assert rc == 0 and "converged" in out and (tmp_path / "x.obj").exists() and (tmp_path / "p.png").exists()
    assert main(["simulate", "--model", str(path), "--set", "zygomaticus_major_L=nan"]) == 2
    assert "zygomaticus_major_L" in capsys.readouterr().err
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    assert main(["simulate", "--model", str(path), "--activations", str(bad)]) == 2
    assert "bad.json" in capsys.readouterr().err
    # blendshape-driven: weights drive the tracks, the activations are read out
    rc = main(["simulate", "--model", str(path), "--weight", "mouthSmileLeft=1", "-o", str(tmp_path / "w.obj")])
    out = capsys.readouterr().out
    assert rc == 0 and "zygomaticus_major_L" in out and "converged" in out and (tmp_path / "w.obj").exists()
    assert main(["simulate", "--model", str(path), "--weight", "smile=1"]) == 2
    assert "unknown blendshape" in capsys.readouterr().err
    assert main(["simulate", "--model", str(path), "--weight", "mouthSmileLeft=1", "--set", "mentalis_L=0.2"]) == 2


def test_cli_rejects_a_sphere(tmp_path, capsys):
    from invface.cli import main
    trimesh.creation.icosphere(4, radius=90.0).export(tmp_path / "ball.obj")
    rc = main(["build-model", "--neutral", str(tmp_path / "ball.obj"), "--resolution", "0.3",
               "--expressions", "none", "-o", str(tmp_path / "x.npz")])
    assert rc != 0
    assert "face" in capsys.readouterr().err
    assert not (tmp_path / "x.npz").exists()
    assert isinstance(MeshError("x"), InvfaceError)


def test_fit_plate_writes_the_kinds_that_finish_and_exits_0(small_expressive_model, tmp_path, monkeypatch, capsys):
    """A simulation that cannot reach an equilibrium leaves the blendshape fit written and
    the exit status 0; when no kind finishes, status 2 and one line naming why."""
    from invface.cli import main
    from invface.fit.calibrate import Calibration
    from invface.fit.samples import write_sample_plates
    from invface.render.synthetic import skin_albedo, studio_light
    from test_pipeline import _failing_simulation
    m = small_expressive_model
    path, = write_sample_plates(m, tmp_path / "plates", names=["smile_blendshape"], size=(240, 180))
    Calibration(gamma=studio_light(), albedo=skin_albedo(m)).save(tmp_path / "calib.npz")
    args = [str(path), "--calib", str(tmp_path / "calib.npz"), "--resolution", str(SMALL_RESOLUTION),
            "--model-kind", "both", "--no-shading"]
    _failing_simulation(monkeypatch)
    assert main(["fit-plate", *args, "-o", str(tmp_path / "out")]) == 0
    out = capsys.readouterr().out
    assert "smile_blendshape.png simulation: did not finish: Newton did NOT converge" in out
    assert (tmp_path / "out/blendshape/fit.json").is_file() and (tmp_path / "out/index.html").is_file()
    from invface.io.livelink import read_livelink_csv      # the kind that finished, in ARKit (one row)
    rows = read_livelink_csv(tmp_path / "out/arkit_blendshape.csv")
    assert len(rows) == 1 and not (tmp_path / "out/arkit_simulation.csv").exists()
    assert (tmp_path / "out/face_blendshape.usd").is_file() and not (tmp_path / "out/face_simulation.usd").exists()
    _failing_simulation(monkeypatch, kinds=("blendshape", "simulation"))
    assert main(["fit-plate", *args, "-o", str(tmp_path / "none")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "no model kind finished: blendshape: Newton did NOT converge" in err[0], err


def test_report_names_a_truncated_fit_file_and_bad_numbers_are_refused(tmp_path, capsys):
    (tmp_path / "fit.json").write_text('{"kind": "blendshape", "weights": {}}')
    (tmp_path / "fit.npz").write_bytes(b"PK\x03\x04" + b"\x00" * 40)         # a zip cut short
    r = run("report", str(tmp_path))
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert str(tmp_path) in r.stderr and "truncated or corrupt" in r.stderr, r.stderr
    r = run("fit-plate", str(tmp_path / "fit.json"), "--iterations", "-1")
    assert r.returncode == 2 and "argument --iterations: must be >= 0, not -1" in r.stderr and "Traceback" not in r.stderr
    from invface.cli import main
    for option, value in (("--workers", "0"), ("--temporal", "-1"), ("--temporal-shading", "-0.5")):
        assert main(["fit-plate", str(tmp_path / "fit.json"), option, value]) == 2
        last = capsys.readouterr().err.strip().splitlines()[-1]
        assert f"argument {option}:" in last and f"not {value}" in last, last


def test_implausible_plate_inputs_are_refused_or_flagged(small_expressive_model, tmp_path, monkeypatch, capsys):
    """Curves off the plate: refused. One curve: fitted, with a warning printed and in
    fit.json. A folder with an earlier run: refused without --force, replaced with it. A run
    stopped after one kind: the report says which kind is missing."""
    import json

    from invface.cli import main
    from invface.fit.calibrate import Calibration
    from invface.fit.samples import write_sample_plates
    from invface.render.synthetic import skin_albedo, studio_light
    m = small_expressive_model
    path, = write_sample_plates(m, tmp_path / "plates", names=["smile_blendshape"], size=(240, 180))
    Calibration(gamma=studio_light(), albedo=skin_albedo(m)).save(tmp_path / "calib.npz")
    curves = json.loads(path.with_name("smile_blendshape.curves.json").read_text())["curves"]
    args = [str(path), "--calib", str(tmp_path / "calib.npz"), "--resolution", str(SMALL_RESOLUTION), "--no-shading"]

    (tmp_path / "far.json").write_text(json.dumps({"curves": {n: (np.array(c) * 10).tolist() for n, c in curves.items()}}))
    assert main(["fit-plate", *args, "--curves", str(tmp_path / "far.json"), "-o", str(tmp_path / "far")]) == 2
    err = capsys.readouterr().err
    assert "lies outside the 240x180 plate" in err and "far.json" in err, err

    (tmp_path / "one.json").write_text(json.dumps({"curves": {"lip_outer_upper": curves["lip_outer_upper"]}}))
    assert main(["fit-plate", *args, "--curves", str(tmp_path / "one.json"), "-o", str(tmp_path / "one")]) == 0
    assert "warning: " in capsys.readouterr().out
    fit = json.loads((tmp_path / "one/blendshape/fit.json").read_text())
    assert len(fit["warnings"]) == 1 and "1 facial feature(s) (lips)" in fit["warnings"][0]
    assert "pose from them is uncertain" in (tmp_path / "one/index.html").read_text()

    assert main(["fit-plate", *args, "-o", str(tmp_path / "one")]) == 2
    assert "holds an earlier run's fits" in capsys.readouterr().err
    assert main(["fit-plate", *args, "-o", str(tmp_path / "one"), "--force"]) == 0
    assert json.loads((tmp_path / "one/blendshape/fit.json").read_text())["warnings"] == []
    # a run whose identity started in the face-shape space is another run, either way round: not resumed
    assert main(["fit-plate", *args, "-o", str(tmp_path / "one"), "--identity-space"]) == 2
    assert "holds an earlier run's fits" in capsys.readouterr().err
    assert main(["fit-plate", *args, "-o", str(tmp_path / "space"), "--identity-space"]) == 0
    assert main(["fit-plate", *args, "-o", str(tmp_path / "space")]) == 2
    assert "holds an earlier run's fits" in capsys.readouterr().err

    import invface.fit.plate as plate_module
    real = plate_module.fit_plate

    def stopped(model, plate, calibration, curves, kind="blendshape", **options):
        if kind == "simulation":
            raise KeyboardInterrupt
        return real(model, plate, calibration, curves, kind=kind, **options)
    monkeypatch.setattr(plate_module, "fit_plate", stopped)
    assert main(["fit-plate", *args, "--model-kind", "both", "-o", str(tmp_path / "stop")]) == 130   # Ctrl-C
    assert capsys.readouterr().err.strip().splitlines()[-1] == "invface: interrupted"
    assert main(["report", str(tmp_path / "stop")]) == 0
    page = (tmp_path / "stop/index.html").read_text()
    assert "No simulation model fit here (the run stopped before it finished)." in page


def test_calibrate_refuses_a_black_plate_and_flags_noise(small_expressive_model, tmp_path):
    from invface.render.plates import write_image
    write_image(tmp_path / "black.png", np.zeros((90, 120, 3), np.float32))
    r = run("calibrate", str(tmp_path / "black.png"), "--resolution", str(SMALL_RESOLUTION), "--max-iter", "2",
            "-o", str(tmp_path / "c.npz"))
    assert r.returncode == 2 and "black.png" in r.stderr and "black" in r.stderr and "Traceback" not in r.stderr
    write_image(tmp_path / "noise.png", np.random.default_rng(0).random((90, 120, 3)).astype(np.float32))
    r = run("calibrate", str(tmp_path / "noise.png"), "--resolution", str(SMALL_RESOLUTION), "--max-iter", "5",
            "-o", str(tmp_path / "c.npz"))
    assert r.returncode == 0, r.stderr
    assert "warning: noise.png: the calibration's pixel RMS is" in r.stdout, r.stdout
