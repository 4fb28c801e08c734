"""The rigid head pose of every fit and render: x_R = R(theta) x(p) + t, for the fit vector
z = (p, theta, t) laid out by ``controls.FitVector``. It sits in the model layer, below the
Dr.Jit bridge and the fit, which both pose surfaces.

R(theta) = Rz Ry Rx (``model.rig.euler_xyz``); x(p) is a surface model's (the blendshape rig or
the driven simulation). Derivatives: the full Jacobian (for the dogleg's Gauss-Newton
matrices) and the vector-Jacobian product (one adjoint product: for gradient-only solvers).
"""
from __future__ import annotations

import numpy as np

from .rig import euler_xyz, euler_xyz_derivatives


def pose_points(x, rotation, translation):
    """R(rotation) x + translation for points x (n, 3) m."""
    return np.asarray(x, float) @ euler_xyz(np.asarray(rotation, float)).T + np.asarray(translation, float)


def unpose_points(xr, rotation, translation):
    """The inverse of ``pose_points``: R^T (xr - translation)."""
    return (np.asarray(xr, float) - np.asarray(translation, float)) @ euler_xyz(np.asarray(rotation, float))


def posed_surface(surface_model, z, vec):
    """(x (V,3), x_R (V,3)) m: the unposed and posed surface at z (vec.size,)."""
    p, rot, tr = vec.unpack(z)
    x = surface_model.surface(p)
    return x, pose_points(x, rot, tr)


def posed_parts(model, z, vec):
    """The inner parts' posed positions (P,3) m at z (jaw and head pose), or None."""
    p, rot, tr = vec.unpack(z)
    x = model.parts_positions(p)
    return None if x is None else pose_points(x, rot, tr)


def posed_jacobian(surface_model, z, vec):
    """(x_R (V,3), d x_R / dz (vec.size, V, 3)) at z."""
    p, th, _ = vec.unpack(z)
    x, xr = posed_surface(surface_model, z, vec)
    Jx = surface_model.surface_jacobian(p) @ euler_xyz(th).T            # (P, V, 3)
    Jth = np.einsum("kij,vj->kvi", euler_xyz_derivatives(th), x)        # (3, V, 3)
    Jt = np.broadcast_to(np.eye(3)[:, None, :], (3, len(x), 3))
    return xr, np.concatenate([Jx, Jth, Jt])


def posed_vjp(surface_model, z, vec, g_xr, x=None):
    """dL/dz (vec.size,) for dL/dx_R = g_xr (V,3): one adjoint product through the surface
    model (``surface_vjp``: for the simulation one back-substitution), not its Jacobian.
    x (V,3): the unposed surface at z when the caller has it."""
    p, th, _ = vec.unpack(z)
    g = np.asarray(g_xr, float)
    if x is None:
        x = surface_model.surface(p)
    gp = surface_model.surface_vjp(p, g @ euler_xyz(th))                # x_R = x R^T: dL/dx = g R
    gth = np.einsum("kij,vj,vi->k", euler_xyz_derivatives(th), x, g)
    return np.concatenate([gp, gth, g.sum(0)])
