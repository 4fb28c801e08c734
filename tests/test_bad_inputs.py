"""The bad-input corpus (issue 63): every input the CLI reads, malformed, through ``main(argv)``
in-process. Each case exits 2 with a last stderr line that names its own input, prints no
traceback, starts no solve and leaves the output folder as it was."""
import hashlib
import json

import numpy as np
import pytest

from invface.cli import main


def _folder_hash(folder):
    h = hashlib.sha1()
    for p in sorted(folder.rglob("*")):
        h.update(str(p.relative_to(folder)).encode())
        if p.is_file():
            h.update(p.read_bytes())
    return h.hexdigest()


def _plate(path, rgba=False):
    import cv2
    img = np.zeros((64, 64, 4), np.uint8) if rgba else np.full((64, 64, 3), 128, np.uint8)
    cv2.imwrite(str(path), img)
    return path.name


def _mesh(path, nan=False):
    import trimesh
    m = trimesh.creation.icosphere(subdivisions=2, radius=0.1)
    v = np.array(m.vertices)
    if nan:
        v[3] = np.nan
    path.write_text("\n".join([f"v {a} {b} {c}" for a, b, c in v] + [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in m.faces]))
    return path.name


def _curves(path, **data):
    path.write_text(json.dumps(data))
    return path.name


