import subprocess
import sys

import numpy as np

from conftest import SMALL_RESOLUTION


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
