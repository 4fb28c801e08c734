"""Vectorised linear-tet element kernels and sparse assembly with a reusable pattern.

Forces follow the finite-volume method of Teran et al. 2003: the force on node n of a tet is
f_n = -P b_n with b_n the area-weighted normal share of n's incident faces. For linear tets
b_n = V grad(N_n), so f_n = -V P G_n with G (T,4,3) the constant shape-function gradients;
this is the form computed here, by one fused numba kernel running in parallel over the tets
(deformation gradient, stress, projected or exact stiffness and the 12x12 element matrix).
"""
from __future__ import annotations

import numba as nb
import numpy as np
import scipy.sparse as sp

from ..errors import MeshError
from ..mesh.tets import shape_gradients, signed_volumes
from . import materials


class Elements:
    """Rest-state data of a tet mesh X0 (N,3) m, tets (T,4) (positive orientation)."""

    def __init__(self, X0, tets):
        X0 = np.asarray(X0, float)
        tets = np.asarray(tets, np.int64)
        if len(tets) == 0:
            raise MeshError("the flesh mesh has no tets")
        vol = signed_volumes(X0, tets)
        bad = np.flatnonzero(~(vol > 1e-18))
        if len(bad):
            raise MeshError(f"the rest flesh mesh has {len(bad)} inverted or degenerate tets "
                            f"(first: tet {bad[0]}, volume {vol[bad[0]]:.3g} m^3); rebuild the model")
        G, _ = shape_gradients(X0, tets)
        self.X0, self.tets, self.volume, self.G = X0, tets, vol, np.ascontiguousarray(G, float)

    def deformation_gradient(self, X):
        """F (T,3,3) for positions X (N,3)."""
        return np.einsum("tni,tnj->tij", X[self.tets], self.G)

    def volumes(self, X):
        """Signed deformed volumes (T,) m^3."""
        return self.volume * np.linalg.det(self.deformation_gradient(X))


@nb.njit(parallel=True, **materials.JIT)
def _flesh_kernel(X, tets, G, vol, fptr, fdir, fact, prm, order, project, psi, grad, Ke):
    """Fused FVM kernel over all tets: energy V Psi (T,), node gradients V P G_n (T,4,3) and
    element stiffness V G^T dP/dF G (T,12,12), node-major (n, i)."""
    for t in nb.prange(tets.shape[0]):
        F = np.zeros((3, 3))
        for n in range(4):
            x = X[tets[t, n]]
            for i in range(3):
                for j in range(3):
                    F[i, j] += x[i] * G[t, n, j]
        P = np.zeros((3, 3))
        H = np.zeros((9, 9))
        e = materials.iso_element(F, prm, order, P, H)
        for q in range(fptr[t], fptr[t + 1]):
            e += materials.fibre_element(F, fdir[q], fact[q], prm, order, P, H)
        V = vol[t]
        psi[t] = V * e
        if order == 0:
            continue
        for n in range(4):
            for i in range(3):
                grad[t, n, i] = V * (P[i, 0] * G[t, n, 0] + P[i, 1] * G[t, n, 1] + P[i, 2] * G[t, n, 2])
        if order == 1:
            continue
        if project and not materials.is_positive_definite(H, 1e-10 * np.abs(H).max()):
            # the definiteness fix: each term's dP/dF with negative eigenvalues clamped, from
            # its closed-form eigensystem (their sum is positive semi-definite)
            H[:, :] = 0.0
            materials.iso_projected(F, prm, 0.0, H)
            for q in range(fptr[t], fptr[t + 1]):
                materials.fibre_projected(F, fdir[q], fact[q], prm, H)
        HG = np.zeros((3, 3, 4, 3))            # HG[i, j, m, a] = sum_b H[ij, ab] G[m, b]
        for i in range(3):
            for j in range(3):
                for m in range(4):
                    for a in range(3):
                        r = 3 * i + j
                        HG[i, j, m, a] = (H[r, 3 * a] * G[t, m, 0] + H[r, 3 * a + 1] * G[t, m, 1]
                                          + H[r, 3 * a + 2] * G[t, m, 2])
        for n in range(4):
            for i in range(3):
                for m in range(4):
                    for a in range(3):
                        Ke[t, 3 * n + i, 3 * m + a] = V * (G[t, n, 0] * HG[i, 0, m, a] + G[t, n, 1] * HG[i, 1, m, a]
                                                           + G[t, n, 2] * HG[i, 2, m, a])


