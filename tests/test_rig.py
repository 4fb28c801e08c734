import numpy as np
import pytest

from invface.errors import ControlsError, InvfaceError
from invface.model.rig import (euler_xyz, jaw_transform, jaw_transform_derivatives, skin,
                               skin_derivatives, skin_vjp)


def test_jaw_transform_identity_and_pivot():
    piv = np.array([0.0, 0.006, -0.004])
    assert np.allclose(jaw_transform(np.zeros(6), piv, np.eye(3)), np.eye(4))
    M = jaw_transform([0.3, 0.1, -0.2, 0, 0, 0], piv, np.eye(3))
    assert np.allclose(M[:3, :3] @ piv + M[:3, 3], piv)
    assert np.allclose(M[:3, :3] @ M[:3, :3].T, np.eye(3))
    assert np.isclose(np.linalg.det(euler_xyz([0.3, -0.2, 0.9])), 1.0)


def test_skinning_derivatives_match_finite_differences_and_their_vjp():
    """skin_derivatives (the tracks' tangent rows) against central differences of
    skin(points + sum_k b_k deltas_k, w, T(j)), and skin_vjp (the adjoint's contraction,
    without the (K+J, N, 3) array) against g . skin_derivatives."""
    rng = np.random.default_rng(3)
    pts, w, d = rng.standard_normal((40, 3)), rng.random(40), rng.standard_normal((3, 40, 3))
    piv, frame = rng.standard_normal(3), np.linalg.qr(rng.standard_normal((3, 3)))[0]
    b, j = rng.random(3), np.array([0.2, 0.05, -0.1, 0.003, -0.002, 0.001])
    x = lambda b, j: skin(pts + np.tensordot(b, d, axes=(0, 0)), w, jaw_transform(j, piv, frame))
    D = skin_derivatives(pts + np.tensordot(b, d, axes=(0, 0)), w, jaw_transform(j, piv, frame), d,
                         jaw_transform_derivatives(j, piv, frame))
    h = 1e-6
    for i in range(9):
        e = np.zeros(9)
        e[i] = h
        fd = (x(b + e[:3], j + e[3:]) - x(b - e[:3], j - e[3:])) / (2 * h)
        assert np.abs(D[i] - fd).max() <= 1e-8 * max(1.0, np.abs(fd).max()), i
    g = rng.standard_normal(pts.shape)
    v = skin_vjp(pts + np.tensordot(b, d, axes=(0, 0)), w, jaw_transform(j, piv, frame), d,
                 jaw_transform_derivatives(j, piv, frame), g)
    assert np.allclose(v, np.einsum("pni,ni->p", D, g), rtol=1e-12, atol=1e-12)


def test_positive_jaw_rotation_opens_the_mouth(small_model):
    m = small_model
    chin = m.landmarks["chin"]
    x = m.surface({"jaw": [0.25, 0, 0, 0, 0, 0]})
    assert x[chin, 1] < m.neutral[chin, 1] - 0.01
    top = m.landmarks["top_of_head"]
    assert np.allclose(x[top], m.neutral[top])
    assert np.allclose(m.surface(None), m.neutral)


def test_bad_controls_raise(small_model):
    with pytest.raises(ControlsError, match="unknown blendshape 'smile'"):
        small_model.surface({"smile": 1.0})
    with pytest.raises(ControlsError, match="jaw"):
        small_model.surface({"jaw": [np.nan, 0, 0, 0, 0, 0]})
    with pytest.raises(ControlsError, match="shape"):
        small_model.surface({"jaw": [0.1, 0.2]})
    with pytest.raises(InvfaceError, match="unknown surface kind"):
        small_model.surface(None, kind="nonsense")
