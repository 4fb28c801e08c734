"""Sparse symmetric positive-definite solvers behind one small interface.

    solver = make_solver(pattern)      # symbolic analysis once per sparsity pattern
    solver.factor(data)                # numeric factorisation per Newton step (raises NotSPD)
    x = solver.solve(b)                # (n,) or (n, k) right-hand sides, reusing the factor

PARDISO (Intel MKL through pypardiso's library, mtype 2 = real SPD, upper-triangular CSR,
phase 11 once, 22 per factorisation, 33 per solve) is the default: pip-only and measured
fastest on the 2-core machine (bench/RESULTS.md). SuperLU (scipy) is the always-available
fallback; it checks definiteness with a sparse LDL-free test (the sign of U's diagonal).
INVFACE_SOLVER=pardiso|superlu forces one.
"""
from __future__ import annotations

import ctypes
import functools
import importlib.metadata
import os

import numpy as np
import scipy.sparse.linalg as spla

from ..errors import DependencyError, InvfaceError


class NotSPD(InvfaceError):
    """The matrix handed to factor() is not positive definite."""


@functools.cache
def _pardiso_function():
    """MKL's pardiso entry point, located once per process: the mkl wheel's runtime library
    by its file list (PYPARDISO_MKL_RT overrides), else pypardiso's own search, which globs
    the whole prefix (importing pypardiso globs once more), which costs a second per process
    where the file list costs milliseconds. Raises DependencyError."""
    path = os.environ.get("PYPARDISO_MKL_RT")
    if path is None:
        try:
            files = importlib.metadata.files("mkl") or []
        except importlib.metadata.PackageNotFoundError:
            files = []
        found = sorted((f for f in files if f.name.startswith("libmkl_rt") or f.name.startswith("mkl_rt")),
                       key=lambda f: len(str(f)))
        path = str(found[0].locate()) if found else None
    if path is not None:
        try:
            return ctypes.CDLL(path).pardiso
        except (OSError, AttributeError):
            pass
    try:
        from pypardiso.pardiso_wrapper import PyPardisoSolver
        return PyPardisoSolver().libmkl.pardiso
    except (ImportError, OSError) as e:    # pragma: no cover - depends on the install
        raise DependencyError(f"MKL's PARDISO is not available (pip install pypardiso): {e}") from e


class PardisoSolver:
    name = "pardiso"

    def __init__(self, pattern):
        """Symbolic analysis (phase 11) of ``pattern``. The fill-reducing ordering METIS finds is
        kept on the pattern and handed to the next solver of the same pattern (iparm[4] = 1),
        which then skips METIS: every SimResult's adjoint solver is such a second one."""
        self._lib = _pardiso_function()
        self.n = pattern.n
        self._ia = (pattern.indptr + 1).astype(np.int32)
        self._ja = (pattern.indices + 1).astype(np.int32)
        self._pt = np.zeros(64, np.int64)
        self._iparm = np.zeros(64, np.int32)
        # user-set iparm: METIS ordering (1), pivot perturbation 1e-8 (9), the rest zero; on
        # the default head's Newton matrix a solve takes 0.003 s against MKL's defaults'
        # 0.008 s, a factorisation the same. (The two-level factorisation, iparm[23] = 10,
        # factors 13 % faster but does not report a matrix that is not positive definite.)
        self._iparm[[0, 1, 9]] = 1, 2, 8
        perm = getattr(pattern, "pardiso_perm", None)
        self._iparm[4] = 2 if perm is None else 1       # 2: return METIS's ordering; 1: use ours
        self._perm = np.zeros(self.n, np.int32) if perm is None else perm
        self._data = np.zeros(pattern.nnz)
        err, _ = self._call(11, np.zeros(self.n))
        if err != 0:
            raise InvfaceError(f"PARDISO analysis failed (error {err})")
        if perm is None:
            pattern.pardiso_perm = self._perm
        self._iparm[4] = 0

    def _call(self, phase, b):
        b = np.asfortranarray(b, dtype=float)
        x = np.zeros_like(b)
        err = ctypes.c_int32(0)
        i32 = ctypes.POINTER(ctypes.c_int32)
        f64 = ctypes.POINTER(ctypes.c_double)
        self._lib(self._pt.ctypes.data_as(ctypes.POINTER(ctypes.c_int64)),
                  ctypes.byref(ctypes.c_int32(1)), ctypes.byref(ctypes.c_int32(1)),
                  ctypes.byref(ctypes.c_int32(2)), ctypes.byref(ctypes.c_int32(phase)),
                  ctypes.byref(ctypes.c_int32(self.n)), self._data.ctypes.data_as(f64),
                  self._ia.ctypes.data_as(i32), self._ja.ctypes.data_as(i32),
                  self._perm.ctypes.data_as(i32),
                  ctypes.byref(ctypes.c_int32(1 if b.ndim == 1 else b.shape[1])),
                  self._iparm.ctypes.data_as(i32), ctypes.byref(ctypes.c_int32(0)),
                  b.ctypes.data_as(f64), x.ctypes.data_as(f64), ctypes.byref(err))
        return err.value, np.ascontiguousarray(x)

    def factor(self, data):
        self._data = np.ascontiguousarray(data, float)
        err, _ = self._call(22, np.zeros(self.n))
        if err == -4:
            raise NotSPD("Newton matrix is not positive definite")
        if err != 0:
            raise InvfaceError(f"PARDISO factorisation failed (error {err})")

    def solve(self, b):
        err, x = self._call(33, b)
        if err != 0:
            raise InvfaceError(f"PARDISO solve failed (error {err})")
        return x

    def __del__(self):
        try:
            if self._pt.any():
                self._call(-1, np.zeros(self.n))
        except Exception:
            pass


