"""Where a solve of ``sim.quasistatic.Simulator`` starts: the jaw-skinned guess that keeps
every tet uninverted, the Euler predictor of continuation methods from a neighbouring
equilibrium, and the lower-energy of two starts.

``WarmStarts`` is a part of ``Simulator``: its methods use the simulator's ``model``,
``elements``, ``dof_of_vertex``, ``free``, ``constrained_positions``, ``_total``, ``_factor``
and ``_solver``.
"""
from __future__ import annotations

import time

import numpy as np

from . import linsolve
from .tracks import Tracks


class WarmStarts:
    """Start states for ``Simulator.solve``: ``_start`` (skinned), ``_tangent_start``
    (predicted), ``_better_start`` (the lower energy)."""

    def _start(self, X, jaw_from, jaw_to):
        """Start state for jaw parameters jaw_to from a state X at jaw_from: the jaw-skinned
        displacement added, constrained vertices exactly placed.

        Next to a tet the state has crushed against the volume barrier the skinned guess can
        invert it (a start outside the energy's domain). The free vertices of such a tet are
        moved rigidly with the jaw instead when it has jaw-fixed vertices, else kept where
        they are, until no tet is inverted (at most 20 passes)."""
        d = self.model.skinned_volume(jaw_to) - self.model.skinned_volume(jaw_from)
        fixed = self.dof_of_vertex < 0
        d[fixed] = self.constrained_positions(jaw_to)[fixed] - X[fixed]
        step = self.model.jaw_matrix(jaw_to) @ np.linalg.inv(self.model.jaw_matrix(jaw_from))
        rigid = X @ step[:3, :3].T + step[:3, 3] - X
        on_jaw = np.zeros(len(X), bool)
        on_jaw[self.model.fixed_jaw] = True
        tets = self.elements.tets
        for _ in range(20):
            start = X + d
            bad = tets[self.elements.volumes(start) <= 0]
            if not len(bad):
                break
            jawed = np.repeat(on_jaw[bad].any(1), 4)
            v = bad.ravel()
            keep = ~fixed[v]
            d[v[keep & jawed]] = rigid[v[keep & jawed]]
            d[v[keep & ~jawed]] = 0.0
        return start

    def _tangent_start(self, X, H, here, there, secs, eps=1e-3):
        """Start state (N,3) for the inputs ``there`` = (activations, jaw, Tracks or None) from
        an equilibrium X at the inputs ``here``, with H the exact Newton matrix data at X: the
        Euler predictor of continuation methods, X^U + dX^U/dt along the straight path between
        the inputs (dX^U/dt = -H^-1 dr/dt, dr/dt by a difference of the residual over ``eps``
        of the path), the constrained vertices placed exactly. None when H is not positive
        definite or the residual is not finite."""
        (a, j, tr), (a1, j1, tr1) = here, there
        je = j + eps * (j1 - j)
        fixed = self.dof_of_vertex < 0
        Xe = X.copy()
        Xe[fixed] = self.constrained_positions(je)[fixed]
        tre = None if tr is None else Tracks(tr.vertices, tr.targets + eps * (tr1.targets - tr.targets),
                                             tr1.stiffness)
        t = time.perf_counter()
        _, g0, _ = self._total(X, a, self.model.jaw_matrix(j), tr, 1)
        _, ge, _ = self._total(Xe, a + eps * (a1 - a), self.model.jaw_matrix(je), tre, 1)
        secs["assembly"] += time.perf_counter() - t
        if g0 is None or ge is None or not np.all(np.isfinite(ge - g0)):
            return None
        t = time.perf_counter()
        try:
            self._factor(H)
        except linsolve.NotSPD:
            return None
        finally:
            secs["factor"] += time.perf_counter() - t
        t = time.perf_counter()
        dU = -self._solver.solve((ge - g0) / eps)
        secs["solve"] += time.perf_counter() - t
        out = X.copy()
        out[fixed] = self.constrained_positions(j1)[fixed]
        out[self.free] += dU.reshape(-1, 3)
        return out

    def _better_start(self, a, b, act, jaw, tracks):
        """Of two start states (b may be None), the one of lower total energy (an inverted
        one's is infinite): the nearer the target's minimum, the fewer Newton steps."""
        if b is None:
            return a
        jm = self.model.jaw_matrix(jaw)
        Ea, Eb = (self._total(x, act, jm, tracks, 0)[0] for x in (a, b))
        return b if Eb < Ea or not np.isfinite(Ea) else a
