"""The Live Link Face CSV (io.livelink): read back by a reader that knows only a recording's
header line (tests/fixtures/livelink_face_recording.csv: the 61 value names in a recording's
order, the Timecode HH:MM:SS:FF.mmm, BlendShapeCount 61), matching columns by name."""
import csv
import re
from pathlib import Path

import numpy as np
import pytest

from invface.io.exporters import export
from invface.io.livelink import read_livelink_csv, timecode, write_livelink_csv
from invface.model.arkit import ARKIT_NAMES

FIXTURE = Path(__file__).parent / "fixtures" / "livelink_face_recording.csv"


def recording_reader(path):
    """A reader written from the recording's header alone: {column: [values]} by name."""
    header = FIXTURE.read_text().splitlines()[0].split(",")
    with open(path, newline="") as fh:
        rows = list(csv.DictReader(fh))
    assert list(rows[0]) == header, "the columns, in the recording's order"
    return {c: [r[c] for r in rows] for c in header}


def test_the_fixture_is_a_recording_header():
    header = FIXTURE.read_text().splitlines()[0].split(",")
    assert header[:2] == ["Timecode", "BlendShapeCount"] and len(header) == 63
    rec = read_livelink_csv(FIXTURE)[0]
    assert rec["BlendShapeCount"] == 61 and rec["MouthSmileLeft"] == 0.42 and rec["HeadYaw"] == -0.05


def test_written_csv_reads_back_by_name(tmp_path):
    rng = np.random.default_rng(0)
    frames = [{"frame": f, "arkit": dict(zip(ARKIT_NAMES, rng.uniform(0, 1, 52).round(6))),
               "rotation": rng.normal(0, 0.1, 3)} for f in (0, 1, 37)]
    path = write_livelink_csv(tmp_path / "arkit_blendshape.csv", frames, ARKIT_NAMES, fps=24)
    got = recording_reader(path)
    assert got["Timecode"] == ["00:00:00:00.000", "00:00:00:01.000", "00:00:01:13.000"]
    assert all(re.fullmatch(r"\d\d:\d\d:\d\d:\d\d\.\d{3}", t) for t in got["Timecode"])
    assert got["BlendShapeCount"] == ["61"] * 3
    for i, f in enumerate(frames):
        for name, v in f["arkit"].items():
            col = name[0].upper() + name[1:]
            assert float(got[col][i]) == pytest.approx(v, abs=1e-6)
        yaw, pitch, roll = (float(got[c][i]) for c in ("HeadYaw", "HeadPitch", "HeadRoll"))
        assert (yaw, pitch, roll) == pytest.approx((f["rotation"][1], f["rotation"][0], f["rotation"][2]), abs=1e-6)
        assert float(got["LeftEyeYaw"][i]) == 0.0
    # through the exporter table's named format, the same bytes
    again = export(tmp_path / "b.csv", {"frames": frames, "arkit_names": ARKIT_NAMES, "fps": 24}, format="livelink")
    assert again.read_text() == path.read_text()


def test_timecodes():
    assert timecode(0, 24) == "00:00:00:00.000"
    assert timecode(24 * 3600 + 24 * 61 + 5, 24) == "01:01:01:05.000"
    assert timecode(2.5, 30) == "00:00:00:02.500"
    with pytest.raises(Exception, match="frame rate"):
        timecode(1, 0)


def test_export_of_an_existing_run(tmp_path):
    """``invface.export(run_dir)`` (and ``invface export DIR``) writes a run's Live Link CSV from
    its fit.json files: a photo's (<kind>/fit.json) and a sequence's (run.json's frames)."""
    import json

    import invface
    from invface.errors import InvfaceError
    arkit = dict.fromkeys(ARKIT_NAMES, 0.0)
    photo = tmp_path / "photo"
    (photo / "blendshape").mkdir(parents=True)
    (photo / "blendshape" / "fit.json").write_text(json.dumps({"arkit": dict(arkit, jawOpen=0.5), "rotation": [0, 0.1, 0]}))
    paths = invface.export(photo)
    assert [p.name for p in paths] == ["arkit_blendshape.csv"]
    rows = read_livelink_csv(paths[0])
    assert len(rows) == 1 and rows[0]["JawOpen"] == 0.5 and rows[0]["HeadYaw"] == pytest.approx(0.1)
    clip = tmp_path / "clip"
    (clip / "run.json").parent.mkdir()
    (clip / "run.json").write_text(json.dumps({"frames": ["f0", "f1"], "fps": 30.0}))
    for i in range(2):
        (clip / f"f{i}" / "simulation").mkdir(parents=True)
        (clip / f"f{i}" / "simulation" / "fit.json").write_text(json.dumps({"frame": 30 + i, "arkit": arkit}))
    rows = read_livelink_csv(invface.export(clip)[0])
    assert [r["Timecode"] for r in rows] == ["00:00:01:00.000", "00:00:01:01.000"]          # 30 fps
    with pytest.raises(InvfaceError, match="holds no fit"):
        invface.export(tmp_path)
    with pytest.raises(InvfaceError, match="export format 'fbx': use csv, usd"):
        invface.export(photo, formats="fbx")
