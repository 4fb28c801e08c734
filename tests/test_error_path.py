"""One error path (issue 63 item 1): bad input is one line and exit 2, naming the file or option;
an internal error is one line and exit 1 pointing to --debug, which shows the traceback; native
libraries' log lines stay off the terminal unless debugging."""
import os
import re

import pytest

from invface import cli


def test_an_unwritable_output_is_one_line_naming_it(small_model, tmp_path, capsys):
    bundle = tmp_path / "head.npz"
    small_model.save(bundle)
    (tmp_path / "afile").write_text("not a folder")
    assert cli.main(["build-model", str(bundle), "-o", str(tmp_path / "afile" / "x.npz")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "afile" in err[0] and "a file stands where a folder is needed" in err[0], err
    assert "Traceback" not in "\n".join(err)


def test_an_internal_error_is_exit_1_and_debug_shows_it(monkeypatch, tmp_path, capsys):
    def broken(args):
        raise ValueError("a bug")
    monkeypatch.setattr(cli, "cmd_report", broken)
    monkeypatch.delenv("INVFACE_DEBUG", raising=False)
    assert cli.main(["report", str(tmp_path)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "internal error: ValueError: a bug" in err[0] and "--debug" in err[0], err
    with pytest.raises(ValueError, match="a bug"):
        cli.main(["--debug", "report", str(tmp_path)])
    monkeypatch.delenv("INVFACE_DEBUG", raising=False)


def test_opencv_and_memory_refusals_are_bad_input(monkeypatch, tmp_path, capsys):
    import cv2

    def opencv(args):
        raise cv2.error("OpenCV(4.x) checkerboard.cpp:54: error: (-215:Assertion failed) size > 0 in function 'x'")

    def memory(args):
        raise MemoryError()
    monkeypatch.delenv("INVFACE_DEBUG", raising=False)
    for fn, words in ((opencv, "OpenCV refused the input"), (memory, "out of memory")):
        monkeypatch.setattr(cli, "cmd_report", fn)
        assert cli.main(["report", str(tmp_path)]) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and words in err[0], err


def test_native_log_lines_are_silenced_unless_debugging(monkeypatch, capfd):
    from invface._env import native_stderr_quiet
    monkeypatch.delenv("INVFACE_DEBUG", raising=False)
    with native_stderr_quiet():
        os.write(2, b"W0000 face_landmarker_graph.cc:181] noise\n")
    assert "noise" not in capfd.readouterr().err
    monkeypatch.setenv("INVFACE_DEBUG", "1")
    with native_stderr_quiet():
        os.write(2, b"W0000 shown when debugging\n")
    assert "shown when debugging" in capfd.readouterr().err


@pytest.mark.parametrize("argv, option", [
    (["fit-scan", "scan.ply", "--lam", "-1"], "--lam"),
    (["fit-scan", "scan.ply", "--max-iter", "0"], "--max-iter"),
    (["fit-plate", "p.png", "--curve-lambda", "-1"], "--curve-lambda"),
    (["fit-plate", "p.png", "--resolution", "nan"], "--resolution"),
    (["fit-plate", "p.png", "--workers", "two"], "--workers"),
    (["camera", "calibrate", "a.png", "--square", "0"], "--square"),
    (["calibrate", "p.png", "--max-iter", "-3"], "--max-iter"),
])
def test_numeric_options_are_checked_before_any_work(argv, option, capsys):
    assert cli.main(argv) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert f"argument {option}:" in err[-1] and "Traceback" not in "\n".join(err), err


def test_simulate_refuses_an_output_it_cannot_write_before_solving(monkeypatch, capsys):
    import invface.pipeline
    monkeypatch.setattr(invface.pipeline, "simulate", lambda *a, **k: pytest.fail("solved before checking -o"))
    assert cli.main(["simulate", "--set", "zygomaticus_major_L=0.5", "-o", "result"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "-o result" in err[0] and ".obj" in err[0], err


def test_version(capsys):
    from invface import __version__
    assert cli.main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"invface {__version__}"


@pytest.mark.parametrize("verb", [["build-model"], ["simulate"], ["calibrate"], ["fit-scan"], ["fit-plate"],
                                  ["report"], ["export"], ["camera", "calibrate"], ["demo"]])
def test_every_verbs_help_states_its_defaults(verb, capsys):
    assert cli.main([*verb, "--help"]) == 0
    out = capsys.readouterr().out
    assert out.startswith("usage: invface") and ("(default:" in out or verb == ["report"]), out[:300]
    for entry in re.split(r"\n(?=  -)", out):               # one option's help, its wrapped lines included
        flat = " ".join(entry.split())
        assert "(default: None)" not in flat and "(default: False)" not in flat, flat
        assert flat.lower().count("default") <= 1, f"a default stated twice: {flat}"


def test_a_fully_transparent_plate_is_refused_before_fitting(tmp_path, capsys):
    import numpy as np

    from invface.io.images import write_image
    img = np.concatenate([np.full((60, 80, 3), 0.5, np.float32), np.zeros((60, 80, 1), np.float32)], -1)
    write_image(tmp_path / "clear.png", img)
    assert cli.main(["fit-plate", str(tmp_path / "clear.png"), "-o", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert "clear.png: its alpha channel is transparent everywhere" in err[-1], err
    assert not (tmp_path / "out").exists()
