"""The hybrid blendshape rig of paper 000, Eq. 1-2: x(b, j) = T(j) (n + B b).

T(j) is linear blend skinning between the rest frame (weight 0) and the 6-DOF jaw
transform (weight 1) with per-vertex jaw weights.
"""
from __future__ import annotations

import numpy as np


def euler_xyz(theta):
    """Rotation matrix (3,3) R = Rz(t2) Ry(t1) Rx(t0) for Euler angles theta (3,) in radians."""
    cx, cy, cz = np.cos(theta)
    sx, sy, sz = np.sin(theta)
    Rx = np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]])
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rz = np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]])
    return Rz @ Ry @ Rx


def jaw_transform(jaw, pivot, frame):
    """4x4 rigid transform of the jaw for parameters jaw (6,) about ``pivot`` (3,) m.

    ``frame`` (3,3) has the jaw's axes as columns (x: the hinge axis through the condyles).
    Rotation jaw[:3] is applied in the jaw frame, translation jaw[3:] is in the jaw frame.
    """
    R = frame @ euler_xyz(np.asarray(jaw[:3], float)) @ frame.T
    t = frame @ np.asarray(jaw[3:], float)
    M = np.eye(4)
    M[:3, :3] = R
    M[:3, 3] = pivot - R @ pivot + t
    return M


def skin(points, weights, M):
    """Linear blend skinning between identity and M (4,4): points (N,3), weights (N,) -> (N,3)."""
    moved = points @ M[:3, :3].T + M[:3, 3]
    return points + weights[:, None] * (moved - points)


def blendshape_surface(neutral, deltas, b, jaw, pivot, frame, jaw_weights):
    """Eq. 1: x = T(j)(n + B b). neutral (V,3), deltas (K,V,3), b (K,), jaw (6,) -> (V,3)."""
    pre = neutral + np.tensordot(b, deltas, axes=(0, 0)) if len(b) else neutral.copy()
    return skin(pre, jaw_weights, jaw_transform(jaw, pivot, frame))
