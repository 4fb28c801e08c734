"""Closest points on a triangle mesh (vectorised, KD-tree candidates; no rtree needed)."""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree


def closest_on_triangles(p, a, b, c):
    """Closest points on triangles (a, b, c) (P,3 each) to points p (P,3).

    Returns barycentric weights (P,3) of the closest point (Ericson, Real-Time Collision
    Detection 5.1.5, region tests done for all points at once).
    """
    ab, ac, ap = b - a, c - a, p - a
    d1, d2 = np.einsum("ij,ij->i", ab, ap), np.einsum("ij,ij->i", ac, ap)
    bp = p - b
    d3, d4 = np.einsum("ij,ij->i", ab, bp), np.einsum("ij,ij->i", ac, bp)
    cp = p - c
    d5, d6 = np.einsum("ij,ij->i", ab, cp), np.einsum("ij,ij->i", ac, cp)
    va, vb, vc = d3 * d6 - d5 * d4, d5 * d2 - d1 * d6, d1 * d4 - d3 * d2
    den = np.where(va + vb + vc == 0, 1e-300, va + vb + vc)
    w = np.stack([va / den, vb / den, vc / den], 1)                       # interior
    with np.errstate(divide="ignore", invalid="ignore"):
        t_ab = d1 / (d1 - d3)
        t_ac = d2 / (d2 - d6)
        t_bc = (d4 - d3) / ((d4 - d3) + (d5 - d6))
        # a collapsed edge's t is inf or nan: its weights are not finite, and replaced below
        cases = [   # (condition, weights), later entries take precedence over the interior
            ((va <= 0) & (d4 - d3 >= 0) & (d5 - d6 >= 0), lambda: np.stack([0 * t_bc, 1 - t_bc, t_bc], 1)),
            ((vb <= 0) & (d2 >= 0) & (d6 <= 0), lambda: np.stack([1 - t_ac, 0 * t_ac, t_ac], 1)),
            ((vc <= 0) & (d1 >= 0) & (d3 <= 0), lambda: np.stack([1 - t_ab, t_ab, 0 * t_ab], 1)),
            ((d6 >= 0) & (d5 <= d6), lambda: np.tile([0.0, 0.0, 1.0], (len(p), 1))),
            ((d3 >= 0) & (d4 <= d3), lambda: np.tile([0.0, 1.0, 0.0], (len(p), 1))),
            ((d1 <= 0) & (d2 <= 0), lambda: np.tile([1.0, 0.0, 0.0], (len(p), 1))),
        ]
        for cond, weights in cases:
            if cond.any():
                w = np.where(cond[:, None], weights(), w)
    bad = ~np.isfinite(w).all(1)          # collapsed triangles: their first vertex
    if bad.any():
        w[bad] = (1.0, 0.0, 0.0)
    return w


def barycentric_points(values, F, tri, w):
    """Per-vertex values (n, d) (positions, normals) interpolated in the triangles ``tri``
    (m,) of faces F at barycentric weights w (m, 3): (m, d)."""
    return np.einsum("nk,nkj->nj", w, np.asarray(values)[np.asarray(F)[tri]])


CHUNK = 20000       # points per batch


def closest_points(points, V, F, k=16):
    """Closest points on the mesh (V (n,3), F (f,3)) to points (P,3).

    Returns triangle ids (P,), barycentric weights (P,3) and distances (P,) in the units of V.
    The candidates are the k triangles with the nearest centroids, exact for meshes with
    triangles of similar size. For many queries on one mesh, build a ``TriangleLocator`` once.
    """
    return TriangleLocator(V, F).closest(points, k)


class TriangleLocator:
    """Closest-point queries on one triangle mesh (V (n,3), F (f,3)), the KD-tree of its
    triangles' centroids built once: what an ICP or an optimiser that measures against the
    same mesh at every step queries (``closest_points`` builds one per call)."""

    def __init__(self, V, F):
        self.V, self.F = np.asarray(V, float), np.asarray(F, np.int64)
        self.tree = cKDTree(self.V[self.F].mean(1))

    def closest(self, points, k=16):
        """``closest_points`` of points (P,3) on this mesh: triangle ids (P,), barycentric
        weights (P,3), distances (P,)."""
        points = np.asarray(points, float).reshape(-1, 3)
        k = min(k, len(self.F))
        if len(points) > CHUNK:          # k candidates per point: bounded memory on a large scan
            parts = [_closest(points[i:i + CHUNK], self.V, self.F, k, self.tree)
                     for i in range(0, len(points), CHUNK)]
            return tuple(np.concatenate(a) for a in zip(*parts))
        return _closest(points, self.V, self.F, k, self.tree)


def candidate_points(points, V, F, k=16):
    """The closest points on each of the k triangles with the nearest centroids to points
    (P,3): triangle ids (P, k), barycentric weights (P, k, 3), distances (P, k)."""
    points = np.asarray(points, float).reshape(-1, 3)
    V, F = np.asarray(V, float), np.asarray(F, np.int64)
    k = min(k, len(F))
    return _candidates(points, V, F, k, cKDTree(V[F].mean(1)))


def _candidates(points, V, F, k, tree):
    _, cand = tree.query(points, k=k)
    cand = cand.reshape(len(points), k)
    P = np.repeat(points, k, axis=0)
    tri = V[F[cand.ravel()]]
    w = closest_on_triangles(P, tri[:, 0], tri[:, 1], tri[:, 2])
    d = np.linalg.norm(np.einsum("pk,pki->pi", w, tri) - P, axis=1)
    return cand, w.reshape(len(points), k, 3), d.reshape(len(points), k)


def _closest(points, V, F, k, tree):
    cand, w, d = _candidates(points, V, F, k, tree)
    best = np.argmin(d, axis=1)
    rows = np.arange(len(points))
    return cand[rows, best], w[rows, best], d[rows, best]
