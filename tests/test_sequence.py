"""Sequences (issue 28): video and folder input, resume after a kill, flags, curves files,
the temporal term, the detector's video mode and a 2-process Dask LocalCluster."""
import csv
import json
import subprocess
import sys
import time

import numpy as np
import pytest

from conftest import SHARED
from invface.errors import InvfaceError

N_FRAMES = 6


@pytest.fixture(scope="module")
def clip(small_expressive_model, tmp_path_factory):
    """A synthetic 6-frame clip (frames folder and MP4) of the small head, its model file and
    the true calibration."""
    from invface.fit.calibrate import Calibration
    from invface.fit.samples import write_sample_clip
    from invface.render.synthetic import skin_albedo, studio_light
    m = small_expressive_model
    root = tmp_path_factory.mktemp("clip")
    m.save(root / "small.npz")
    Calibration(gamma=studio_light(), albedo=skin_albedo(m)).save(root / "calib.npz")
    frames, video = write_sample_clip(m, root, n=N_FRAMES, size=(240, 180))
    return root, frames, video


def cli(root, *args):
    cmd = [sys.executable, "-m", "invface.cli", "fit-plate", *args, "--model", str(root / "small.npz"),
           "--calib", str(root / "calib.npz"), "--no-shading"]
    return cmd


def test_frame_selection_and_clip_sources(clip, tmp_path):
    from invface.pipeline.clips import open_clip, parse_frames
    assert parse_frames("2:8:2", 10) == [2, 4, 6] and parse_frames(":3", 10) == [0, 1, 2]
    assert parse_frames("-1", 10) == [9] and parse_frames(None, 3) == [0, 1, 2]
    for bad in ("a:b", "5:2", "1:2:0", "12", "1:2:3:4"):
        with pytest.raises(InvfaceError, match="--frames"):
            parse_frames(bad, 10)
    root, frames, video = clip
    v = open_clip(video, "1:5:2")
    assert v.kind == "video" and v.count == N_FRAMES and v.fps == 24 and v.indices == [1, 3]
    got = list(v.frames())
    assert [f.name for f in got] == ["clip.frame_000001", "clip.frame_000003"]
    assert got[1].time == pytest.approx(3 / 24) and got[0].plate.image.shape == (180, 240, 3)
    # the video's frames are the folder's frames through a lossy encoder
    f3 = next(open_clip(frames, "3").frames())
    assert f3.name == "frame_003" and np.abs(f3.plate.image - got[1].plate.image).mean() < 0.02
    assert got[0].digest != got[1].digest and next(v.frames(0, 1)).digest == got[0].digest
    (tmp_path / "broken.mp4").write_bytes(b"\x00" * 64)
    with pytest.raises(InvfaceError, match="broken.mp4: not a readable video"):
        open_clip(tmp_path / "broken.mp4")
    (tmp_path / "notes.txt").write_text("x")
    with pytest.raises(InvfaceError, match="notes.txt: not a plate image"):
        open_clip(tmp_path / "notes.txt")


def test_flags_and_curves_of_flagged_frames_come_from_their_neighbours():
    from invface.pipeline.frames import flag_reason
    from invface.pipeline.outputs import curve_rows, jitter
    assert flag_reason(2.0, 0.01, [1.0, 1.2, 0.9]) == ""
    assert "curve RMS 12.0 px" in flag_reason(12.0, 0.01, [1.0, 1.2, 0.9])
    assert flag_reason(3.5, 0.01, [1.0, 1.0]) == ""                 # 3.5x but only 2.5 px more
    assert "lip volume change +38.0 %" in flag_reason(1.0, 0.38, [])
    recs = [{"_name": f"f{i}", "frame": i, "time": i / 24, "weights": {"smile": w}, "jaw": [0] * 6,
             "rotation": [0, 0, 0], "translation": [0, 0, 0], "flagged": "x" if i == 2 else ""}
            for i, w in enumerate([0.0, 0.2, 0.9, 0.6, 0.8])]
    rows = curve_rows(recs)
    assert rows[2]["weight_smile"] == pytest.approx(0.4) and rows[2]["flagged"] == "x"
    assert rows[3]["weight_smile"] == 0.6
    smooth = curve_rows([dict(r, weights={"smile": 0.1 * i}, flagged="") for i, r in enumerate(recs)])
    raw = curve_rows([dict(r, flagged="") for r in recs])
    assert jitter(smooth) < 1e-9 and jitter(rows) < 1e-9 and jitter(raw) > 1.0   # the flagged spike removed


