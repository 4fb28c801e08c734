import numpy as np
import pytest

from invface.errors import ControlsError, InvfaceError
from invface.model.rig import euler_xyz, jaw_transform


def test_jaw_transform_identity_and_pivot():
    piv = np.array([0.0, 0.006, -0.004])
    assert np.allclose(jaw_transform(np.zeros(6), piv, np.eye(3)), np.eye(4))
    M = jaw_transform([0.3, 0.1, -0.2, 0, 0, 0], piv, np.eye(3))
    assert np.allclose(M[:3, :3] @ piv + M[:3, 3], piv)
    assert np.allclose(M[:3, :3] @ M[:3, :3].T, np.eye(3))
    assert np.isclose(np.linalg.det(euler_xyz([0.3, -0.2, 0.9])), 1.0)


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
