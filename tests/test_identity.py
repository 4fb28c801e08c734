"""The actor's identity from one plate's curves (fit.identity)."""
from dataclasses import replace

import numpy as np

from invface.fit.curves import curve_points, rms_px
from invface.fit.identity import fit_identity
from invface.model.pose import pose_points
from invface.model.controls import FitVector
from invface.morph.synthetic import random_identity
from invface.render.camera import Camera

ROT, TR = np.array([0.04, -0.12, 0.02]), np.array([0.005, -0.004, 0.01])


def _with_neutral(model, neutral):
    return replace(model, neutral=neutral, _surface_models={}, _embedding=None)


def _curves(model, cam, p):
    x = pose_points(model.surface_model("blendshape").surface(p), ROT, TR)
    return {k: cam.project(curve_points(model, k, x))[0] for k in model.curves}


def _gap(model, truth, cam, p):
    """RMS px between the model's and the truth's projected curve vertices at controls p."""
    a, b = _curves(model, cam, p), _curves(truth, cam, p)
    return rms_px({k: np.linalg.norm(a[k] - b[k], axis=1) for k in a})


def test_identity_from_one_frame_carries_to_other_expressions(small_expressive_model):
    """Curves of another face (the model's neutral under smooth random bumps, 3 mm) on one
    frame with known controls and pose: the fitted correction brings that frame's curves and
    those of other expressions (not seen by the fit) much nearer; on the model's own curves
    it moves nothing."""
    m = small_expressive_model
    cam = Camera.front_view(360, 270)
    vec = FitVector.of(m)
    names = list(m.blendshape_names)
    p = np.zeros(vec.P)
    p[names.index(names[0])] = 0.2
    truth = _with_neutral(m, random_identity(m.neutral, 5, amplitude=0.003, width=0.02, stretch=0.0))
    fit = fit_identity(m, cam, _curves(truth, cam, p), p, ROT, TR)
    assert fit.rms_after < 0.35 * fit.rms_before and fit.rms_before > 1.0
    adapted = _with_neutral(m, m.neutral + fit.displacement)
    other = np.zeros(vec.P)
    other[[names.index(n) for n in names[1:4]]] = 0.5          # another expression, not fitted
    before, after = _gap(m, truth, cam, other), _gap(adapted, truth, cam, other)
    assert after < 0.5 * before, (before, after)
    same = fit_identity(m, cam, _curves(m, cam, p), p, ROT, TR)
    assert same.max_mm < 0.01 and same.rms_after < 1e-3


def test_identity_finds_the_face_proportions(small_expressive_model):
    """A wider, shorter face (width x1.06, height x0.95, depth their geometric mean): the
    proportions recover both scales, and the field left after them stays small (by default,
    without the face-shape space, whose shapes would take a share of the width)."""
    m = small_expressive_model
    cam = Camera.front_view(360, 270)
    p = np.zeros(FitVector.of(m).P)
    s = np.array([1.06, 0.95, np.sqrt(1.06 * 0.95)])
    c = m.neutral[np.concatenate([m.curves[k] for k in m.curves])].mean(0)
    truth = _with_neutral(m, c + (m.neutral - c) * s)
    fit = fit_identity(m, cam, _curves(truth, cam, p), p, ROT, TR)
    assert np.abs(np.exp(fit.proportions[:2]) - s[:2]).max() < 0.01, fit.proportions
    assert fit.rms_after < 0.2 * fit.rms_before
    assert fit.max_mm < 1.0, fit.max_mm


def test_face_shape_space_jacobian_matches_finite_differences(small_expressive_model):
    """d r / d c of the curve residuals against the space's shapes (carried onto the small
    head by closest point) equals central differences of the residuals."""
    from invface.fit.curves import CurveObjective
    from invface.fit.identity import curve_data, space_jacobian
    from invface.morph.identity_space import identity_shapes
    m = small_expressive_model
    S = identity_shapes(m)
    assert S.shape == (20, len(m.neutral), 3) and np.abs(S).max() > 0.003
    cam = Camera.front_view(360, 270)
    p = np.zeros(FitVector.of(m).P)
    truth = _with_neutral(m, m.neutral + 1.5 * S[0] - S[3])
    sm = m.surface_model("blendshape")
    obj = CurveObjective(m, sm, cam, _curves(truth, cam, p), 0.0)
    data = curve_data(sm.surface(p), ROT, TR)
    c = np.array([0.3, -0.2] + [0.0] * 18)
    d0 = np.tensordot(c, S, axes=1)
    r, _, blocks = data(d0, (obj, 1.0))
    J = space_jacobian(blocks, S)
    h = 1e-4
    for k in (0, 3, 11):
        fd = (data(d0 + h * S[k], (obj, 1.0))[0] - data(d0 - h * S[k], (obj, 1.0))[0]) / (2 * h)
        assert np.allclose(J[:, k], fd, rtol=1e-3, atol=1e-4 * np.abs(fd).max()), k


