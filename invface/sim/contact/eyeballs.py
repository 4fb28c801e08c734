"""The lids sliding on the eyeballs: an exact sphere contact per eyeball (paper 000 Eq. 3's
collision penalty with the eyeball as a rigid sphere on the cranium)."""
from __future__ import annotations

import numpy as np

from ...model.gaze import fit_sphere
from .base import ContactModel, penalty, psd, vertex_blocks


def eyeball_spheres(model):
    """[(centre (3,), radius)] of the model's eyeballs (inner parts named eye_*), which ride
    the cranium: fixed in the simulation's frame."""
    if model.parts is None:
        return []
    return [fit_sphere(model.parts.mesh(n)[0]) for n in model.parts.names if str(n).startswith("eye_")]


class EyeballContacts(ContactModel):
    """The lids sliding on the eyeballs: each free boundary vertex within ``radius`` of an
    eyeball's surface at rest is kept outside that sphere (centre c, radius R) by the penalty
    of its gap

        gap = |x - c| - R - gap_rest,   E = e(gap)    (e: ``penalty``, gap_rest = min(rest gap, 0))

    a C2 function of x alone (the sphere is rigid on the cranium), exact for any slide: unlike
    the triangle contacts, a lid that travels over the whole eyeball never leaves it.
    Gradient e' n, Hessian e'' n n^T + e'/|x - c| (I - n n^T), n = (x - c)/|x - c|."""

    def __init__(self, X0, cand, spheres, stiffness, radius):
        self.n_vertices = len(X0)
        vs, cs, rs = [], [], []
        for c, R in spheres:
            d = np.linalg.norm(X0[cand] - c, axis=1) - R
            near = cand[d < radius]
            vs.append(near)
            cs.append(np.tile(c, (len(near), 1)))
            rs.append(np.full(len(near), R))
        self.v = np.concatenate(vs) if vs else np.zeros(0, np.int64)
        self.c = np.concatenate(cs) if cs else np.zeros((0, 3))
        self.R = np.concatenate(rs) if rs else np.zeros(0)
        self.stiffness = float(stiffness)
        self.rest_gap = np.zeros(len(self.v))
        self.rest_gap = np.minimum(self._gap(X0)[0], 0.0)

    def __len__(self):
        return len(self.v)

    def _gap(self, X):
        d = np.asarray(X, float)[self.v] - self.c
        rho = np.linalg.norm(d, axis=1)
        return rho - self.R - self.rest_gap, d / rho[:, None], rho

    def terms(self, X, order):
        """(vertex ids (e,), energy (e,), gradient (e,3) if order >= 1, Hessian (e,3,3) if 2)
        of the acting contacts at positions X (N,3)."""
        gap, n, rho = self._gap(X)
        m = gap < 0
        e, de, dde = penalty(gap[m], self.stiffness)
        out = [self.v[m], e]
        if order >= 1:
            out.append(de[:, None] * n[m])
        if order >= 2:
            nn = np.einsum("ci,cj->cij", n[m], n[m])
            out.append(dde[:, None, None] * nn + (de / rho[m])[:, None, None] * (np.eye(3) - nn))
        return out

    def energy(self, X, M):
        return float(self.terms(X, 0)[1].sum())

    def gradient(self, X, M):
        v, _, g = self.terms(X, 1)
        out = np.zeros((self.n_vertices, 3))
        np.add.at(out, v, g)
        return out

    def blocks(self, X, M, project=False):
        v, _, _, H = self.terms(X, 2)
        return vertex_blocks(v, psd(H) if project else H)

    def projection_blocks(self, X, M):
        v, _, _, H = self.terms(X, 2)
        return vertex_blocks(v, psd(H) - H)

    def acting_vertices(self, X, M):
        return np.unique(self.terms(X, 0)[0])