class FleshModel:
    """Energy of the flesh: isotropic material on every tet + fibre term on muscle tets.

    fibre_tets (Q,), fibre_dirs (Q,3), fibre_muscle (Q,) index the (tet, muscle) pairs; a tet
    in two muscles carries both fibre families.
    """

    def __init__(self, elements: Elements, material: materials.Material,
                 fibre_tets, fibre_dirs, fibre_muscle):
        self.el, self.mat = elements, material
        ftets = np.asarray(fibre_tets, np.int64)
        order = np.argsort(ftets, kind="stable")           # fibre entries grouped by tet
        self.fdirs = np.ascontiguousarray(np.asarray(fibre_dirs, float).reshape(-1, 3)[order])
        self.fmus = np.asarray(fibre_muscle, np.int64)[order]
        self.ftets = ftets[order]
        self.fptr = np.searchsorted(self.ftets, np.arange(len(elements.tets) + 1))
        # per fibre entry: its tet's nodes (Q,4), d . G_n (Q,4) and rest volume (Q,)
        self._fibre_nodes = elements.tets[self.ftets]
        self._fibre_G = np.einsum("qj,qnj->qn", self.fdirs, elements.G[self.ftets])
        self._fibre_volume = elements.volume[self.ftets]
        self.prm = material.params()

    def _along_fibres(self, V):
        """sum_n (d . G_n) V_n (Q,3) per fibre entry for a vertex field V (N,3) over its tet's
        nodes n: F d for positions, the work per unit pull for an adjoint field."""
        nodes, Gd = self._fibre_nodes, self._fibre_G
        return sum(V[nodes[:, n]] * Gd[:, n, None] for n in range(4))

    def fibre_pull(self, X):
        """V sigma_max f_a(lam) F d / lam per fibre entry (Q,3) at positions X (N,3), in the
        order of ``fmus``: the active force on a tet's node n per unit activation is this times
        d . G_n (``active_forces``, ``active_work``)."""
        Fd = self._along_fibres(X)
        lam = np.maximum(np.linalg.norm(Fd, axis=1), 1e-12)
        w = self.mat.active_width
        return (self._fibre_volume * self.mat.sigma_max * np.exp(-((lam - 1) / w) ** 2) / lam)[:, None] * Fd

    def active_forces(self, pull):
        """d(energy gradient)/d(activation) per fibre entry (Q,4,3) from ``fibre_pull`` (Q,3):
        the active forces of Eq. 4 (with a minus sign), V sigma_max f_a(lam) (d lam/dF) G_n,
        (d lam/dF) G_n = (F d)(d . G_n) / lam."""
        return pull[:, None, :] * self._fibre_G[:, :, None]

    def active_work(self, pull, mu, n_muscles):
        """mu . (the active forces of muscle m per unit activation) (n_muscles,) for
        ``fibre_pull`` (Q,3) and a vertex field mu (N,3), without forming the forces (Q,4,3)."""
        return np.bincount(self.fmus, np.einsum("qi,qi->q", pull, self._along_fibres(mu)), minlength=n_muscles)

    def evaluate(self, X, act, order=2, project=False, Ke=None):
        """Energy (J), gradient (T,4,3) and element stiffness (T,12,12) at positions X (N,3).

        act (M,) muscle activations. order 0/1/2 stops after the energy/gradient. ``project``
        applies the per-element definiteness fix to dP/dF. Ke: an array (T,12,12) float64 that
        order 2 writes the element stiffness into, instead of a new one (``Simulator`` keeps one).
        """
        el = self.el
        T = len(el.tets)
        psi = np.empty(T)
        grad = np.empty((T, 4, 3)) if order >= 1 else np.empty((1, 4, 3))
        if order < 2:
            Ke = np.empty((1, 12, 12))
        elif Ke is None:
            Ke = np.empty((T, 12, 12))
        a = np.asarray(act, float)[self.fmus] if len(self.fmus) else np.zeros(0)
        _flesh_kernel(np.ascontiguousarray(X, float), el.tets, el.G, el.volume, self.fptr, self.fdirs,
                      a, self.prm, order, project, psi, grad, Ke)
        E = float(psi.sum())
        return E, (grad if order >= 1 else None), (Ke if order == 2 else None)

    def stiffness(self, X, act, tets):
        """Exact element stiffness (len(tets),12,12) of the tets ``tets`` (indices) at positions
        X (N,3) m with muscle activations act (M,): ``evaluate``'s, on a subset of the mesh."""
        el = self.el
        tets = np.asarray(tets, np.int64)
        lo, n = self.fptr[tets], np.diff(self.fptr)[tets]          # each tet's fibre entries
        fptr = np.concatenate([[0], np.cumsum(n)])
        q = np.repeat(lo - fptr[:-1], n) + np.arange(fptr[-1])
        a = np.asarray(act, float)[self.fmus[q]]
        Ke = np.empty((len(tets), 12, 12))
        _flesh_kernel(np.ascontiguousarray(X, float), el.tets[tets], el.G[tets], el.volume[tets], fptr,
                      self.fdirs[q], a, self.prm, 2, False, np.empty(len(tets)),
                      np.empty((len(tets), 4, 3)), Ke)
        return Ke


