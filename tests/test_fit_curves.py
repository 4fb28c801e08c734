"""Plate curves and the curve fit of Eq. 15."""
import json

import numpy as np
import pytest

from invface.errors import InvfaceError
from invface.fit.curves import (PLATE_CURVES, closest_on_polyline, curve_points, fit_curves, projection_jacobian,
                                read_curves, resample, write_curves)
from invface.model.rig import euler_xyz
from invface.render.camera import Camera

ROT, TR = np.array([0.04, -0.12, 0.02]), np.array([0.005, -0.004, 0.01])


def test_closest_point_on_polyline():
    poly = np.array([[0.0, 0], [10, 0], [10, 10]])
    q = closest_on_polyline(np.array([[5.0, 3], [12, 5], [-2, -1], [11, 12]]), poly)
    np.testing.assert_allclose(q, [[5, 0], [10, 5], [0, 0], [10, 10]])
    r = resample(poly, 5)
    np.testing.assert_allclose(r, [[0, 0], [5, 0], [10, 0], [10, 5], [10, 10]])


def test_projection_jacobian_matches_camera_and_finite_differences():
    cam = Camera.front_view(720, 540)
    cam.K[0, 2] += 13.0
    cam.K[0, 1] = 2.5                                  # skew
    x = np.random.default_rng(0).normal(0, 0.05, (6, 3))
    uv, J = projection_jacobian(cam, x)
    np.testing.assert_allclose(uv, cam.project(x)[0], atol=1e-9)
    h = 1e-7
    for k in range(3):
        d = np.zeros(3)
        d[k] = h
        fd = (projection_jacobian(cam, x + d)[0] - projection_jacobian(cam, x - d)[0]) / (2 * h)
        np.testing.assert_allclose(J[:, :, k], fd, rtol=1e-5, atol=1e-3)


def test_curve_objective_jacobian_matches_finite_differences(small_expressive_model):
    from invface.fit.curves import CurveObjective
    m = small_expressive_model
    cam = Camera.front_view(720, 540)
    p = m.parameters({"mouthSmileLeft": 0.6, "jaw": [0.1, 0, 0, 0, 0, 0]})
    curves = _plate_curves(m, cam, PLATE_CURVES, p)
    obj = CurveObjective(m, m.surface_model("blendshape"), cam, curves, 3600.0)
    z = np.r_[np.full(len(p), 0.3), ROT + 0.01, TR]
    r, J = obj(z)
    for k in (0, 4, len(p) - 6, len(p), len(p) + 2, len(p) + 4):     # weights, jaw, pose
        e = np.zeros(len(z))
        e[k] = 1e-6
        fd = (obj(z + e)[0] - obj(z - e)[0]) / 2e-6
        assert np.linalg.norm(fd - J[:, k]) < 1e-3 * np.linalg.norm(fd) + 1e-6, k


def _plate_curves(model, cam, names, p, noise=0.3):
    x = model.surface_model("blendshape").surface(p) @ euler_xyz(ROT).T + TR
    rng = np.random.default_rng(0)
    return {n: resample(projection_jacobian(cam, curve_points(model, n, x))[0], 40) + rng.normal(0, noise, (40, 2))
            for n in names}


def test_snapped_curves_are_smoothed_and_slit_curves_kept():
    """A staircase (a curve snapped to grid vertices) is flattened with its ends held; the rows
    are affine weights (they commute with the pose); slit curves keep their vertices."""
    from invface.fit.curves import curve_weights
    n = 21
    stairs = np.c_[np.arange(n, dtype=float), 0.5 * (np.arange(n) % 2)]          # zig-zag of 0.5 px
    W = curve_weights("lip_outer_upper", n)
    assert np.allclose(W.sum(1), 1) and np.allclose(W[[0, -1]], np.eye(n)[[0, -1]])
    smooth = W @ stairs
    assert np.ptp(smooth[3:-3, 1]) < 0.02 and np.allclose(smooth[:, 0], stairs[:, 0])
    assert np.array_equal(curve_weights("lip_inner_upper", n), np.eye(n))


def test_curve_fit_matches_the_plate_curves(small_expressive_model):
    m = small_expressive_model
    cam = Camera.front_view(720, 540)
    p = m.parameters({"mouthSmileLeft": 0.6, "mouthSmileRight": 0.5, "jaw": [0.1, 0, 0, 0, 0, 0]})
    curves = _plate_curves(m, cam, PLATE_CURVES, p)
    start = fit_curves(m, cam, curves, rotation=ROT, translation=TR, solve_pose=False, max_iter=0)
    fit = fit_curves(m, cam, curves, rotation=ROT, translation=TR, solve_pose=False)
    # lambda_1 = 3600 and the L1 term (fit.priors.SPARSITY) keep the weights small, so the fit
    # stays above the 0.3 px noise (1.7 px with SPARSITY 0.1, 2.4 px with 0.4)
    assert start.rms_px > 5 and fit.rms_px < 2.6
    assert np.all(fit.p[:len(m.blendshape_names)] >= 0) and np.all(fit.p[:len(m.blendshape_names)] <= 1)


