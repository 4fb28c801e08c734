"""Synthetic actors for tests and benchmarks: the template skin under a smooth random
deformation (identity change) and a random similarity transform (pose and unit), a front part
of it, and a torso to put under a scan."""
from __future__ import annotations

import numpy as np

from .orient import kabsch


def random_identity(neutral, seed, amplitude=0.004, bumps=8, width=0.03, stretch=0.04):
    """Deformed copy (V,3) m of ``neutral`` (V,3): a random anisotropic scale about the
    centroid (sd ``stretch``) plus ``bumps`` Gaussian bumps of width ``width`` m and random
    displacement (sd ``amplitude`` m per axis)."""
    rng = np.random.default_rng(seed)
    c = neutral.mean(0)
    X = c + (neutral - c) * (1 + rng.normal(0, stretch, 3))
    for _ in range(bumps):
        p = neutral[rng.integers(len(neutral))]
        w = np.exp(-np.sum((neutral - p) ** 2, 1) / (2 * width ** 2))
        X += w[:, None] * rng.normal(0, amplitude, 3)
    return X


def random_pose(X, seed, unit=0.001, shift=0.2):
    """X (V,3) m rotated by a uniformly random rotation, shifted by ~``shift`` m and written in
    ``unit`` (metres per file unit). Returns (file coordinates (V,3), R (3,3), t (3,))."""
    from scipy.spatial.transform import Rotation
    rng = np.random.default_rng(seed + 1000)
    R = Rotation.random(random_state=seed).as_matrix()
    t = rng.normal(0, shift, 3)
    return (X @ R.T + t) / unit, R, t


def front_part(X, F, cut):
    """The part of a head (X (V,3) m, F (T,3)) in front of the plane z = cut (m): a partial,
    front-of-face scan. Returns (ids (n,) of the kept vertices, faces (t,3) on them)."""
    keep = X[F].mean(1)[:, 2] > cut
    ids = np.unique(F[keep])
    remap = np.full(len(X), -1)
    remap[ids] = np.arange(len(ids))
    return ids, remap[F[keep]]


def onto_part(X, ids, Q):
    """X (V,3) moved rigidly so that its part X[ids] lies best on Q (n,3) (least squares):
    a whole head carried into the frame where only its scanned part is known."""
    R, t = kabsch(X[ids], Q)
    return X @ R.T + t


def torso(top, radii=(0.23, 0.13, 0.15), below=(0.135, 0.04)):
    """A closed ellipsoid torso (vertices (n,3) m, faces (t,3)): semi-axes ``radii`` (m: width,
    height, depth), its centre ``below`` (m: down, back) from ``top`` (3,), a head's lowest
    point; the defaults give a torso 46 x 26 x 30 cm whose top meets the neck."""
    import trimesh
    s = trimesh.creation.icosphere(4, radius=1.0)
    V = np.asarray(s.vertices) * np.asarray(radii) + np.asarray(top, float) - np.array([0.0, below[0], below[1]])
    return V, np.asarray(s.faces)
