"""Vectorised implicit-surface primitives and smooth Boolean operations.

All functions take points ``p`` of shape (..., 3) in metres and return approximate signed
distances (..., ) in metres: negative inside, positive outside.
"""
import numpy as np


def smin(a, b, k):
    """Polynomial smooth minimum (smooth union) with blend radius ``k`` metres."""
    if k <= 0:
        return np.minimum(a, b)
    h = np.clip(0.5 + 0.5 * (b - a) / k, 0.0, 1.0)
    return b * (1 - h) + a * h - k * h * (1 - h)


def smax(a, b, k):
    """Smooth maximum (smooth intersection / subtraction of ``-b``)."""
    return -smin(-a, -b, k)


def ellipsoid(p, c, r):
    """Approximate SDF of an axis-aligned ellipsoid, centre ``c`` (3,), radii ``r`` (3,)."""
    q = (p - np.asarray(c)) / np.asarray(r)
    k0 = np.linalg.norm(q, axis=-1)
    k1 = np.linalg.norm(q / np.asarray(r), axis=-1)
    return k0 * (k0 - 1.0) / np.maximum(k1, 1e-12)


def round_cone(p, a, b, ra, rb):
    """SDF-like distance to a cone with rounded ends from ``a`` (radius ra) to ``b`` (radius rb).

    Uses the linear radius interpolation along the projection onto the axis; exact for a
    capsule (ra == rb) and a good approximation when the radii differ by much less than the
    length, which is how it is used here.
    """
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    ab = b - a
    t = np.clip(((p - a) @ ab) / (ab @ ab), 0.0, 1.0)
    closest = a + t[..., None] * ab
    return np.linalg.norm(p - closest, axis=-1) - (ra + (rb - ra) * t)


def mirror_x(f):
    """Make a primitive symmetric about x = 0: f(p) evaluated at (|x|, y, z)."""
    def g(p, *args, **kw):
        q = p.copy()
        q[..., 0] = np.abs(q[..., 0])
        return f(q, *args, **kw)
    return g
