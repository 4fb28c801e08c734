"""Curvature on a fixed-size stencil (paper 001 sec. 6, Fig. 4-5).

At each vertex, 8 points on a circle of fixed radius (5 mm) in the tangent plane are folded
onto the mesh (here: projected to their closest surface point, which for a 5 mm stencil on a
face stays on the same sheet) and the curvature tensor is estimated from the 8 directional
curvatures after Taubin (1995): kappa_k = 2 n.(p_k - v) / |p_k - v|^2 along the tangent
direction T_k, M = mean_k kappa_k T_k T_k^T, and the principal curvatures are
kappa_1 = 3 m_1 - m_2, kappa_2 = 3 m_2 - m_1 for the eigenvalues m_1, m_2 of M. Because the
stencil has a fixed size in metres, the estimate measures features (eye corners, alar
grooves, lip corners) rather than mesh noise, and does not depend on the mesh resolution.
"""
from __future__ import annotations

import numpy as np

from ..mesh.closest import barycentric_points, closest_points
from ..mesh.triangles import vertex_normals

STENCIL_RADIUS = 0.005   # m (the paper's 0.005 units, its models being in metres)
STENCIL_POINTS = 8


def stencil_curvature(V, F, ids=None, radius=STENCIL_RADIUS, n_points=STENCIL_POINTS):
    """Principal curvatures (P,2) (1/m, sorted, convex positive) at vertices ``ids`` (default
    all) of the mesh (V (n,3) m, F (f,3)) from the fixed-size stencil."""
    V, F = np.asarray(V, float), np.asarray(F, np.int64)
    ids = np.arange(len(V)) if ids is None else np.asarray(ids)
    n = vertex_normals(V, F)[ids]
    # tangent basis per vertex
    a = np.where(np.abs(n[:, :1]) < 0.9, np.array([[1.0, 0, 0]]), np.array([[0, 1.0, 0]]))
    t1 = np.cross(n, a)
    t1 /= np.linalg.norm(t1, axis=1, keepdims=True)
    t2 = np.cross(n, t1)
    th = 2 * np.pi * np.arange(n_points) / n_points
    dirs = np.cos(th)[None, :, None] * t1[:, None] + np.sin(th)[None, :, None] * t2[:, None]
    v = V[ids]
    q = v[:, None] + radius * dirs                                        # (P,8,3)
    tri, w, _ = closest_points(q.reshape(-1, 3), V, F)
    p = barycentric_points(V, F, tri, w).reshape(len(ids), n_points, 3)
    d = p - v[:, None]
    dn = np.einsum("pkj,pj->pk", d, n)
    kappa = -2 * dn / np.maximum((d ** 2).sum(2), 1e-30)                 # convex positive
    T = d - dn[..., None] * n[:, None]
    T /= np.maximum(np.linalg.norm(T, axis=2, keepdims=True), 1e-30)
    T2 = np.stack([np.einsum("pkj,pj->pk", T, t1), np.einsum("pkj,pj->pk", T, t2)], 2)
    M = np.einsum("pk,pki,pkj->pij", kappa, T2, T2) / n_points
    m = np.linalg.eigvalsh(M)                                             # (P,2) ascending
    k1, k2 = 3 * m[:, 0] - m[:, 1], 3 * m[:, 1] - m[:, 0]
    return np.sort(np.stack([k1, k2], 1), axis=1)


def feature_strength(V, F, ids=None, **kw):
    """Sum of absolute principal curvatures (P,) (1/m) from the fixed-size stencil."""
    return np.abs(stencil_curvature(V, F, ids, **kw)).sum(1)
