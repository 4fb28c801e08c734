"""Triangle-mesh helpers shared by the simulation (contacts) and the renderer (shading)."""
from __future__ import annotations

import numpy as np


def face_normals(X, faces):
    """Unnormalised face normals (F,3) of triangles ``faces`` (F,3) at positions X: the
    cross product of two edges, twice the triangle's area long."""
    X, faces = np.asarray(X, float), np.asarray(faces)
    return np.cross(X[faces[:, 1]] - X[faces[:, 0]], X[faces[:, 2]] - X[faces[:, 0]])


def triangle_areas(X, faces):
    """Areas (F,) of triangles ``faces`` at positions X (units of X squared)."""
    return 0.5 * np.linalg.norm(face_normals(X, faces), axis=1)


def vertex_normals(X, faces, n_vertices=None):
    """Area-weighted unit vertex normals (N,3) of triangles ``faces`` (F,3) at positions X;
    N = n_vertices, default len(X)."""
    X, faces = np.asarray(X, float), np.asarray(faces)
    fn = face_normals(X, faces)
    vn = np.zeros((len(X) if n_vertices is None else n_vertices, 3))
    for k in range(3):
        np.add.at(vn, faces[:, k], fn)
    return vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-30)
