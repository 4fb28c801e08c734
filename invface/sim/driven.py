"""The blendshape-driven muscle simulation x(w) of paper 000 Sec. 6: controls -> surface.

    ds = DrivenSimulation(model)
    r = ds.solve(p)              # p = (b (K,), jaw (6,)): tracks, activations, quasistatics
    x = ds.surface(p)            # render-surface vertices (V,3), warm-started from the last solve

Given blendshape weights b and jaw parameters j, the muscle track targets M_m(b, j) (Eq. 7)
and centre-lines C_m(b, j) (Eq. 8) follow from the Poisson precompute (sim.poisson), the
centre-line lengths (Eq. 9) give the activations a_m(L_m), the jaw gives the constrained
vertices X^C(j), and Eq. 6 (FVM + contacts + tracks) is solved for X^U by Newton.
Derivatives with respect to p are in sim.adjoint.
"""
from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np

from ..model.rig import JAW_NAMES, split_parameters
from .poisson import track_displacements
from .quasistatic import SimResult, SimulationError, Simulator
from .tracks import MuscleTracks, TrackState


# track springs' stiffness over (shear modulus x mean edge length): stiff enough that the
# flesh follows sculpted shapes that no activation of the model's muscles makes exactly
# (bench/arkit_shapes.py), soft enough that contacts and the flesh's volume still act
TRACK_STIFFNESS = 8.0


@dataclass
class DrivenResult:
    """A solved state: parameters p (K+6,), the track state (Eq. 7-9) and the SimResult."""
    p: np.ndarray
    tracks: TrackState
    sim: SimResult
    _sensitivity: object = field(default=None, repr=False)

    @property
    def X(self):
        return self.sim.X


class DrivenSimulation:
    """x(w) by simulation for a FaceModel (parameters: the model's blendshapes, then the jaw).

    track_stiffness: N/m per track vertex (default ``TRACK_STIFFNESS`` x shear modulus x mean
    edge length);
    other arguments as ``Simulator``. The Poisson displacements come from the model's bundle
    (``track_displacements``) or are computed here when it has none.
    """

    def __init__(self, model, material=None, track_stiffness=None, contact=True,
                 contact_stiffness=None, solver=None, contacts=()):
        self.model = model
        self.sim = Simulator(model, material, contact, contact_stiffness, solver, contacts)
        dX = model.track_displacements
        K, N = len(model.blendshape_names), len(model.rest_positions)
        if dX is None or np.shape(dX) != (K, N, 3):
            dX = track_displacements(model)
        k = track_stiffness if track_stiffness is not None else \
            TRACK_STIFFNESS * self.sim.material.shear_modulus * self.sim.edge_length
        self.tracks = MuscleTracks(model, dX, self.sim.dof_of_vertex >= 0, k)
        self.parameter_names = list(model.blendshape_names) + JAW_NAMES
        self.n_blendshapes = K
        self.W = model.embedding_matrix()
        self.last = None
        # (p (P,), X (N,3), dX/dp (P,N,3)) of the last tangent solve (sim.adjoint): a solve
        # near it starts from the first-order prediction when that is lower in energy
        self.predictor = None
        self.solved = set()        # parameter vectors (bytes) solved before: see result_at
        self.counts = {"solves": 0, "newton_iterations": 0}    # work done so far, for the fits' records
        self.start = "last"        # where new solves start: see result_at

    def split(self, p):
        """(b (K,), jaw (6,)) from a parameter vector p (K+6,); validates it."""
        return split_parameters(p, self.parameter_names, self.n_blendshapes)

    def solve(self, p, warm="last", **kw):
        """DrivenResult for parameters p. warm: 'last' (the previous solve), a DrivenResult or
        None (cold, from the jaw-skinned rest state); a warm solve also tries the first-order
        prediction from the last tangent solve (``predictor``), whichever start is lower in
        energy. Other keywords go to Simulator.solve."""
        b, jaw = self.split(p)
        state = self.tracks.evaluate(b, self.model.jaw_matrix(jaw))
        if isinstance(warm, str):
            warm = self.last
        guess = None
        if warm is not None and self.predictor is not None:
            p0, X0, dX = self.predictor
            guess = X0 + np.tensordot(np.asarray(p, float) - p0, dX, axes=1)
        res = self.sim.solve(state.activations, jaw, tracks=self.tracks.springs(state),
                             warm=warm.sim if warm is not None else None, guess=guess, **kw)
        out = DrivenResult(np.asarray(p, float).copy(), state, res)
        self.counts["solves"] += 1
        self.counts["newton_iterations"] += int(res.iterations)
        self.last = out
        self.solved.add(out.p.tobytes())
        return out

    def surface_of(self, result):
        """Render-surface vertices (V,3) of a DrivenResult."""
        return self.W @ result.X

    def surface(self, p):
        """Render-surface vertices (V,3) m for parameters p (warm-started; no new solve when p
        is the last one)."""
        return self.surface_of(self.result_at(p))

    def result_at(self, p):
        """The DrivenResult at p: the last one when p is unchanged, else a new solve, warm
        from the last one (``start = "last"``) or cold, from rest (``"rest"``). Either way
        the surface is a function of p alone, to the Newton tolerance (the energy is a function
        of the state and p, sim.contact).

        A warm solve at a p that was solved before and does not converge now is tried again
        from rest: a fit coming back to its accepted point after rejected trials starts from
        the last rejected state (at the end of an ICT jawOpen fit Newton stalled there at a
        relative residual of 2e-6). A p never solved is not retried: a fit's trial that the
        simulation cannot reach is rejected at the cost of one solve."""
        p = np.asarray(p, float).reshape(-1)
        if self.last is not None and np.array_equal(self.last.p, p):
            return self.last
        if self.start == "rest":
            return self.solve(p, warm=None)
        try:
            return self.solve(p, warm="last")
        except SimulationError:
            if p.tobytes() not in self.solved:
                raise
            return self.solve(p, warm=None)

    @contextmanager
    def starting_from(self, start):
        """Context in which new solves start from ``start``: "last" or "rest"."""
        if start not in ("last", "rest"):
            raise ValueError(f"start must be 'last' or 'rest', got {start!r}")
        old, self.start = self.start, start
        try:
            yield self
        finally:
            self.start = old

    def sensitivity(self, p):
        """sim.adjoint.Sensitivity at p (reuses the last solve when p is unchanged)."""
        from .adjoint import Sensitivity
        r = self.result_at(p)
        if r._sensitivity is None:
            r._sensitivity = Sensitivity(self, r)
        return r._sensitivity

    def surface_jacobian(self, p):
        """dx/dp (P, V, 3) by tangent solves (one factorisation, P right-hand sides)."""
        return self.sensitivity(p).surface_jacobian()

    def surface_vjp(self, p, gx):
        """dLoss/dp (P,) for dLoss/dx = gx (V,3): one adjoint solve."""
        return self.sensitivity(p).surface_gradient(gx)
