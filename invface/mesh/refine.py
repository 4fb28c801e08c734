"""Uniform 1:8 refinement of a tet mesh (red refinement).

Every edge gets its midpoint; every tet is cut into its four corner tets and the four tets
of the inner octahedron, split along its shortest diagonal (of the three, the one that
keeps the children's shapes best). The children of tet t are rows 8t..8t+7; a conforming
mesh stays conforming, since neighbours share their edges' midpoints.
"""
from __future__ import annotations

import numpy as np

from .tets import orient

# the six edges of a tet, in the order of the midpoint columns m01 m02 m03 m12 m13 m23
_EDGES = np.array([[0, 1], [0, 2], [0, 3], [1, 2], [1, 3], [2, 3]])
# corner tets on columns 0-3 (vertices) and 4-9 (midpoints m01 m02 m03 m12 m13 m23)
_CORNERS = np.array([[0, 4, 5, 6], [4, 1, 7, 8], [5, 7, 2, 9], [6, 8, 9, 3]])
# the octahedron's three diagonals (opposite midpoints) and, for each, the ring of the other four
_OCTA = np.array([
    [[4, 9, 5, 7], [4, 9, 7, 8], [4, 9, 8, 6], [4, 9, 6, 5]],     # m01-m23, ring m02 m12 m13 m03
    [[5, 8, 4, 6], [5, 8, 6, 9], [5, 8, 9, 7], [5, 8, 7, 4]],     # m02-m13, ring m01 m03 m23 m12
    [[6, 7, 4, 8], [6, 7, 8, 9], [6, 7, 9, 5], [6, 7, 5, 4]],     # m03-m12, ring m01 m13 m23 m02
])


def subdivide(X, tets):
    """Red refinement of a tet mesh.

    X (N,3), tets (T,4). Returns (X2 (N+E,3), tets2 (8T,4), edges (E,2)): the old vertices
    first, then the midpoint of edge e (vertex N+e); children of tet t are rows 8t..8t+7, all
    positively oriented."""
    X = np.asarray(X, float)
    tets = np.asarray(tets, np.int64)
    N, T = len(X), len(tets)
    pairs = np.sort(tets[:, _EDGES].reshape(-1, 2), axis=1)
    edges, inv = np.unique(pairs, axis=0, return_inverse=True)
    X2 = np.concatenate([X, 0.5 * (X[edges[:, 0]] + X[edges[:, 1]])])
    cols = np.concatenate([tets, N + inv.reshape(T, 6)], axis=1)         # (T,10)
    diag = np.stack([np.linalg.norm(X2[cols[:, a]] - X2[cols[:, b]], axis=1)
                     for a, b in ((4, 9), (5, 8), (6, 7))], axis=1)
    choice = np.argmin(diag, axis=1)
    local = np.concatenate([np.broadcast_to(_CORNERS, (T, 4, 4)), _OCTA[choice]], axis=1)   # (T,8,4)
    out = np.take_along_axis(cols[:, None, :], local.reshape(T, 1, 32), axis=2).reshape(T * 8, 4)
    return X2, orient(X2, out), edges