def test_pose_from_curves(small_expressive_model):
    m = small_expressive_model
    cam = Camera.front_view(720, 540)
    names = PLATE_CURVES + ("brow_L", "brow_R", "nose_base", "nose_bridge")
    curves = _plate_curves(m, cam, names, m.parameters({}))
    fit = fit_curves(m, cam, curves)
    assert np.abs(fit.rotation - ROT).max() < 0.03 and np.abs(fit.translation - TR).max() < 0.003
    assert fit.rms_px < 1.0


def test_pose_from_curves_of_a_smile(small_expressive_model):
    """The tracking pass explains the smile by the controls, not the pose (one pass with
    lambda_1 = 3600 left the smile's weights near 0.05 and the pitch 0.023 rad, the height
    2.2 mm off)."""
    m = small_expressive_model
    cam = Camera.front_view(720, 540)
    names = PLATE_CURVES + ("brow_L", "brow_R", "nose_base", "nose_bridge")
    p = m.parameters({"mouthSmileLeft": 0.7, "mouthSmileRight": 0.6, "jaw": [0.08, 0, 0, 0, 0, 0]})
    fit = fit_curves(m, cam, _plate_curves(m, cam, names, p))
    assert np.abs(fit.rotation - ROT).max() < 0.01 and np.abs(fit.translation - TR).max() < 1e-3
    smile = [m.blendshape_names.index(n) for n in ("mouthSmileLeft", "mouthSmileRight")]
    assert np.all(fit.tracked[smile] > 0.4) and np.all(fit.p[smile] < fit.tracked[smile])
    assert {h["pass"] for h in fit.history} == {"pose", "controls"}


def test_anchored_pose_pass_keeps_the_depth_of_the_calibration_pose(small_expressive_model):
    """Eyes and lips only (the sample plates' curves) on an open mouth fix the head's depth
    poorly: from a calibration pose at the plate's depth (rotation 0.02 rad off) the free pose
    pass ends 1.8 mm deep; anchored to the calibration's translation, within 0.5 mm. The
    anchor's rows act on the translation alone."""
    from invface.fit.curves import pose_anchor
    from invface.model.controls import FitVector
    m = small_expressive_model
    cam = Camera.front_view(720, 540)
    curves = _plate_curves(m, cam, PLATE_CURVES, m.parameters({"lipsPart": 0.5, "lowerLipDepress": 0.4}))
    err = {a: np.abs(fit_curves(m, cam, curves, rotation=ROT + 0.02, translation=TR, anchored=a).translation - TR).max()
           for a in (False, True)}
    assert err[True] < 0.5e-3 and err[True] < err[False] / 3, err
    vec = FitVector.of(m)
    c, w = pose_anchor(vec, np.zeros(vec.size), 3600.0)
    assert np.all(w[vec.translation] == 1000.0) and not w[: vec.P + 3].any()


def test_curve_file_errors(small_expressive_model, tmp_path):
    m = small_expressive_model
    write_curves(tmp_path / "ok.json", {"eye_L_upper": [[1, 2], [3, 4]]}, image_size=(720, 540))
    assert set(read_curves(tmp_path / "ok.json", m, image_size=(720, 540))) == {"eye_L_upper"}
    with pytest.raises(InvfaceError, match="drawn on a \\[720, 540\\] image"):
        read_curves(tmp_path / "ok.json", m, image_size=(360, 270))
    (tmp_path / "bad.json").write_text(json.dumps({"curves": {"lip_smile": [[1, 2], [3, 4]]}}))
    with pytest.raises(InvfaceError, match="bad.json: unknown curve name\\(s\\) \\['lip_smile'\\]"):
        read_curves(tmp_path / "bad.json", m)
    (tmp_path / "short.json").write_text(json.dumps({"curves": {"brow_L": [[1, 2]]}}))
    with pytest.raises(InvfaceError, match="'brow_L' needs at least 2"):
        read_curves(tmp_path / "short.json", m)


