"""Derivatives of the driven simulation (paper 000 Sec. 7) by the implicit function theorem.

At a converged state the free-DOF residual r(X^U, p) = dE/dX^U vanishes, so

    H dX^U/dp = -dr/dp,          H = dr/dX^U (the exact Newton matrix at the solution)

with p = (b, j). dr/dp collects
  * the active fibre forces times the activation slopes: (df_fvm/da)(da/dL)(dL/dC)(dC/dp);
  * the tracks: -k dM/dp (Eq. 5, 7);
  * the jaw-driven constrained vertices: H_UC dX^C/dj (full element stiffness);
  * the collision planes on the jaw, which move rigidly with it.
Tangent mode solves all K+6 right-hand sides with one factorisation (the Jacobian Dogleg
needs); adjoint mode solves H mu = dL/dX^U once and contracts mu with dr/dp term by term,
so a gradient costs one adjoint solve whatever K is: a few back-substitutions with the
solve's last factorisation of an exact Hessian (``SimResult.solve_adjoint``), no
factorisation of its own.

Contacts: the contact energy (sim.contact) is a C2 function of the flesh positions and
the jaw transform, and its full Hessian is in the Newton matrix H, so with the jaw
triangles' motion (``ContactModel.jaw_derivative``) in dr/dp these are the derivatives of the
equilibrium as a function of p, whatever state the solve started from.
"""
from __future__ import annotations

import functools

import numpy as np

from ..model.rig import jaw_transform_derivatives
from ..model.controls import FitVector


class Sensitivity:
    """Tangent and adjoint derivatives of a DrivenResult of a DrivenSimulation.

    Arrays: P = K + 6 parameters (``model.controls.FitVector``), N tet vertices, V surface vertices, n free DOFs.
    """

    def __init__(self, driven, result):
        self.ds, self.res = driven, result
        sim, model = driven.sim, driven.model
        self.sim = sim
        X = result.X
        _, jaw = driven.split(result.p)
        jm = model.jaw_matrix(jaw)
        dM = jaw_transform_derivatives(jaw, model.jaw_pivot, model.jaw_frame)
        self.vec = FitVector(model.blendshape_names)           # p = (b (K,), jaw (6,))
        self.P, self.K, self.N = self.vec.P, self.vec.K, len(X)
        jaw_rows = self.vec.jaw
        tr = driven.tracks
        self.da = tr.activation_jacobian(result.tracks, jm, dM)               # (M, P)
        self._jaw_motion = jm, dM
        self.dXc = np.zeros((self.P, self.N, 3))                                # constrained X^C(j)
        self.jaw_vertices = j = model.fixed_jaw
        self.dXc[jaw_rows, j] = np.einsum("pab,nb->pna", dM[:, :3, :3], model.rest_positions[j]) + dM[:, None, :3, 3]
        self.pull = sim.flesh.fibre_pull(X)                                    # (Q,3)
        col = sim.contacts
        self.dcontact = col.jaw_derivative(X, jm, dM) if col is not None else np.zeros((6, self.N, 3))
        # exact element stiffness of the tets on the jaw's constrained vertices: the only ones
        # whose stiffness meets dX^C/dj (H_UC dX^C/dj, and mu . H_UC dX^C/dj)
        self.jaw_tets = sim.jaw_tets
        self.Ke = sim.flesh.stiffness(X, result.sim.activations, self.jaw_tets)
        self.free = sim.free

    # -- pieces of dr/dp ------------------------------------------------------------------
    @functools.cached_property
    def dt(self):
        """d track targets / dp (P, n_tr, 3) (tangent mode; the adjoint contracts without it)."""
        return self.ds.tracks.target_derivatives(self.res.tracks, *self._jaw_motion)

    def _jaw_rows_times(self, V):
        """dX^C/dj . V (6,) for V (N,3): dX^C is zero but on the jaw rows and vertices."""
        j = self.jaw_vertices
        return np.einsum("pni,ni->p", self.dXc[self.vec.jaw][:, j], V[j])

    def _stiffness_times(self, V):
        """Element stiffness times displacements V (N,3) -> (N,3) (flesh only), summed over the
        tets on the jaw's constrained vertices: exact for a V that is zero elsewhere (dX^C/dj),
        and on those vertices for any V."""
        tets = self.sim.elements.tets[self.jaw_tets]
        z = np.einsum("tab,tb->ta", self.Ke, V[tets].reshape(len(tets), 12)).reshape(-1, 3)
        out = np.zeros((self.N, 3))
        np.add.at(out, tets.reshape(-1), z)
        return out

    def _active_matrix(self):
        """Active force per muscle (M, N, 3): d gradient / d a_m."""
        fl = self.sim.flesh
        out = np.zeros((len(self.da), self.N, 3))
        np.add.at(out, (fl.fmus[:, None], self.sim.elements.tets[fl.ftets]), fl.active_forces(self.pull))
        return out

    def rhs(self):
        """dr/dp as vertex fields (P, N, 3) (free rows are the ones that count)."""
        R = np.einsum("mni,mp->pni", self._active_matrix(), self.da)
        tr = self.ds.tracks
        R[:, tr.vertices] -= tr.stiffness[None, :, None] * self.dt
        for i in range(self.P)[self.vec.jaw]:
            R[i] += self._stiffness_times(self.dXc[i])
        R[self.vec.jaw] += self.dcontact
        return R

    def _rhs_transpose(self, mu):
        """mu . dr/dp (P,) for mu (N,3) zero on constrained vertices, without forming dr/dp."""
        g = self.sim.flesh.active_work(self.pull, mu, len(self.da)) @ self.da
        tr = self.ds.tracks
        g -= tr.target_vjp(self.res.tracks, *self._jaw_motion, tr.stiffness[:, None] * mu[tr.vertices])
        g[self.vec.jaw] += self._jaw_rows_times(self._stiffness_times(mu))
        g[self.vec.jaw] += np.einsum("pni,ni->p", self.dcontact, mu)
        return g

    # -- derivatives ------------------------------------------------------------------------
    def tangent(self):
        """dX/dp (P, N, 3): all tet vertices, from one factorisation and P right-hand sides."""
        R = self.rhs()[:, self.free].reshape(self.P, -1)
        dU = -self.res.sim.solver.solve(np.ascontiguousarray(R.T)).reshape(-1, self.P)
        dX = self.dXc.copy()
        dX[:, self.free] = dU.T.reshape(self.P, -1, 3)
        self.ds.predictor = (self.res.p, self.res.X, dX)      # the next solves' first-order start
        return dX

    def gradient(self, gX):
        """dLoss/dp (P,) for dLoss/dX = gX (N,3): one adjoint solve."""
        gX = np.asarray(gX, float)
        g = -self._rhs_transpose(_adjoint_state(self.sim, self.res.sim, gX))
        g[self.vec.jaw] += self._jaw_rows_times(gX)
        return g

    def surface_jacobian(self):
        """dx/dp (P, V, 3) of the render surface."""
        dX = self.tangent()                                  # (P, N, 3)
        P, N = dX.shape[:2]
        # one sparse product for all P columns: 3.7x faster than P products with a smooth
        # embedding's 74 weights per vertex (bench/embedding.py)
        return (self.ds.W @ dX.transpose(1, 0, 2).reshape(N, 3 * P)).reshape(-1, P, 3).transpose(1, 0, 2)

    def surface_gradient(self, gx):
        """dLoss/dp (P,) for dLoss/dx = gx (V,3) on the render surface."""
        return self.gradient(self.ds.W.T @ np.asarray(gx, float))