@nb.njit(parallel=True, **materials.JIT)
def _gather_sum(ptr, src, values, out):
    """out[s] = sum of values[src[ptr[s]:ptr[s + 1]]] for every slot s, in parallel."""
    for s in nb.prange(len(ptr) - 1):
        acc = 0.0
        for k in range(ptr[s], ptr[s + 1]):
            acc += values[src[k]]
        out[s] = acc


class Pattern:
    """Upper-triangular CSR sparsity pattern over free DOFs, built once and reused.

    dof_of_vertex (N,): free-vertex number or -1 for a constrained vertex; tets (T,4);
    extra_pairs (P,2) vertex pairs coupled by other terms (contacts).
    """

    def __init__(self, dof_of_vertex, tets, extra_pairs=None):
        dv = np.asarray(dof_of_vertex, np.int64)
        self.dof_of_vertex = dv
        nv = int(dv.max() + 1)
        self.n = n = 3 * nv
        vd = dv[np.asarray(tets, np.int64)]                               # (T,4)
        self.elem_dofs = np.where(vd[:, :, None] >= 0, 3 * vd[:, :, None] + np.arange(3), -1).reshape(-1, 12)
        # 3x3 blocks of free-vertex pairs (i <= j), sorted: the tets', the extra pairs', the diagonal
        P, Q = vd[:, :, None], vd[:, None, :]
        upper = (P >= 0) & (Q >= 0) & (P <= Q)                            # (T,4,4)
        keys = [(P * nv + Q)[upper]]
        if extra_pairs is not None and len(extra_pairs):
            e = dv[np.asarray(extra_pairs, np.int64)]
            e = e[(e >= 0).all(1)]
            keys.append(e.min(1) * nv + e.max(1))
        keys.append(np.arange(nv) * (nv + 1))
        bkeys, binv = np.unique(np.concatenate(keys), return_inverse=True)
        bi, bj = bkeys // nv, bkeys % nv
        nb = np.bincount(bi, minlength=nv)                                # blocks per vertex row
        rank = np.arange(len(bkeys)) - np.concatenate([[0], np.cumsum(nb)[:-1]])[bi]   # 0: diagonal
        # DOF row 3i+a holds the diagonal block's columns 3i+a..3i+2, then 3 per block to its right
        a3 = np.arange(3)
        self.indptr = np.concatenate([[0], np.cumsum((3 - a3)[None, :] + 3 * (nb[:, None] - 1))])

        def block_slots(k, a, b):
            base = self.indptr[3 * bi[k] + a]
            return np.where(rank[k] == 0, base + b - a, base + 3 - a + 3 * (rank[k] - 1) + b)

        self.nnz = int(self.indptr[-1])
        self.indices = np.empty(self.nnz, np.int64)
        k = np.arange(len(bkeys))
        for a in range(3):
            for b in range(3):
                m = (rank > 0) | (b >= a)
                self.indices[block_slots(k[m], a, b)] = 3 * bj[m] + b
        rows = np.repeat(np.arange(n), np.diff(self.indptr))
        self.keys = rows * n + self.indices                               # sorted: CSR order
        # each stored entry of each element matrix (T,12,12), flat, and its data slot
        t, p, q = np.nonzero(upper)
        kb = binv[: len(t)]
        keep, slot = [], []
        for a in range(3):
            for b in range(3):
                m = (p != q) | (b >= a)
                keep.append(t[m] * 144 + (3 * p[m] + a) * 12 + 3 * q[m] + b)
                slot.append(block_slots(kb[m], a, b))
        keep, slot = np.concatenate(keep), np.concatenate(slot)
        # gathered per data slot (a stable sort: each slot sums in the element order)
        order = np.argsort(slot, kind="stable")
        self.elem_src = keep[order]
        self.elem_ptr = np.searchsorted(slot[order], np.arange(self.nnz + 1))
        self.diag_slot = self.slots(np.arange(self.n), np.arange(self.n))

    def _block_entries(self, pairs):
        """Row/col DOF ids (P*9,) of the 3x3 blocks of vertex pairs (P,2); -1 if constrained."""
        dv = self.dof_of_vertex[pairs[:, 0]]
        du = self.dof_of_vertex[pairs[:, 1]]
        i, j = np.meshgrid(np.arange(3), np.arange(3), indexing="ij")
        r = np.where(dv[:, None, None] >= 0, 3 * dv[:, None, None] + i, -1).reshape(-1)
        c = np.where(du[:, None, None] >= 0, 3 * du[:, None, None] + j, -1).reshape(-1)
        return r, c

    def slots(self, r, c):
        """Data slots of entries (r, c) (any order; must be in the pattern)."""
        key = np.minimum(r, c) * self.n + np.maximum(r, c)
        s = np.searchsorted(self.keys, key)
        if len(key) and (s.max() >= self.nnz or np.any(self.keys[s] != key)):
            raise KeyError("entry outside the sparsity pattern")
        return s

    def assemble(self, Ke=None, blocks=None):
        """CSR data (nnz,) from element matrices Ke (T,12,12) and vertex blocks.

        blocks: list of (pairs (P,2) vertex ids, B (P,3,3)) added as B at (v, u); callers add
        both (v, u) and (u, v) for symmetric couplings, or one (v, v) for diagonal blocks.
        Only entries with row <= col (free DOF numbering) are stored.
        """
        data = np.zeros(self.nnz)
        if Ke is not None:
            _gather_sum(self.elem_ptr, self.elem_src, Ke.reshape(-1), data)
        for pairs, B in blocks or []:
            if len(pairs) == 0:
                continue
            r, c = self._block_entries(np.asarray(pairs, np.int64))
            m = (r >= 0) & (c >= 0) & (r <= c)
            data += np.bincount(self.slots(r[m], c[m]), B.reshape(-1)[m], minlength=self.nnz)
        return data

    def matrix(self, data, full=False):
        """scipy CSR of the upper triangle (or the full symmetric matrix)."""
        U = sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))
        if not full:
            return U
        return (U + U.T - sp.diags(U.diagonal())).tocsr()

    def matvec(self, data):
        """v (n,) -> A v for the symmetric matrix whose upper triangle is data (nnz,)."""
        U = self.matrix(data)
        Ut, d = U.T, U.diagonal()
        return lambda v: U @ v + Ut @ v - d * v

    def scatter(self, grad_nodes):
        """Free-DOF vector (n,) from per-tet node vectors (T,4,3) of the pattern's tets."""
        dofs = self.elem_dofs.reshape(-1)
        m = dofs >= 0
        return np.bincount(dofs[m], grad_nodes.reshape(-1)[m], minlength=self.n)
