"""The hybrid blendshape rig of paper 000, Eq. 1-2: x(b, j) = T(j) (n + B b).

T(j) is linear blend skinning between the rest frame (weight 0) and the 6-DOF jaw
transform (weight 1) with per-vertex jaw weights.
"""
from __future__ import annotations

import numpy as np


def _axis_rotations(theta):
    """Rx(t0), Ry(t1), Rz(t2) and their derivatives in their own angle."""
    cx, cy, cz = np.cos(theta)
    sx, sy, sz = np.sin(theta)
    R = (np.array([[1, 0, 0], [0, cx, -sx], [0, sx, cx]]),
         np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]]),
         np.array([[cz, -sz, 0], [sz, cz, 0], [0, 0, 1]]))
    dR = (np.array([[0, 0, 0], [0, -sx, -cx], [0, cx, -sx]]),
          np.array([[-sy, 0, cy], [0, 0, 0], [-cy, 0, -sy]]),
          np.array([[-sz, -cz, 0], [cz, -sz, 0], [0, 0, 0]]))
    return R, dR


def euler_xyz(theta):
    """Rotation matrix (3,3) R = Rz(t2) Ry(t1) Rx(t0) for Euler angles theta (3,) in radians."""
    (Rx, Ry, Rz), _ = _axis_rotations(theta)
    return Rz @ Ry @ Rx


def euler_xyz_derivatives(theta):
    """dR/dtheta_i (3,3,3) of ``euler_xyz`` (index 0: the angle)."""
    (Rx, Ry, Rz), (dRx, dRy, dRz) = _axis_rotations(theta)
    return np.array([Rz @ Ry @ dRx, Rz @ dRy @ Rx, dRz @ Ry @ Rx])


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


def jaw_transform_derivatives(jaw, pivot, frame):
    """d(jaw_transform)/d(jaw_i) (6,4,4) for jaw parameters jaw (6,)."""
    D = np.zeros((6, 4, 4))
    for i, dE in enumerate(euler_xyz_derivatives(np.asarray(jaw[:3], float))):
        dR = frame @ dE @ frame.T
        D[i, :3, :3] = dR
        D[i, :3, 3] = -dR @ pivot
    D[3:, :3, 3] = frame.T            # translation i moves along the frame's axis i
    return D


def skin(points, weights, M):
    """Linear blend skinning between identity and M (4,4): points (N,3), weights (N,) -> (N,3)."""
    moved = points @ M[:3, :3].T + M[:3, 3]
    return points + weights[:, None] * (moved - points)


def skin_derivatives(points, weights, M, deltas, dM):
    """Derivatives of skin(points + sum_k b_k deltas_k, weights, M) at b's current points.

    points (N,3) pre-skinning positions, deltas (K,N,3), dM (J,4,4) transform derivatives.
    Returns (K+J, N, 3): d/db_k = (1-w) d_k + w R d_k; d/dj = w (dR p + dt).
    """
    K, w = len(deltas), weights[:, None]
    out = np.empty((K + len(dM),) + np.shape(points))
    # (1-w) d + w R d = d + w (R - I) d, as one (K N, 3) x (3, 3) product
    db = out[:K]
    np.matmul(deltas.reshape(-1, 3), M[:3, :3].T - np.eye(3), out=db.reshape(-1, 3))
    db *= w
    db += deltas
    J = len(dM)                               # dR p for all J at once: (N, 3) x (3, 3 J)
    dj = (points @ dM[:, :3, :3].transpose(2, 0, 1).reshape(3, 3 * J)).reshape(-1, J, 3).transpose(1, 0, 2)
    out[K:] = w * (dj + dM[:, None, :3, 3])
    return out


def skin_vjp(points, weights, M, deltas, dM, g):
    """sum over points of g . skin_derivatives(points, weights, M, deltas, dM) (K+J,) for g
    (N,3), without forming the derivatives: (1-w) d + w R d = d + w (R - I) d, so the
    blendshape part is deltas against g + w g (R - I)."""
    w = weights[:, None]
    gb = g + w * (g @ (M[:3, :3] - np.eye(3)))
    wg = w * g
    dj = np.einsum("jab,na,nb->j", dM[:, :3, :3], wg, points) + dM[:, :3, 3] @ wg.sum(0)
    return np.concatenate([deltas.reshape(len(deltas), -1) @ gb.reshape(-1), dj])


