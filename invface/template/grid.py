"""The template's surface parameterisation: rays from a centre inside the head.

A direction is given by a lateral angle ``alpha`` (0 on the midline, + to the actor's left)
and a sagittal angle ``beta`` (0 forward, +90 deg straight up):
``d = (sin a, cos a sin b, cos a cos b)``. The skin is star-shaped from ``CENTER`` so each
direction meets it once; the face mask is a rectangle in (alpha, beta) far from the poles
(which point through the ears).

The coarse grid (simulation skin) is relaxed in 3D so edges follow a sizing field; the fine
grid (render skin) subdivides each coarse cell, so every fine vertex has a known coarse cell.
"""
from __future__ import annotations

import numpy as np

CENTER = np.array([0.0, 0.02, 0.0])
ALPHA_RANGE = np.radians([-72.0, 72.0])
BETA_RANGE = np.radians([-68.0, 105.0])


def directions(alpha, beta):
    """Unit ray directions (..., 3) for angles alpha, beta (..., ) in radians."""
    ca = np.cos(alpha)
    return np.stack([np.sin(alpha), ca * np.sin(beta), ca * np.cos(beta)], axis=-1)


def angles(d):
    """Inverse of :func:`directions` for unit vectors d (..., 3) -> (alpha, beta)."""
    return np.arcsin(np.clip(d[..., 0], -1, 1)), np.arctan2(d[..., 1], d[..., 2])


def raycast(field, alpha, beta, r_lo=0.005, r_hi=0.32, iters=40):
    """Distance r (..., ) from CENTER to the zero level of ``field`` along each ray (bisection).

    r_lo, r_hi: scalars or arrays bracketing the crossing (metres).
    """
    d = directions(alpha, beta)
    lo = np.broadcast_to(np.asarray(r_lo, float), np.shape(alpha)).copy()
    hi = np.broadcast_to(np.asarray(r_hi, float), np.shape(alpha)).copy()
    for _ in range(iters):
        m = 0.5 * (lo + hi)
        inside = field(CENTER + m[..., None] * d) < 0
        lo = np.where(inside, m, lo)
        hi = np.where(inside, hi, m)
    return 0.5 * (lo + hi)


def point_at(field, x, y, iters=6):
    """Skin points (..., 3) seen from the front at lateral x and height y (..., ) metres."""
    x, y = np.broadcast_arrays(np.asarray(x, float), np.asarray(y, float))
    z = np.full(x.shape, 0.1)
    for _ in range(iters):
        d = np.stack([x, y, z], -1) - CENTER
        a, b = angles(d / np.linalg.norm(d, axis=-1, keepdims=True))
        p = CENTER + raycast(field, a, b)[..., None] * directions(a, b)
        z = p[..., 2]
    return p


def quad_triangles(ni, nj, index):
    """Two triangles per cell of an (ni, nj) vertex grid; ``index`` (ni, nj) -> vertex id.

    Returns (cells (C,2) lower-left (i, j) of each triangle's cell, tris (C,3)), outward
    oriented for the ray parameterisation (i along alpha, j along beta).
    """
    i, j = np.meshgrid(np.arange(ni - 1), np.arange(nj - 1), indexing="ij")
    i = i.ravel()
    j = j.ravel()
    a, b, c, e = index[i, j], index[i + 1, j], index[i + 1, j + 1], index[i, j + 1]
    # split every cell along the diagonal that keeps the mesh mirror symmetric about i = ni//2
    left = i < (ni - 1) // 2
    t1 = np.where(left[:, None], np.stack([a, b, e], 1), np.stack([a, b, c], 1))
    t2 = np.where(left[:, None], np.stack([b, c, e], 1), np.stack([a, c, e], 1))
    cells = np.concatenate([np.stack([i, j], 1)] * 2)
    return cells, np.concatenate([t1, t2])


def relax(field, alpha, beta, fixed, size, iters=150):
    """Tangential spring relaxation of a grid on the skin.

    alpha, beta: (ni, nj) angles; fixed: (ni, nj) bool, vertices that keep their angles;
    size: callable p (..., 3) -> target edge length factor (smaller = denser).
    Returns relaxed (alpha, beta), mirror-symmetric about the centre column.
    """
    alpha = alpha.copy()
    beta = beta.copy()
    ni = alpha.shape[0]
    r = raycast(field, alpha, beta)
    for _ in range(iters):
        # the rays turn by a fraction of a cell per iteration: bracket around the last radius
        r = raycast(field, alpha, beta, 0.75 * r, 1.25 * r, iters=20)
        p = CENTER + r[..., None] * directions(alpha, beta)
        acc = np.zeros_like(p)
        wsum = np.zeros(p.shape[:2])
        for di, dj in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            q = np.roll(p, (-di, -dj), axis=(0, 1))
            w = 1.0 / size(0.5 * (p + q))
            valid = np.ones(p.shape[:2], bool)
            if di == 1:
                valid[-1, :] = False
            if di == -1:
                valid[0, :] = False
            if dj == 1:
                valid[:, -1] = False
            if dj == -1:
                valid[:, 0] = False
            w = w * valid
            acc += w[..., None] * q
            wsum += w
        target = acc / wsum[..., None]
        a_new, b_new = angles((target - CENTER) / np.linalg.norm(target - CENTER, axis=-1, keepdims=True))
        a_new = np.where(fixed, alpha, 0.5 * alpha + 0.5 * a_new)
        b_new = np.where(fixed, beta, 0.5 * beta + 0.5 * b_new)
        # exact mirror symmetry: column i mirrors column ni-1-i
        alpha = 0.5 * (a_new - a_new[::-1])
        beta = 0.5 * (b_new + b_new[::-1])
        alpha[ni // 2] = 0.0
    return alpha, beta


def subdivide(alpha, beta, factor):
    """Refine a coarse (ni, nj) angle grid by ``factor`` with bilinear interpolation.

    Returns fine (alpha, beta) of shape ((ni-1)*f+1, (nj-1)*f+1); coarse vertex (i, j) is
    fine vertex (i*f, j*f).
    """
    ni, nj = alpha.shape
    s = np.arange((ni - 1) * factor + 1) / factor
    t = np.arange((nj - 1) * factor + 1) / factor
    i0 = np.minimum(np.floor(s).astype(int), ni - 2)
    j0 = np.minimum(np.floor(t).astype(int), nj - 2)
    u = (s - i0)[:, None]
    v = (t - j0)[None, :]

    def interp(g):
        return ((1 - u) * (1 - v) * g[i0][:, j0] + u * (1 - v) * g[i0 + 1][:, j0]
                + u * v * g[i0 + 1][:, j0 + 1] + (1 - u) * v * g[i0][:, j0 + 1])

    return interp(alpha), interp(beta)