def test_face_mask_fills_the_detector_oval():
    from invface.fit.landmarks import CURVE_INDICES, FACE_OVAL, curves_from_landmarks, face_mask
    pts = np.zeros((478, 2))
    t = np.linspace(0, 2 * np.pi, len(FACE_OVAL), endpoint=False)
    pts[FACE_OVAL] = np.c_[50 + 30 * np.sin(t), 40 - 20 * np.cos(t)]   # an ellipse, from the top
    mask = face_mask(pts, 80, 100)
    assert mask.sum() == pytest.approx(np.pi * 30 * 20, rel=0.06)        # outline pixels included
    assert mask[40, 50] and not mask[5, 5] and not mask[40, 85]
    # the mouth opening (between the inner lip contours) is left out
    up, lo = CURVE_INDICES["lip_inner_upper"], CURVE_INDICES["lip_inner_lower"]
    u = np.linspace(-8, 8, len(up))
    pts[up], pts[lo] = np.c_[50 + u, 48 - 3 * np.cos(u / 8 * np.pi / 2)], np.c_[50 + u, 48 + 3 * np.cos(u / 8 * np.pi / 2)]
    holed = face_mask(pts, 80, 100)
    assert not holed[48, 50] and holed[40, 50] and face_mask(pts, 80, 100, holes=False)[48, 50]
    assert (mask & ~holed).sum() == pytest.approx(2 / 3 * 16 * 6, rel=0.35)    # the lens between them
    pts = np.arange(956, dtype=float).reshape(478, 2)
    c = curves_from_landmarks(pts)
    assert set(c) == set(CURVE_INDICES) | {"iris_L", "iris_R"} and {"nose_bridge", "nose_base", "jaw_line"} <= set(c)
    assert sorted((c["iris_L"][0, 0], c["iris_R"][0, 0])) == [pts[468, 0], pts[473, 0]]     # one iris each
    # the nostril base's middle point lies halfway from landmark 2 (columella) to 164 (philtrum)
    assert np.allclose(c["nose_base"][2], (pts[2] + pts[164]) / 2) and np.allclose(c["nose_base"][0], pts[240])


def test_astronaut_photo_pose_and_light(small_expressive_model):
    """The public-domain astronaut photo (scikit-image), another identity than the model:
    with the nose and jaw curves the pose of this near-frontal photo is found, and the
    light calibrated inside the detector's face oval is a plausible, near-white light."""
    pytest.importorskip("skimage")
    from invface.fit import landmarks
    if not landmarks.available():
        pytest.skip("landmark detector not installed")
    from skimage.data import astronaut

    from invface.fit.lambdas import face_scale
    from invface.pipeline import auto_calibrate, find_curves
    from invface.render.plates import Plate, srgb_to_linear
    img = srgb_to_linear(astronaut() / 255.0).astype(np.float32)
    m = small_expressive_model
    plate = Plate(image=img, camera=Camera.front_view(512, 512), path="astronaut.png")
    curves, source = find_curves(m, plate)
    assert source == "landmark detector" and 5000 < plate.mask.sum() < 15000
    scale = face_scale(curves)[0]
    result = auto_calibrate(m, plate, curves, source, max_iter=15)      # lambdas scaled by the face's size
    rot = result.pose.rotation
    assert result.pose.lam == pytest.approx(3600 * scale) and result.calibration.lam == pytest.approx(2500 * scale)
    # the face turned down as MediaPipe's own head pose has it (0.26 rad; eyes and lips alone
    # gave 0.58), and not turned aside
    assert abs(rot[0] - 0.26) < 0.1 and abs(rot[1]) < 0.1
    cal = result.calibration
    dc = cal.gamma[0]
    assert dc.min() > 0 and dc.max() / dc.min() < 1.4            # all-channel gauge: blue DC was 3.6x red
    assert np.mean(cal.albedo < 0) < 0.01                          # no black scalp (was 41 %)
    assert cal.history[-1]["rms"] < 0.09


def test_the_prior_measures_the_jaw_in_its_range(small_expressive_model):
    """Eq. 15's prior charges a jaw slide or twist at its bound what it charges a blendshape at
    weight 1 (ARKit's jawLeft/Right/Forward are those ratios), and the hinge in rad: 8 mm of
    slide was all but free in metres and real-photo fits slid the jaw to its bounds."""
    from invface.fit.priors import regulariser
    from invface.model.controls import FitVector
    from invface.model.rig import JAW_UPPER
    vec = FitVector.of(small_expressive_model)
    cost = {}
    for name, i, v in (("weight", 0, 1.0), ("hinge", vec.K, 0.3), ("forward", vec.K + 5, JAW_UPPER[5]),
                       ("yaw", vec.K + 1, JAW_UPPER[1])):
        z = np.zeros(vec.size)
        z[i] = v
        r, J = regulariser(z, vec, 3600.0)
        cost[name] = float(r @ r)
        assert np.allclose(J[:, vec.controls] @ z[vec.controls], r)
    assert cost["forward"] == pytest.approx(cost["weight"]) and cost["yaw"] == pytest.approx(cost["weight"])
    assert cost["hinge"] == pytest.approx(3600.0 * 0.09)