def blendshape_surface(neutral, deltas, b, jaw, pivot, frame, jaw_weights):
    """Eq. 1: x = T(j)(n + B b). neutral (V,3), deltas (K,V,3), b (K,), jaw (6,) -> (V,3)."""
    return skin(pre_skinning(neutral, deltas, b), jaw_weights, jaw_transform(jaw, pivot, frame))


def pre_skinning(neutral, deltas, b):
    """n + B b (V,3)."""
    return neutral + np.tensordot(b, deltas, axes=(0, 0)) if len(b) else neutral.copy()


JAW_NAMES = ["jaw_rx", "jaw_ry", "jaw_rz", "jaw_tx", "jaw_ty", "jaw_tz"]
# the jaw's anatomical range (fits and the builder's jaw split keep to it), in the jaw frame
# about the pivot, from the rest pose in occlusion: opening 0..0.6 rad about the hinge (-0.02
# rad of slack for a neutral not quite in occlusion), +-0.15 rad sideways and twist, +-8 mm
# sideways and forward/back, and down to 8 mm but not up. Closing past occlusion or lifting
# the jaw drives the lower teeth into the upper ones: no real jaw goes there, and the flesh
# between the two bones has no equilibrium there (bench/robustness.py).
JAW_LOWER = np.array([-0.02, -0.15, -0.15, -0.008, -0.008, -0.008])   # rad, rad, rad, m, m, m
JAW_UPPER = np.array([0.6, 0.15, 0.15, 0.008, 0.0, 0.008])


def split_parameters(p, names, n_blendshapes):
    """(b (K,), jaw (6,)) from a parameter vector p (K+6,) laid out as ``names``; validated."""
    from ..errors import ControlsError

    p = np.asarray(p, float).reshape(-1)
    if p.shape != (len(names),):
        raise ControlsError(f"expected {len(names)} parameters ({n_blendshapes} blendshape weights "
                            f"+ 6 jaw), got {p.size}")
    if not np.all(np.isfinite(p)):
        bad = [n for n, v in zip(names, p) if not np.isfinite(v)]
        raise ControlsError(f"non-finite control values: {', '.join(bad)}")
    return p[:n_blendshapes], p[n_blendshapes:]


class BlendshapeRig:
    """The blendshape model x(p) (Eq. 1-2) behind the surface-model interface shared with the
    driven simulation: parameter_names, surface(p), surface_jacobian(p), surface_vjp(p, gx),
    with p = (b (K,), jaw (6,)) and surfaces (V,3) m."""

    def __init__(self, model):
        self.model = model
        self.parameter_names = list(model.blendshape_names) + JAW_NAMES
        self.n_blendshapes = len(model.blendshape_names)

    def split(self, p):
        return split_parameters(p, self.parameter_names, self.n_blendshapes)

    def surface(self, p):
        m = self.model
        b, jaw = self.split(p)
        return blendshape_surface(m.neutral, m.blendshapes, b, jaw, m.jaw_pivot, m.jaw_frame, m.jaw_weights)

    def surface_jacobian(self, p):
        """dx/dp (P, V, 3), analytic."""
        m = self.model
        b, jaw = self.split(p)
        return skin_derivatives(pre_skinning(m.neutral, m.blendshapes, b), m.jaw_weights, m.jaw_matrix(jaw),
                                m.blendshapes, jaw_transform_derivatives(jaw, m.jaw_pivot, m.jaw_frame))

    def surface_vjp(self, p, gx):
        """dLoss/dp (P,) for dLoss/dx = gx (V,3)."""
        m = self.model
        b, jaw = self.split(p)
        M = m.jaw_matrix(jaw)
        gx = np.asarray(gx, float)
        w = m.jaw_weights[:, None]
        # d/db_k: sum_v gx_v . ((1-w) d + w R d) = sum_v ((1-w) gx + w R^T gx) . d
        gpre = (1 - w) * gx + w * (gx @ M[:3, :3])
        gb = np.einsum("kvi,vi->k", m.blendshapes, gpre)
        pre = pre_skinning(m.neutral, m.blendshapes, b)
        dM = jaw_transform_derivatives(jaw, m.jaw_pivot, m.jaw_frame)
        gj = np.einsum("jab,vb,va->j", dM[:, :3, :3], w * pre, gx) + dM[:, :3, 3] @ (w * gx).sum(0)
        return np.concatenate([gb, gj])