class SuperLUSolver:
    name = "superlu"

    def __init__(self, pattern):
        self.pattern = pattern
        self._lu = None

    def factor(self, data):
        A = self.pattern.matrix(data, full=True).tocsc()
        try:
            lu = spla.splu(A, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                           options={"SymmetricMode": True})
        except RuntimeError as e:
            raise NotSPD(f"Newton matrix is singular ({e})") from e
        # With symmetric diagonal pivoting, A = P^T L U P and U's diagonal holds the pivots;
        # an SPD matrix has them all positive.
        if np.any(lu.U.diagonal() <= 0) or np.any(lu.perm_r != lu.perm_c):
            raise NotSPD("Newton matrix is not positive definite")
        self._lu = lu

    def solve(self, b):
        return self._lu.solve(np.asarray(b, float))


def preconditioned_cg(matvec, precondition, b, rtol=1e-12, max_iter=25):
    """x (n,) with A x = b by conjugate gradients, A given by ``matvec`` (n,) -> (n,), the
    preconditioner by ``precondition`` (n,) -> (n,) (M^-1 r: a factorised matrix near A).
    Stops at |b - A x| <= rtol |b|. Returns None when it does not get there in ``max_iter``
    iterations or meets a direction of non-positive curvature (A not positive definite, or
    the preconditioner too far from it): the caller factorises A instead."""
    nb = np.linalg.norm(b)
    if nb == 0:
        return np.zeros_like(b)
    x = precondition(b)
    r = b - matvec(x)
    if np.linalg.norm(r) <= rtol * nb:
        return x
    z = precondition(r)
    p, rz = z.copy(), float(r @ z)
    for _ in range(max_iter):
        Ap = matvec(p)
        pAp = float(p @ Ap)
        if not pAp > 0 or not rz > 0:
            return None
        a = rz / pAp
        x += a * p
        r -= a * Ap
        if np.linalg.norm(r) <= rtol * nb:      # before the next back-substitution, not after it
            return x
        z = precondition(r)
        rz, rz_old = float(r @ z), rz
        p = z + (rz / rz_old) * p
    return None


def available():
    """Names of the solvers that can run here, best first."""
    try:
        _pardiso_function()
        return ["pardiso", "superlu"]
    except DependencyError:
        return ["superlu"]


class MatrixPattern:
    """The upper-triangular CSR pattern of a symmetric scipy sparse matrix, for solvers of
    matrices other than the FEM Newton matrix (``fem.Pattern``): same interface."""

    def __init__(self, A):
        import scipy.sparse as sp
        U = sp.triu(sp.csr_matrix(A), format="csr")
        U.sum_duplicates()
        U.sort_indices()
        self.n, self.nnz = U.shape[0], U.nnz
        self.indptr, self.indices = U.indptr.astype(np.int64), U.indices.astype(np.int64)
        rows = np.repeat(np.arange(self.n), np.diff(self.indptr))
        self._keys = rows * self.n + self.indices            # sorted (CSR, sorted indices)

    def values(self, B):
        """Values (nnz,) of symmetric ``B`` (pattern within this one's) in pattern order."""
        import scipy.sparse as sp
        V = sp.triu(sp.coo_matrix(B))
        keys = V.row.astype(np.int64) * self.n + V.col
        slot = np.searchsorted(self._keys, keys)
        if np.any(slot >= self.nnz) or np.any(self._keys[np.minimum(slot, self.nnz - 1)] != keys):
            raise InvfaceError("matrix has entries outside the analysed sparsity pattern")
        return np.bincount(slot, V.data, minlength=self.nnz)

    def matrix(self, data, full=False):
        import scipy.sparse as sp
        U = sp.csr_matrix((data, self.indices, self.indptr), shape=(self.n, self.n))
        return (U + U.T - sp.diags(U.diagonal())).tocsr() if full else U


def make_solver(pattern, name=None):
    """A solver for ``pattern`` (fem.Pattern): name or INVFACE_SOLVER, else the best available."""
    name = name or os.environ.get("INVFACE_SOLVER") or available()[0]
    if name == "pardiso":
        return PardisoSolver(pattern)
    if name == "superlu":
        return SuperLUSolver(pattern)
    raise InvfaceError(f"unknown sparse solver {name!r}; choose from {available()}")
