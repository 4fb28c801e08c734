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
    x = (p[..., 0] - c[0]) / r[0]
    y = (p[..., 1] - c[1]) / r[1]
    z = (p[..., 2] - c[2]) / r[2]
    k0 = np.sqrt(x * x + y * y + z * z)
    x /= r[0]
    y /= r[1]
    z /= r[2]
    k1 = np.sqrt(x * x + y * y + z * z)
    return k0 * (k0 - 1.0) / np.maximum(k1, 1e-12)


def round_cone(p, a, b, ra, rb):
    """SDF-like distance to a cone with rounded ends from ``a`` (radius ra) to ``b`` (radius rb).

    Uses the linear radius interpolation along the projection onto the axis; exact for a
    capsule (ra == rb) and a good approximation when the radii differ by much less than the
    length, which is how it is used here.
    """
    ab = [b[i] - a[i] for i in range(3)]
    d = [p[..., i] - a[i] for i in range(3)]
    t = np.clip((d[0] * ab[0] + d[1] * ab[1] + d[2] * ab[2]) / (ab[0] ** 2 + ab[1] ** 2 + ab[2] ** 2), 0.0, 1.0)
    e = [d[i] - t * ab[i] for i in range(3)]
    return np.sqrt(e[0] ** 2 + e[1] ** 2 + e[2] ** 2) - (ra + (rb - ra) * t)

