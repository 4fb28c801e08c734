"""A toy contact model written against the contact interface only: a rigid plate carried by the
jaw, pressing on a set of flesh vertices. It is the check that a new contact model plugs into
``Simulator(model, contacts=[...])`` from its own file: Newton, the Newton matrix's pattern,
the fallback ladder, the contact-region test and the adjoint's jaw term all reach it through
``ContactModel``, with no edit anywhere else (tests/test_contact.py).

Energy of vertex i at x_i, for the plate through p(M) = R p0 + t with unit normal n(M) = R n0
(M = [R t] the jaw transform):

    gap_i = n . (x_i - p),   E = sum_i e(gap_i)          (e: ``contact.base.penalty``)

gradient e'(gap) n, Hessian e''(gap) n n^T (positive semi-definite: the plate does not turn with
x), and d(gradient)/dj = e'' (dn/dj . (x - p) - n . dp/dj) n + e' dn/dj.
"""
from __future__ import annotations

import numpy as np

from invface.sim.contact.base import ContactModel, penalty, vertex_blocks


class JawPlate(ContactModel):
    """A plate through point p0 (3,) m with unit normal n0 (3,) in the jaw's rest frame, pushing
    vertices (v,) of N flesh vertices to its +n0 side with stiffness k (N/m)."""

    def __init__(self, n_vertices, vertices, point, normal, stiffness):
        self.n_vertices = int(n_vertices)
        self.v = np.asarray(vertices, np.int64)
        self.p0 = np.asarray(point, float)
        self.n0 = np.asarray(normal, float) / np.linalg.norm(normal)
        self.k = float(stiffness)

    def __len__(self):
        return len(self.v)

    def _plane(self, M):
        return M[:3, :3] @ self.p0 + M[:3, 3], M[:3, :3] @ self.n0

    def _terms(self, X, M):
        p, n = self._plane(M)
        d = np.asarray(X, float)[self.v] - p
        e, de, dde = penalty(d @ n, self.k)
        return p, n, d, e, de, dde

    def energy(self, X, M):
        return float(self._terms(X, M)[3].sum())

    def gradient(self, X, M):
        _, n, _, _, de, _ = self._terms(X, M)
        out = np.zeros((self.n_vertices, 3))
        np.add.at(out, self.v, de[:, None] * n)
        return out

    def blocks(self, X, M, project=False):
        _, n, _, _, _, dde = self._terms(X, M)
        return vertex_blocks(self.v, dde[:, None, None] * np.outer(n, n))     # PSD: project changes nothing

    def acting_vertices(self, X, M):
        return np.unique(self.v[self._terms(X, M)[4] != 0])

    def jaw_derivative(self, X, M, dM):
        _, n, d, _, de, dde = self._terms(X, M)
        out = np.zeros((len(dM), self.n_vertices, 3))
        for i, D in enumerate(dM):
            dn = D[:3, :3] @ self.n0
            dp = D[:3, :3] @ self.p0 + D[:3, 3]
            dgap = d @ dn - n @ dp
            np.add.at(out[i], self.v, (dde * dgap)[:, None] * n + de[:, None] * dn)
        return out


def chin_plate(model, depth=1e-3, stiffness=2e3):
    """A JawPlate in front of the chin of a FaceModel: facing back (-z), ``depth`` m behind the
    most forward free skin vertex below the mouth, acting on the free skin vertices below the
    mouth within 6 mm of it (some start ``depth`` inside it)."""
    X0 = np.asarray(model.rest_positions, float)
    free = np.ones(len(X0), bool)
    free[model.fixed_cranium] = free[model.fixed_jaw] = False
    mouth_y = float(np.asarray(model.neutral)[model.landmarks["stomion"], 1])
    chin = np.flatnonzero(free & (X0[:, 1] < mouth_y - 0.015))
    front = X0[chin, 2].max()
    v = chin[X0[chin, 2] > front - 0.006]
    return JawPlate(len(X0), v, (0.0, 0.0, front - depth), (0.0, 0.0, -1.0), stiffness)
