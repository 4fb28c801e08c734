"""Tube meshes around polylines (the muscles' spindles and rings in the previews)."""
from __future__ import annotations

import numpy as np


def tube(points, radii, n_around=14, closed=False, up=None, flatten=1.0):
    """Triangle mesh (V (P*n,3), F (f,3)) of a tube of circular cross-section.

    points (P,3) m: the centre-line (a closed ring need not repeat its first point);
    radii (P,) m: the radius at each point (0 closes an open end in a point). The cross
    sections are carried along by parallel transport, so the tube does not twist; with ``up``
    (P,3) they are turned to it instead, and their extent along it is ``flatten`` * radii
    (a strap lying flat under the skin for up = the skin's outward direction).
    """
    P = np.asarray(points, float)
    r = np.asarray(radii, float)
    if closed and np.allclose(P[0], P[-1]):
        P, r = P[:-1], r[:-1]
    t = np.gradient(P, axis=0) if not closed else np.roll(P, -1, 0) - np.roll(P, 1, 0)
    t /= np.maximum(np.linalg.norm(t, axis=1, keepdims=True), 1e-12)
    a = np.cross(t[0], [1.0, 0.0, 0.0] if abs(t[0, 0]) < 0.9 else [0.0, 1.0, 0.0])
    frames = np.zeros((len(P), 2, 3))
    for k in range(len(P)):                      # parallel transport: one cross product per point
        if up is not None:
            a = np.asarray(up[k], float)
        a = a - (a @ t[k]) * t[k]
        a /= np.linalg.norm(a)
        frames[k] = a, np.cross(t[k], a)
    phi = np.linspace(0, 2 * np.pi, n_around, endpoint=False)
    ring = (flatten * np.cos(phi)[None, :, None] * frames[:, None, 0]
            + np.sin(phi)[None, :, None] * frames[:, None, 1])
    V = (P[:, None] + r[:, None, None] * ring).reshape(-1, 3)
    n_rows = len(P) if closed else len(P) - 1
    i, j = np.meshgrid(np.arange(n_rows), np.arange(n_around), indexing="ij")
    a0 = i * n_around + j
    a1 = i * n_around + (j + 1) % n_around
    b0 = ((i + 1) % len(P)) * n_around + j
    b1 = ((i + 1) % len(P)) * n_around + (j + 1) % n_around
    F = np.concatenate([np.stack([a0, a1, b0], -1).reshape(-1, 3), np.stack([a1, b1, b0], -1).reshape(-1, 3)])
    return V, F.astype(np.int64)


def spindle(n, closed=False):
    """Radius factors (n,) in (0, 1] along a muscle's centre-line: a fusiform belly, 1 at the
    middle and 0.4 at the origin and insertion (1 all round a closed ring)."""
    if closed:
        return np.ones(n)
    s = np.linspace(0.0, 1.0, n)
    return 0.4 + 0.6 * np.sin(np.pi * s) ** 0.7
