"""The Newton step's fallback ladder of ``sim.quasistatic.Simulator`` (its module docstring
tells the method): inexact steps on a held factorisation, then the exact Hessian, the
contact-projected one with Levenberg-Marquardt shifts and the element-projected one, each
tried until one factors and descends, starting one rung below the last that worked.

``NewtonLadder`` is a part of ``Simulator``: its methods use the simulator's sparsity
``pattern``, linear ``_solver`` (and ``_solver_name``), ``contacts`` (a ContactSet or None),
``_total`` (energy, gradient and Newton matrix data), ``force_scale``, ``adjacency``,
``dof_of_vertex``, ``N`` and the factorisation counters ``_factorisations`` and
``_exact_factor``.
"""
from __future__ import annotations

import time

import numpy as np

from . import linsolve


class NewtonLadder:
    """Newton directions for ``Simulator._newton`` (``_newton_step``) and the matrices the
    fallback tries (``_ladder``)."""

    SHIFTS = (1e-3, 1e-2)       # Levenberg-Marquardt shifts of the exact Hessian (no contacts): smaller
    #                             ones do not factor where the exact Hessian fails, larger ones damp every
    #                             direction (bench/cold_solves.py measures them)
    CONTACT_SHIFTS = (1e-2,)    # ... of the contact-projected one: a smaller shift first only adds
    #                             failed factorisations

    def _ladder(self):
        """Newton matrices in the order the fallback tries them, least altered first: (kind,
        Levenberg-Marquardt shift mu) with kind 'exact', 'contacts' (the acting contacts'
        Hessians projected to PSD, the flesh's exact) or 'projected' (every element's)."""
        if self.contacts is None:
            shifts = [("exact", mu) for mu in self.SHIFTS]
        else:
            shifts = [("contacts", 0.0)] + [("contacts", mu) for mu in self.CONTACT_SHIFTS]
        return [("exact", 0.0)] + shifts + [("projected", 0.0)]

    CG_GATE = 1e-2              # see _newton_step
    EXACT_BELOW = 1e-1          # with contacts, the exact Hessian only below this relative residual
    CG_RTOL, CG_ITER = 1e-2, 8   # Newton steps by conjugate gradients on a held factorisation: see _newton_step

    def _newton_step(self, X, act, jm, tracks, data, g, secs, memory):
        """Newton direction for the exact Hessian data (nnz,) and gradient g (n,).

        First, while the solver holds this Newton run's factorisation of an earlier step's
        exact Hessian (``memory[1]``, that Hessian's data; ``_exact_factor`` still the latest
        factorisation) and this Hessian is within CG_GATE of it (|H - H_held| <= CG_GATE
        |H_held| over the upper triangle's entries): conjugate gradients on the exact Hessian preconditioned
        with it, to |H dx + g| <= eta |g| with the forcing term eta = min(CG_RTOL, the
        relative residual), in at most CG_ITER iterations, a back-substitution and a product
        with H each (an inexact Newton step: a factorisation costs many such iterations, the
        more the larger the mesh). Beyond the gate contacts have switched and the tries mostly
        fail, so they are not made. Else, or when
        they do not converge or meet non-positive curvature: the first matrix of ``_ladder``
        that factors and gives a descent direction, starting one rung below the one that
        worked last step (``memory[0]``), and with contacts never at the exact Hessian while
        the relative residual is above EXACT_BELOW: far from equilibrium, while contacts
        switch, the exact Hessian is often not positive definite, and PARDISO finds that out
        only near the end of a factorisation. Nor, with contacts, where its submatrix around
        the acting contacts is not positive
        definite (``_contact_region_indefinite``: a proof that its factorisation would fail). A
        shifted matrix is M + mu diag|H| with H the exact Hessian. When none works (a singular
        projected matrix), a scaled gradient step."""
        diag = self.pattern.diag_slot
        relative = float(np.linalg.norm(g)) / (self.force_scale * np.sqrt(len(g)))
        dx = self._held_factor_step(data, g, relative, secs, memory)
        if dx is not None:
            return dx
        base = {"exact": data}

        def matrix(kind):
            if kind not in base:
                t = time.perf_counter()
                if kind == "contacts":
                    base[kind] = data + self._contact_projection(X, jm)
                else:
                    base[kind] = self._total(X, act, jm, tracks, 2, project=True)[2]
                secs["assembly"] += time.perf_counter() - t
            return base[kind]

        ladder = self._ladder()
        first = max(memory[0] - 1, 0)
        if self.contacts is not None and relative > self.EXACT_BELOW:
            first = max(first, 1)                   # far from equilibrium: not the exact Hessian
        for rung in range(first, len(ladder)):
            kind, mu = ladder[rung]
            values = matrix(kind)
            if mu:
                values = values.copy()
                values[diag] += mu * np.abs(data[diag])
            if kind == "exact" and self.contacts is not None:
                t = time.perf_counter()
                indefinite = self._contact_region_indefinite(X, jm, values)
                secs["factor"] += time.perf_counter() - t
                if indefinite:
                    continue
            dx = self._factored_direction(values, g, secs)
            if dx is not None:
                memory[0] = rung
                if rung == 0:
                    self._exact_factor, memory[1] = self._factorisations, data
                return dx
        memory[0] = len(ladder)
        return -g / (np.abs(base["projected"][diag]).max() + 1e-30)

    def _held_factor_step(self, data, g, relative, secs, memory):
        """``_newton_step``'s inexact step: conjugate gradients on the exact Hessian (data
        (nnz,)) preconditioned with the held factorisation, to the forcing term min(CG_RTOL,
        ``relative``), when that factorisation is the solver's latest and its Hessian
        (``memory[1]``) is within CG_GATE of this one; None when not tried, not converged or
        not a descent direction."""
        if not (memory[1] is not None and self._exact_factor == self._factorisations and (
                np.linalg.norm(data - memory[1]) <= self.CG_GATE * np.linalg.norm(memory[1]))):
            return None
        t = time.perf_counter()
        dx = linsolve.preconditioned_cg(self.pattern.matvec(data), self._solver.solve, -g,
                                        rtol=min(self.CG_RTOL, relative), max_iter=self.CG_ITER)
        secs["solve"] += time.perf_counter() - t
        return dx if dx is not None and dx @ g < 0 else None

    def _factored_direction(self, values, g, secs):
        """-M^-1 g with M (data ``values``) factored; None when M is not positive definite or
        the direction does not descend."""
        t = time.perf_counter()
        try:
            self._factor(values)
        except linsolve.NotSPD:
            secs["factor"] += time.perf_counter() - t
            return None
        secs["factor"] += time.perf_counter() - t
        t = time.perf_counter()
        dx = -self._solver.solve(g)
        secs["solve"] += time.perf_counter() - t
        return dx if dx @ g < 0 else None

    CONTACT_RINGS = 4           # see _contact_region_indefinite
    REGION_FRACTION = 0.1       # ... and the largest region, as a fraction of the DOFs, it tests

    def _contact_region_indefinite(self, X, jm, values):
        """True when the Newton matrix data (nnz,) restricted to the flesh vertices of the
        contacts acting at X (N,3) (jaw transform jm (4,4)), grown by CONTACT_RINGS rings of
        tet neighbours, is not positive definite. It is a principal submatrix, so then neither
        is the whole matrix, and factorising that would fail: the ladder skips the exact
        Hessian without paying for it. Where contacts switch, their unprojected Hessians are
        what makes the exact Hessian indefinite, near them. The test pays where the region is
        a small part of a large mesh; regions over REGION_FRACTION of the DOFs are not tested
        (False): there a test costs a good part of the factorisation it would spare."""
        verts = self.contacts.acting_vertices(X, jm)
        if len(verts) == 0:
            return False
        region = np.zeros(self.N)
        region[verts] = 1.0
        for _ in range(self.CONTACT_RINGS):
            region = self.adjacency @ region
        dof = self.dof_of_vertex[region > 0]
        dof = dof[dof >= 0]
        if 3 * len(dof) > self.REGION_FRACTION * self.pattern.n:
            return False
        idx = (3 * dof[:, None] + np.arange(3)).ravel()          # ascending: rows <= columns stay so
        S = self.pattern.matrix(values)[idx][:, idx]               # the submatrix's upper triangle
        pattern = linsolve.MatrixPattern(S)
        try:
            linsolve.make_solver(pattern, self._solver_name).factor(pattern.values(S))
        except linsolve.NotSPD:
            return True
        return False

    def _factor(self, values):
        """Factorise Newton matrix data (nnz,) into ``_solver`` (raises linsolve.NotSPD)."""
        self._factorisations += 1
        self._solver.factor(values)

    def _contact_projection(self, X, jm):
        """Newton matrix data (nnz,) to add to the exact matrix to project each acting
        contact's Hessian to PSD (the flesh's terms stay exact)."""
        return self.pattern.assemble(None, self.contacts.projection_blocks(X, jm))