def test_video_fit_is_killed_and_resumed_and_writes_curves_and_overlay(clip, tmp_path):
    """A run killed after two frames leaves them finished; the same command fits only the
    others; other inputs are refused; the curves file has every frame with the fit's
    controls; the overlay video has a frame per fitted frame."""
    root, _, video = clip
    out = tmp_path / "out"
    proc = subprocess.Popen(cli(root, str(video), "-o", str(out)), stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    t0 = time.time()
    while len(list(out.glob("*/blendshape/fit.json"))) < 2 and proc.poll() is None and time.time() - t0 < 300:
        time.sleep(0.2)
    proc.kill()
    log = proc.communicate()[0]
    done = sorted(f.parent.parent.name for f in out.glob("*/blendshape/fit.json"))
    assert 2 <= len(done) < N_FRAMES, log
    assert not json.loads((out / "run.json").read_text())["finished"]
    stamps = {n: (out / n / "blendshape/fit.json").stat().st_mtime_ns for n in done}
    r = subprocess.run(cli(root, str(video), "-o", str(out)), capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert f"{len(done)} frame(s) finished before from the same inputs were skipped" in r.stdout
    assert all((out / n / "blendshape/fit.json").stat().st_mtime_ns == t for n, t in stamps.items())
    assert len(list(out.glob("*/blendshape/fit.json"))) == N_FRAMES
    assert "resuming the run there" in r.stdout and "jitter" in r.stdout
    # the actor's identity was fitted once, on the picked frame, and reused by the resumed run
    assert (out / "actor.npz").is_file() and "reusing" in r.stdout and "identity" in r.stdout
    # a frame's page: the quick pictures; `invface report` on the frame adds the heat map
    frame = out / "clip.frame_000003"
    assert (frame / "blendshape/curves.png").is_file() and not (frame / "blendshape/mesh_error.png").exists()
    rep = subprocess.run([sys.executable, "-m", "invface.cli", "report", str(frame)], capture_output=True, text=True)
    assert rep.returncode == 0 and (frame / "blendshape/mesh_error.png").is_file(), rep.stderr
    # other inputs: refused, then --restart starts over
    r = subprocess.run(cli(root, str(video), "-o", str(out), "--temporal", "0"), capture_output=True, text=True)
    assert r.returncode == 2 and "made from other inputs" in r.stderr and "--restart" in r.stderr
    with open(out / "curves.csv") as f:
        table = list(csv.DictReader(f))
    assert [int(t["frame"]) for t in table] == list(range(N_FRAMES)) and {t["kind"] for t in table} == {"blendshape"}
    fit3 = json.loads((out / "clip.frame_000003/blendshape/fit.json").read_text())
    assert float(table[3]["weight_mouthSmileLeft"]) == pytest.approx(fit3["weights"]["mouthSmileLeft"])
    assert float(table[3]["time"]) == pytest.approx(3 / 24)
    # each frame against its truth (clip.frame_NNNNNN.truth.json beside the video): curves only
    assert fit3["truth"]["shape_median_mm"] < 0.5 and fit3["curve_rms_px"] < 1.0
    curves = json.loads((out / "curves.json").read_text())["blendshape"]
    assert len(curves["rows"]) == N_FRAMES and "weight_mouthSmileLeft" in curves["columns"]
    import cv2
    cap = cv2.VideoCapture(str(out / "overlay_blendshape.mp4"))
    assert int(cap.get(cv2.CAP_PROP_FRAME_COUNT)) == N_FRAMES and cap.get(cv2.CAP_PROP_FRAME_WIDTH) > 3 * 300
    page = (out / "index.html").read_text()
    assert 'href="curves.csv"' in page and 'href="overlay_blendshape.mp4"' in page


def test_temporal_term_lowers_jitter_without_losing_the_curves(small_expressive_model, clip):
    from invface.fit.calibrate import Calibration
    from invface.pipeline import fit_sequence
    from invface.pipeline.outputs import curve_rows, jitter
    root, frames, _ = clip
    cal = Calibration.load(root / "calib.npz")
    res = {}
    for t in (0.0, 1.0):
        rows = fit_sequence(small_expressive_model, frames, cal, shading=False, temporal=t)
        recs = [{"_name": r["name"], "frame": r["index"], "time": r["time"],
                 **r["fit"]["blendshape"].summary()} for r in rows]
        res[t] = (jitter(curve_rows(recs)), max(r["kinds"]["blendshape"]["curve_rms_px"] for r in rows))
    assert res[1.0][0] < 0.8 * res[0.0][0], res
    assert res[1.0][1] < res[0.0][1] + 0.3, res


def test_a_frame_starts_where_the_two_before_it_point():
    """Constant velocity per frame from the last two unflagged frames, clamped to the box; no
    prediction from frames out of order or across a long gap."""
    from invface.model.controls import FitVector
    from invface.pipeline.frames import PREDICT_GAP, predict
    vec = FitVector(["a", "b"])
    z0, z1 = vec.pack(weights=[0.2, 0.9], rotation=[0.0, 0.1, 0.0]), vec.pack(weights=[0.3, 0.95],
                                                                               rotation=[0.0, 0.2, 0.0])
    z = predict(vec, (4, z0), (6, z1), 8)
    assert np.allclose(z[vec.weights], [0.4, 1.0]) and np.allclose(z[vec.rotation], [0.0, 0.3, 0.0])
    assert np.allclose(predict(vec, (4, z0), (6, z1), 7)[vec.rotation], [0.0, 0.25, 0.0])
    assert predict(vec, (6, z1), (4, z0), 8) is None and predict(vec, (4, z0), (6, z1), 6) is None
    assert predict(vec, (4, z0), (6, z1), 6 + 2 * PREDICT_GAP + 1) is None


def test_each_frame_after_two_starts_from_their_prediction(small_expressive_model, clip, monkeypatch):
    """In a sequence, the third frame on starts from the prediction of the two before it (its
    temporal term still pulls towards the last one)."""
    import invface.fit.plate as fp
    from invface.fit.calibrate import Calibration
    from invface.model.controls import FitVector
    from invface.pipeline import fit_sequence
    root, frames, _ = clip
    calls, fit_plate = [], fp.fit_plate
    monkeypatch.setattr(fp, "fit_plate", lambda *a, **k: calls.append(k) or fit_plate(*a, **k))
    rows = fit_sequence(small_expressive_model, frames, Calibration.load(root / "calib.npz"), select="0:4",
                        shading=False)
    vec = FitVector.of(small_expressive_model)
    fits = [r["fit"]["blendshape"] for r in rows]
    z = [vec.pack(f.p, f.rotation, f.translation) for f in fits]
    assert calls[0]["guess"] is None and calls[1]["guess"] is None and calls[1]["start"] is fits[0]
    lo, hi = vec.bounds()
    for i in (2, 3):
        assert calls[i]["start"] is fits[i - 1]
        assert np.allclose(calls[i]["guess"], np.clip(2 * z[i - 1] - z[i - 2], lo, hi))


def test_two_process_local_cluster_matches_the_single_process_run(small_expressive_model, clip, tmp_path):
    """--workers 2 (a distributed.LocalCluster) fits the same frames: the chunks' first
    frames are refitted from the chunk before, and the answers agree with one process."""
    pytest.importorskip("distributed")
    from invface.fit.calibrate import Calibration
    from invface.pipeline.clips import open_clip
    from invface.pipeline.distributed import chunk_bounds, fit_sequence_distributed
    from invface.pipeline.frames import fit_frames
    from invface.pipeline.outputs import sequence_records
    from invface.pipeline.runs import run_hash
    assert chunk_bounds(7, 3) == [(0, 2), (2, 5), (5, 7)] and chunk_bounds(2, 5) == [(0, 1), (1, 2)]
    import pickle
    root, frames, _ = clip
    m, cal = small_expressive_model, Calibration.load(root / "calib.npz")
    # the model travels to the workers pickled, also after its simulation was used (the
    # solver's native handles stay behind; the copy rebuilds its surface models)
    p = m.parameters({"mouthSmileLeft": 0.3})
    # (both solve from rest to the same tolerance -- the session model's warm start and
    # first-order prediction would land elsewhere within it; PARDISO's threaded reductions
    # leave them 1-2e-9 m apart in some test orders)
    sim = m.surface_model("simulation")
    x = sim.surface_of(sim.solve(p, warm=None))
    assert np.abs(pickle.loads(pickle.dumps(m)).surface_model("simulation").surface(p) - x).max() < 1e-8
    opts = dict(shading=False, temporal=1.0)
    inputs = run_hash(m, cal, opts)
    c = open_clip(frames, "0:4")
    rows = fit_sequence_distributed(m, c, cal, tmp_path / "two", inputs=inputs, workers=2, **opts)
    assert [r["name"] for r in rows] == c.names
    recs = sequence_records(tmp_path / "two", ["blendshape"])["blendshape"]
    assert [r["_name"] for r in recs] == c.names and recs[2].get("second_pass") and not recs[1].get("second_pass")
    fit_frames(m, c, cal, tmp_path / "one", inputs=inputs, **opts)
    ones = sequence_records(tmp_path / "one", ["blendshape"])["blendshape"]
    for a, b in zip(recs, ones):
        wa, wb = np.array(list(a["weights"].values())), np.array(list(b["weights"].values()))
        assert np.abs(wa - wb).max() < 0.05 and abs(a["curve_rms_px"] - b["curve_rms_px"]) < 0.1


@pytest.mark.skipif(not (SHARED / "data/real/video/single_face.mp4").is_file(), reason="real clip not available")
def test_detector_tracks_the_real_clip_in_video_mode():
    """The detector's video mode on the real phone clip: landmarks on every frame of a
    stretch, a steady track (frame-to-frame motion of the eye corners within a few px), and a
    time that goes back starts a new track instead of failing."""
    from invface.fit.landmarks import LandmarkTracker, available
    from invface.pipeline.clips import open_clip
    from invface.render.plates import linear_to_srgb
    if not available():
        pytest.skip("landmark detector not installed")
    c = open_clip(SHARED / "data/real/video/single_face.mp4", "0:12")
    with LandmarkTracker() as track:
        pts = [track(linear_to_srgb(f.plate.image), f.time, f.name) for f in c.frames()]
        again = track(linear_to_srgb(next(c.frames(0, 1)).plate.image), 0.0)
    pts = np.array(pts)
    assert pts.shape == (12, 478, 2) and np.abs(again - pts[0]).max() < 1.0
    step = np.linalg.norm(np.diff(pts[:, [33, 263]], axis=0), axis=2)
    assert step.max() < 8.0, step.max()


def test_the_calibration_frame_is_the_most_neutral_of_the_whole_shot(small_expressive_model, clip):
    """pick_neutral can look over the whole shot (fit-plate --neutral-from shot), not only the
    frames asked for: on the sample clip
    (a smile and the jaw rising and falling over the 6 frames) it picks the first, neutral
    frame, though the frames asked for are the last three, and says why; a frame whose eyes the
    detector scores as shut costs EYES_SHUT_COST more."""
    from invface.fit.samples import clip_controls
    from invface.pipeline.clips import open_clip
    from invface.pipeline.neutral import EYES_SHUT_COST, neutral_score, pick_neutral
    m = small_expressive_model
    _, frames, _ = clip
    asked = open_clip(frames, "3:6")
    assert 0 not in asked.indices
    chosen, why, seen = pick_neutral(m, open_clip(frames), candidates=6, over="the whole shot")
    frame, pose = chosen.frame, chosen.pose
    assert [c.frame.index for c in seen] == list(range(6)) and any(c is chosen for c in seen)
    truth = [sum(w.values()) + 10 * jaw[0] for w, jaw, _, _ in clip_controls(m, N_FRAMES)]
    assert frame.index == int(np.argmin(truth)) == 0
    assert why.startswith("the most neutral-looking of 6 frames spread over the whole shot (expression")
    open_eyes, _ = neutral_score(pose, {"eyeBlinkLeft": 0.0, "eyeBlinkRight": 0.0})
    shut, parts = neutral_score(pose, {"eyeBlinkLeft": 1.0, "eyeBlinkRight": 1.0})
    assert shut - open_eyes == pytest.approx(EYES_SHUT_COST) and set(parts) == {"weights", "jaw", "eyes shut"}


def test_an_identity_in_the_space_is_shared_by_the_frames_that_show_another_side(small_expressive_model, clip,
                                                                                tmp_path):
    """With the face-shape space, a clip's identity is fitted on the calibration frame and the
    frames looked at to choose it that show the head from another side (``distinct_views``):
    run.json names them, the sentence says how many, and a resumed run with the same frames
    reuses actor.npz, while one with the same calibration frame alone fits the identity again."""
    from dataclasses import replace
    from types import SimpleNamespace

    from invface.io.jsonfile import write_object
    from invface.pipeline.clips import open_clip
    from invface.pipeline.neutral import Candidate, distinct_views
    from invface.pipeline.runs import read_run
    from invface.pipeline.session import prepare_run, shot_frame
    at = lambda yaw: Candidate(None, {}, "", SimpleNamespace(rotation=(0.0, yaw, 0.0)))     # noqa: E731
    turns = [at(y) for y in (0.05, 0.12, 0.2, 0.3, -0.09)]
    assert distinct_views(at(0.0), turns) == [turns[1], turns[3]]
    m = small_expressive_model
    _, frames, _ = clip
    shot = shot_frame(m, open_clip(frames))
    assert len(shot.others) == N_FRAMES - 1 and all(c.frame is not shot.frame for c in shot.others)
    shared = distinct_views(Candidate(shot.frame, shot.curves, shot.source, shot.pose), shot.others)
    assert 1 <= len(shared) < N_FRAMES - 1
    _, _, rec = prepare_run(m, shot, tmp_path, calibration=object(), identity_space=True)
    assert rec["identity_frames"] == [c.frame.digest for c in shared]
    assert f"and {len(shared)} other frame(s)" in rec["identity"]
    write_object(tmp_path / "run.json", rec)
    assert read_run(tmp_path)["identity_frames"] == rec["identity_frames"]
    said = []
    prepare_run(m, shot, tmp_path, calibration=object(), identity_space=True,
                progress=lambda e: said.append(e.get("message", "")))
    assert any(t.startswith("reusing") and "identity" in t for t in said), said
    said.clear()
    _, _, alone = prepare_run(m, replace(shot, others=()), tmp_path, calibration=object(), identity_space=True,
                              progress=lambda e: said.append(e.get("message", "")))
    assert not any(t.startswith("reusing") for t in said) and "other frame" not in alone["identity"]
    assert "identity_frames" not in alone
