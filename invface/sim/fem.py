"""Vectorised linear-tet element kernels and sparse assembly with a reusable pattern.

Forces follow the finite-volume method of Teran et al. 2003: the force on node n of a tet is
f_n = -P b_n with b_n the area-weighted normal share of n's incident faces. For linear tets
b_n = V grad(N_n), so f_n = -V P G_n with G (T,4,3) the constant shape-function gradients;
this is the form computed here (one einsum over all tets, no element loop).
"""
from __future__ import annotations

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
        self.X0, self.tets, self.volume, self.G = X0, tets, vol, G

    def deformation_gradient(self, X):
        """F (T,3,3) for positions X (N,3)."""
        return np.einsum("tni,tnj->tij", X[self.tets], self.G)

    def volumes(self, X):
        """Signed deformed volumes (T,) m^3."""
        return self.volume * np.linalg.det(self.deformation_gradient(X))

    def node_forces(self, P, weight=None):
        """Energy gradient per tet node (T,4,3) from stresses P (T,3,3): V P G_n (= -f_n)."""
        w = self.volume if weight is None else self.volume * weight
        return np.einsum("t,tij,tnj->tni", w, P, self.G)

    def node_stiffness(self, H, tet_ids=None):
        """Element stiffness (T,12,12) from dP/dF blocks H (T,9,9), node-major (n, i)."""
        G = self.G if tet_ids is None else self.G[tet_ids]
        V = self.volume if tet_ids is None else self.volume[tet_ids]
        T = len(H)
        K = np.einsum("t,tijab,tnj,tmb->tnima", V, H.reshape(T, 3, 3, 3, 3), G, G, optimize=True)
        return K.reshape(T, 12, 12)


class FleshModel:
    """Energy of the flesh: isotropic material on every tet + fibre term on muscle tets.

    fibre_tets (Q,), fibre_dirs (Q,3), fibre_muscle (Q,) index the (tet, muscle) pairs; a tet
    in two muscles carries both fibre families.
    """

    def __init__(self, elements: Elements, material: materials.Material,
                 fibre_tets, fibre_dirs, fibre_muscle):
        self.el, self.mat = elements, material
        self.ftets = np.asarray(fibre_tets, np.int64)
        self.fdirs = np.asarray(fibre_dirs, float)
        self.fmus = np.asarray(fibre_muscle, np.int64)

    def evaluate(self, X, act, order=2, project=False):
        """Energy (J), gradient (T,4,3) and element stiffness (T,12,12) at positions X (N,3).

        act (M,) muscle activations. order 0/1/2 stops after the energy/gradient. ``project``
        applies the per-element definiteness fix to dP/dF.
        """
        el = self.el
        F = el.deformation_gradient(X)
        psi, P, H = materials.isotropic(F, self.mat, order)
        a = np.asarray(act, float)[self.fmus]
        fpsi, fP, fH = materials.fibre(F[self.ftets], self.fdirs, a, self.mat, order)
        E = float(el.volume @ psi + el.volume[self.ftets] @ fpsi)
        if order == 0:
            return E, None, None
        np.add.at(P, self.ftets, fP)
        grad = el.node_forces(P)
        if order == 1:
            return E, grad, None
        np.add.at(H, self.ftets, fH)
        if project:
            H = materials.project_psd(H)
        return E, grad, el.node_stiffness(H)


class Pattern:
    """Upper-triangular CSR sparsity pattern over free DOFs, built once and reused.

    dof_of_vertex (N,): free-vertex number or -1 for a constrained vertex; tets (T,4);
    extra_pairs (P,2) vertex pairs coupled by other terms (contacts).
    """

    def __init__(self, dof_of_vertex, tets, extra_pairs=None):
        self.dof_of_vertex = np.asarray(dof_of_vertex, np.int64)
        self.n = 3 * int(self.dof_of_vertex.max() + 1)
        vd = self.dof_of_vertex[tets]                                     # (T,4)
        edof = np.where(vd[:, :, None] >= 0, 3 * vd[:, :, None] + np.arange(3), -1).reshape(-1, 12)
        self.elem_dofs = edof
        r = np.repeat(edof, 12, axis=1).reshape(-1)
        c = np.tile(edof, (1, 12)).reshape(-1)
        keep = (r >= 0) & (c >= 0) & (r <= c)
        self.elem_keep = np.flatnonzero(keep)
        keys = r[keep] * self.n + c[keep]
        extra = np.empty(0, np.int64)
        if extra_pairs is not None and len(extra_pairs):
            er, ec = self._block_entries(np.asarray(extra_pairs, np.int64))
            m = (er >= 0) & (ec >= 0)
            er, ec = np.minimum(er[m], ec[m]), np.maximum(er[m], ec[m])
            extra = er * self.n + ec
        diag = np.arange(self.n) * (self.n + 1)
        self.keys, inv = np.unique(np.concatenate([keys, extra, diag]), return_inverse=True)
        self.elem_slot = inv[: len(keys)]
        rows = self.keys // self.n
        self.indptr = np.concatenate([[0], np.cumsum(np.bincount(rows, minlength=self.n))])
        self.indices = (self.keys % self.n).astype(np.int64)
        self.nnz = len(self.keys)
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
            data += np.bincount(self.elem_slot, Ke.reshape(-1)[self.elem_keep], minlength=self.nnz)
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

    def scatter(self, grad_nodes):
        """Free-DOF vector (n,) from per-tet node vectors (T,4,3) of the pattern's tets."""
        dofs = self.elem_dofs.reshape(-1)
        m = dofs >= 0
        return np.bincount(dofs[m], grad_nodes.reshape(-1)[m], minlength=self.n)