def test_identity_in_the_space_recovers_a_known_face_in_3d(small_expressive_model):
    """A face of the space (coefficients 1.5 sd on four shapes, depth included), seen from the
    front: the fitted head is nearer the true face in 3D than the template, depth included,
    which the field alone cannot see."""
    from invface.morph.identity_space import identity_shapes
    m = small_expressive_model
    S = identity_shapes(m)
    cam = Camera.front_view(360, 270)
    p = np.zeros(FitVector.of(m).P)
    c = np.zeros(20)
    c[[0, 1, 3, 5]] = [1.5, -1.5, 1.5, -1.5]
    truth = _with_neutral(m, m.neutral + np.tensordot(c, S, axes=1))
    curves = _curves(truth, cam, p)
    err = lambda d: np.median(np.linalg.norm(m.neutral + d - truth.neutral, axis=1))     # noqa: E731
    with_space = fit_identity(m, cam, curves, p, ROT, TR, space=True)
    without = fit_identity(m, cam, curves, p, ROT, TR, space=False)
    assert err(with_space.displacement) < 0.5 * err(0.0), (err(with_space.displacement), err(0.0))
    assert err(with_space.displacement) < 0.8 * err(without.displacement)
    assert np.corrcoef(with_space.coefficients, c)[0, 1] > 0.7, with_space.coefficients.round(2)


def test_the_detectors_habits_are_taken_off_before_the_identity(small_expressive_model):
    """A detector that draws every curve 3 px low, on the model's own face: fitted as they
    are, the curves move the head (the identity takes the habit for a face); with the offsets
    the detector shows on a render of the model itself taken off, it stays where it is."""
    from invface.fit.identity import detector_bias
    m = small_expressive_model
    cam = Camera.front_view(360, 270)
    p = np.zeros(FitVector.of(m).P)
    habit = {k: v + [0.0, 3.0] for k, v in _curves(m, cam, p).items()}
    bias = detector_bias(m, cam, habit, p, ROT, TR, lambda image: habit)
    assert set(bias) == set(habit) and all(np.abs(b).max() > 1.0 for k, b in bias.items() if k == "nose_base")
    plain = fit_identity(m, cam, habit, p, ROT, TR, space=True)
    fixed = fit_identity(m, cam, habit, p, ROT, TR, space=True, bias=bias)
    moved = lambda f: np.linalg.norm(f.displacement, axis=1).max()       # noqa: E731
    assert moved(plain) > 0.001 and moved(fixed) < 0.1 * moved(plain), (moved(plain), moved(fixed))
    assert fixed.rms_after < 0.05


def test_several_views_pin_the_depth_that_one_frontal_view_leaves_to_the_prior(small_expressive_model):
    """A face of the space, seen from the front only and from three views turning 0.5 rad each
    way: the identity shared by the three views is nearer the true face in 3D than the one
    from the front alone, and one view through ``fit_identity_views`` is ``fit_identity``."""
    from invface.fit.identity import IdentityView, fit_identity_views
    from invface.morph.identity_space import identity_shapes
    m = small_expressive_model
    S = identity_shapes(m)
    cam = Camera.front_view(360, 270)
    p = np.zeros(FitVector.of(m).P)
    c = np.zeros(20)
    c[[0, 2, 4, 7]] = [1.5, -1.5, 1.5, 1.5]
    truth = _with_neutral(m, m.neutral + np.tensordot(c, S, axes=1))
    x = truth.surface_model("blendshape").surface(p)

    def view(yaw):
        rot = ROT + [0.0, yaw, 0.0]
        curves = {k: cam.project(curve_points(truth, k, pose_points(x, rot, TR)))[0] for k in truth.curves}
        return IdentityView(cam, curves, p, rot, TR)
    err = lambda f: np.median(np.linalg.norm(m.neutral + f.displacement - truth.neutral, axis=1))  # noqa: E731
    front = fit_identity_views(m, [view(0.0)], space=True)
    turning = fit_identity_views(m, [view(-0.5), view(0.0), view(0.5)], space=True)
    assert err(turning) < 0.8 * err(front), (err(turning), err(front))
    assert turning.rms_after < 0.5 * turning.rms_before
    single = fit_identity(m, cam, view(0.0).curves, p, ROT, TR, space=True)
    assert np.allclose(single.displacement, front.displacement)