def cold_finite_differences(driven, p, gx, rtol=1e-10, indices=None):
    """Finite differences (P,) of L(p) = sum(gx * surface(p)) for gx (V,3), every solve from
    rest (the check of ``surface_vjp``): steps 1e-4 for the weights, 1e-5 rad
    for the jaw rotations, 1e-6 m for its translations. Central, but one-sided (second order,
    into the box, steps of 1e-5) for a weight at its lower bound 0, where the activations
    have their break (the derivative the adjoint gives there is the one into the box).
    ``indices``: only these parameters (the others are 0 in the result)."""
    vec = FitVector(driven.model.blendshape_names)
    steps = np.full(vec.P, 1e-4)
    steps[vec.jaw] = [1e-5, 1e-5, 1e-5, 1e-6, 1e-6, 1e-6]
    L = lambda q: np.sum(gx * driven.surface_of(driven.solve(q, warm=None, rtol=rtol)))
    fd = np.zeros(vec.P)
    L0 = None
    for i in range(vec.P) if indices is None else indices:
        h = steps[i]
        e = np.zeros_like(p)
        e[i] = h
        if i < vec.K and p[i] == 0.0:       # a tenth of the step: the curvature is high there
            L0 = L(p) if L0 is None else L0
            fd[i] = (-3 * L0 + 4 * L(p + 0.1 * e) - L(p + 0.2 * e)) / (0.2 * h)
        else:
            fd[i] = (L(p + e) - L(p - e)) / (2 * h)
    return fd


def activation_gradient(sim, result, gX):
    """dLoss/da (M,) at a Simulator's equilibrium (jaw and tracks held) for dLoss/dX = gX
    (N,3): one adjoint solve H mu = gX^U with the exact Newton matrix at the solution,
    then dLoss/da_m = -mu . dr/da_m, dr/da_m the active fibre forces of muscle m per unit
    activation (Eq. 4). The muscle-level gradient of paper 000 Sec. 7, without the
    blendshape-driven tracks (``Sensitivity`` has those); what the paper-scale bench times."""
    mu = _adjoint_state(sim, result, np.asarray(gX, float))
    return -sim.flesh.active_work(sim.flesh.fibre_pull(result.X), mu, len(sim.muscle_names))


def _adjoint_state(sim, result, gX):
    """mu (N,3): H mu = gX^U on the free DOFs (H the exact Newton matrix of the SimResult
    ``result``: ``SimResult.solve_adjoint``), zero on the constrained vertices."""
    mu = np.zeros_like(gX)
    mu[sim.free] = result.solve_adjoint(gX[sim.free].reshape(-1)).reshape(-1, 3)
    return mu