# name: (files to make {name: maker(path)}, argv (relative names), text the last line must hold)
CASES = {
    "calibrate --square 0": ({"board.png": _plate}, ["camera", "calibrate", "board.png", "--board", "9x6",
                                                      "--square", "0", "-o", "out/cam.json"], "--square"),
    "fit-scan of a JSON file": ({"scan.json": lambda p: p.write_text("[1, 2]")}, ["fit-scan", "scan.json", "-o", "out"],
                                "scan.json"),
    "fit-scan --lam -1": ({"scan.obj": _mesh}, ["fit-scan", "scan.obj", "--lam", "-1", "-o", "out"], "--lam"),
    "fit-scan --max-iter 0": ({"scan.obj": _mesh}, ["fit-scan", "scan.obj", "--max-iter", "0", "-o", "out"],
                              "--max-iter"),
    "fit-scan of a NaN vertex": ({"nan.obj": lambda p: _mesh(p, nan=True)},
                                 ["fit-scan", "nan.obj", "--unit", "m", "-o", "out"], "nan.obj"),
    "fit-plate --curve-lambda -1": ({"plate.png": _plate}, ["fit-plate", "plate.png", "--curve-lambda", "-1",
                                                            "-o", "out"], "--curve-lambda"),
    "curves with image_size 5": ({"plate.png": _plate, "c.json": lambda p: _curves(
        p, image_size=5, curves={"lip_outer_upper": [[1, 2], [3, 4]]})},
        ["fit-plate", "plate.png", "--curves", "c.json", "--no-identity", "-o", "out"], "c.json"),
    "curves not a list of points": ({"plate.png": _plate, "c.json": lambda p: _curves(
        p, curves={"lip_outer_upper": "here"})},
        ["fit-plate", "plate.png", "--curves", "c.json", "--no-identity", "-o", "out"], "c.json"),
    "curves of an unknown name": ({"plate.png": _plate, "c.json": lambda p: _curves(
        p, curves={"lips": [[1, 2], [3, 4]]})},
        ["fit-plate", "plate.png", "--curves", "c.json", "--no-identity", "-o", "out"], "c.json"),
    "a transparent plate": ({"clear.png": lambda p: _plate(p, rgba=True)}, ["fit-plate", "clear.png", "-o", "out"],
                            "clear.png"),
    "a calibration that is not an NPZ": ({"plate.png": _plate, "calib.npz": lambda p: p.write_bytes(b"garbage"),
                                          "c.json": lambda p: _curves(p, curves={"lip_outer_upper": [[20, 30], [40, 30]]})},
                                         ["fit-plate", "plate.png", "--calib", "calib.npz", "--curves", "c.json",
                                          "-o", "out"], "calib.npz"),
    "a model that is not a bundle": ({"plate.png": _plate, "head.npz": lambda p: p.write_text("{}")},
                                     ["fit-plate", "plate.png", "--model", "head.npz", "-o", "out"], "head.npz"),
    "simulate into a file with no mesh suffix": ({}, ["simulate", "--weight", "mouthSmileLeft=1", "-o", "out/result"],
                                                 "out/result"),
    "a plate that does not exist": ({}, ["fit-plate", "missing.png", "-o", "out"], "missing.png"),
    "export of a folder with no fit": ({}, ["export", "out"], "out"),
    "export in an unknown format": ({"out/blendshape/fit.json": lambda p: p.write_text("{}")},
                                    ["export", "out", "--format", "fbx"], "fbx"),
    # a run's records, edited by hand or by another tool
    "report of a fit.json whose weights are a list": (
        {"out/blendshape/fit.json": lambda p: p.write_text('{"kind": "blendshape", "weights": [0.5]}')},
        ["report", "out"], "fit.json: field 'weights' is list, not a JSON object of numbers"),
    "export of a fit.json with an ARKit value in words": (
        {"out/blendshape/fit.json": lambda p: p.write_text('{"arkit": {"jawOpen": "wide"}}')},
        ["export", "out", "--format", "csv"], "arkit: field 'jawOpen' is \"wide\""),
    "export of a run.json whose frames are a number": (
        {"out/run.json": lambda p: p.write_text('{"frames": 3}')}, ["export", "out"],
        "run.json: field 'frames' is int, not a list of strings"),
    # plates as VFX delivers them
    "a sequence pattern that matches no file": ({}, ["fit-plate", "shot.####.exr", "-o", "out"], "shot.####.exr"),
    "a DPX that is not one": ({"p.dpx": lambda p: p.write_bytes(b"not a dpx file")}, ["fit-plate", "p.dpx", "-o", "out"],
                              "p.dpx"),
    "--frames beyond the sequence's numbers": ({"seq/shot.0001.png": _plate, "seq/shot.0002.png": _plate},
                                               ["fit-plate", "seq/shot.####.png", "--frames", "5-9", "-o", "out"],
                                               "--frames 5-9"),
    "an unknown --colorspace": ({"plate.png": _plate}, ["fit-plate", "plate.png", "--colorspace", "nope", "-o", "out"],
                                "--colorspace"),
    # an existing output is refused unless --overwrite, the same way by every verb, before any work
    "calibrate onto an existing calibration": ({"plate.png": _plate, "out/calib.npz": lambda p: p.write_bytes(b"x")},
                                               ["calibrate", "plate.png", "-o", "out/calib.npz"],
                                               "out/calib.npz: already exists; pass --overwrite"),
    "fit-scan into a folder that holds a fit": ({"scan.obj": _mesh, "out/fit.json": lambda p: p.write_text("{}")},
                                                ["fit-scan", "scan.obj", "-o", "out"], "--overwrite"),
    "camera calibrate onto a camera file": ({"board.png": _plate, "out/cam.json": lambda p: p.write_text("{}")},
                                            ["camera", "calibrate", "board.png", "--board", "9x6", "-o",
                                             "out/cam.json"], "out/cam.json: already exists"),
    "build-model under a file": ({"out/afile": lambda p: p.write_text("")},
                                 ["build-model", "--template", "-o", "out/afile/x.npz"], "a file stands where a folder"),
    "simulate onto an existing mesh": ({"out/x.obj": lambda p: p.write_text("")},
                                       ["simulate", "--weight", "mouthSmileLeft=1", "-o", "out/x.obj"], "out/x.obj"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_bad_input_is_one_clear_line(case, tmp_path, monkeypatch, capsys):
    files, argv, named = CASES[case]
    monkeypatch.chdir(tmp_path)
    (tmp_path / "out").mkdir()
    for name, make in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        make(tmp_path / name)
    before = _folder_hash(tmp_path / "out")
    code = main(argv)
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2, (case, err)
    assert err and named in err[-1], (case, err)
    assert not any("Traceback" in line for line in err), case
    assert _folder_hash(tmp_path / "out") == before, case


def test_sidecar_fields_name_the_file_and_the_field(tmp_path):
    """io.schema.Fields, the one checker of every sidecar's fields: each bad field is one
    InvfaceError that names the file and the field; the calibration's metadata that is not
    JSON (a JSONDecodeError before), a ground-truth weight that is not a number (a ValueError
    before) and a camera's fractional width are three of its readers'."""
    from invface.errors import BundleError, CameraError, InvfaceError
    from invface.fit.calibrate import Calibration
    from invface.io.arrays import savez
    from invface.io.schema import Fields
    from invface.render.camera import Camera
    f = Fields({"K": [[1, 0], [0, 1]], "n": "3", "w": 2.5, "s": 4, "o": [1], "j": "{bad", "none": None},
               "cam.json", listing="fields: K, n")
    for call, words in ((lambda: f.array("K", (3, 3)), "cam.json: field 'K' has shape (2, 2), expected (3, 3)"),
                        (lambda: f.array("missing"), "cam.json: missing field 'missing' (fields: K, n)"),
                        (lambda: f.array("none"), "cam.json: missing field 'none'"),
                        (lambda: f.number("n"), "cam.json: field 'n' is \"3\", not a finite number"),
                        (lambda: f.number("w", integer=True), "cam.json: field 'w' is 2.5, not a whole number"),
                        (lambda: f.number("s", high=3), "cam.json: field 's' is 4, outside [-inf, 3]"),
                        (lambda: f.text("s"), "cam.json: field 's' is int, not a string"),
                        (lambda: f.mapping("o"), "cam.json: field 'o' is list, not a JSON object"),
                        (lambda: f.json("j"), "cam.json: field 'j' is not valid JSON")):
        with pytest.raises(InvfaceError) as e:
            call()
        assert str(e.value).startswith(words), (words, str(e.value))
    assert f.array("absent", default=None) is None and f.number("s") == 4.0
    with pytest.raises(InvfaceError, match="x.json: must hold a JSON object"):
        Fields([1, 2], "x.json")
    calib = tmp_path / "calib.npz"
    savez(calib, dict(gamma=np.zeros((9, 3)), albedo=np.full((5, 3), 0.5), rotation=np.zeros(3),
                      translation=np.zeros(3), meta=np.array("not json")))
    with pytest.raises(BundleError, match="calib.npz: field 'meta' is not valid JSON"):
        Calibration.load(calib)
    from invface.fit.plate import read_truth
    truth = tmp_path / "plate.truth.json"
    truth.write_text(json.dumps({"kind": "simulation", "weights": {"mouthSmileLeft": "a"}, "rotation": [0, 0, 0],
                                 "translation": [0, 0, 0.5]}))
    with pytest.raises(InvfaceError, match="plate.truth.json: weights: field 'mouthSmileLeft' is \"a\""):
        read_truth(truth, None)
    cam = Camera.front_view(64, 48).to_dict()
    with pytest.raises(CameraError, match="cam.json: field 'width' is 64.5, not a whole number"):
        Camera.from_dict(dict(cam, width=64.5), source="cam.json")
    assert Camera.from_dict(cam).size == (64, 48)
