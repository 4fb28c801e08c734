"""Simultaneous untangling and quality optimisation of a tet mesh (Escobar et al. 2003).

Each tet's deformation gradient F (from a reference shape, here the template's rest tet) is
scored by the regularised mean-ratio distortion

    E(F) = |F|_F^2 / (3 h(det F)^(2/3)),    h(d) = (d + sqrt(d^2 + delta^2)) / 2,

weighted by the reference volume. E is 1 for a similarity of the reference and grows without
bound as a tet flattens; with delta > 0 it stays finite for inverted tets, so a gradient
method moves them back through zero volume (the untangling), and at delta -> 0 the minimiser
is the quality optimum. A pass's delta (``_delta``) is wide while a tet is inverted; once
none is, it is small against the smallest volume ratio where a tet has shrunk to a sliver
(a fixed delta scores a tiny tet below a good one). Used when the volume morph's Laplacian
relaxation (paper 001 sec. 9) leaves tets inverted or below the quality bound; it replaces
remeshing there.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import minimize

SHRUNK = 1e-3       # volume ratio below which the regulariser follows the smallest ratio


def _energy(X, X0inv, vol0, tets, delta):
    """Energy (float) and its gradient (N,3) for positions X (N,3)."""
    P = X[tets]
    Ds = (P[:, 1:] - P[:, :1]).transpose(0, 2, 1)            # (T,3,3) columns x_i - x_0
    F = Ds @ X0inv
    s = np.einsum("tij,tij->t", F, F)
    c0, c1, c2 = F[:, :, 0], F[:, :, 1], F[:, :, 2]
    cof = np.stack([np.cross(c1, c2), np.cross(c2, c0), np.cross(c0, c1)], axis=2)
    d = np.einsum("ti,ti->t", c0, cof[:, :, 0])
    r = np.sqrt(d * d + delta * delta)
    # (d + r) / 2, written for d < 0 without the cancellation that makes it 0 at a small delta
    h = np.where(d >= 0, 0.5 * (d + r), 0.5 * delta * delta / np.where(d >= 0, 1.0, r - d))
    dh = h / r
    e = s / (3 * h ** (2 / 3))
    dEdF = (2 * F / (3 * h[:, None, None] ** (2 / 3))
            - ((2 / 9) * s * h ** (-5 / 3) * dh)[:, None, None] * cof)
    G = vol0[:, None, None] * dEdF @ X0inv.transpose(0, 2, 1)  # dE/dDs (T,3,3)
    g = np.zeros_like(X)
    cols = G.transpose(0, 2, 1)                                # (T,3 vertices,3)
    np.add.at(g, tets[:, 1:].ravel(), cols.reshape(-1, 3))
    np.add.at(g, tets[:, 0], -cols.sum(axis=1))
    return float((vol0 * e).sum()), g


def _delta(dets):
    """The regulariser for volume ratios ``dets`` (T,): while a tet is inverted, wide enough to
    carry it back through zero volume; once none is, 0.01, or, where a tet has shrunk below
    ``SHRUNK`` of its volume, small against the smallest ratio, so that the tet costs what its
    shape says (at 0.01, a tet at 0.1 % of its volume scores below a good one)."""
    dmin = float(dets.min())
    if dmin <= 0:
        return float(np.sqrt(1e-4 - dmin * 1e-2))
    return 1e-2 if dmin >= SHRUNK else float(max(1e-8, 0.1 * dmin))


def untangle(X, X0, tets, free, delta=None, iters=300):
    """Move the ``free`` vertex ids of the tet mesh (X (N,3) m, tets (T,4)) to minimise the
    regularised mean-ratio distortion against the reference positions X0 (N,3), holding all
    other vertices. Only tets touching a free vertex are scored. Without ``delta``, it follows
    the tets (``_delta``): a pass with the untangling delta, then, while a tet is under
    ``SHRUNK`` of its volume and none is inverted, up to two with one small against the
    smallest volume ratio. Returns new positions (N,3)."""
    free = np.asarray(free, np.int64)
    if len(free) == 0:
        return X.copy()
    mask = np.zeros(len(X), bool)
    mask[free] = True
    T = tets[mask[tets].any(axis=1)]
    Q = X0[T]
    D0 = (Q[:, 1:] - Q[:, :1]).transpose(0, 2, 1)
    vol0 = np.abs(np.linalg.det(D0)) / 6
    X0inv = np.linalg.inv(D0)
    vol0 = vol0 / vol0.mean()
    Xw = X.copy()

    def ratios():
        return np.linalg.det((Xw[T][:, 1:] - Xw[T][:, :1]).transpose(0, 2, 1) @ X0inv)

    def fun(z, d):
        Xw[free] = z.reshape(-1, 3)
        E, g = _energy(Xw, X0inv, vol0, T, d)
        return E, g[free].ravel()

    d = _delta(ratios()) if delta is None else delta
    for _ in range(3):
        res = minimize(fun, Xw[free].ravel(), args=(d,), jac=True, method="L-BFGS-B",
                       options={"maxiter": iters, "gtol": 1e-10, "ftol": 1e-14})
        Xw[free] = res.x.reshape(-1, 3)
        if delta is not None:
            break
        smaller = _delta(ratios())
        if smaller >= d:
            break
        d = smaller
    return Xw
