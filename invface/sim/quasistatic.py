"""Quasistatic flesh simulation: Newton-Raphson on Eq. 3 / Eq. 6 of paper 000.

    sim = Simulator(model)                                 # set-up once per model
    res = sim.solve({"zygomaticus_major_L": 0.8}, jaw=...) # steady state X (N,3)
    res2 = sim.solve(acts2, warm=res)                      # warm start

The unknowns are the free flesh vertices X^U; cranium vertices are fixed at rest, jaw
vertices follow the 6-DOF jaw transform. The steady state zeroes the sum of FVM, collision
and track forces, i.e. it is a stationary point of the total energy

    E(X) = sum_t V_t Psi(F_t; a) + E_contacts(X; j) + sum_v k_v/2 |x_v - t_v|^2,

a C2 function of the state X and the inputs (a, j, t) alone (the contact models of sim.contact
are fixed at set-up; Psi's volume barrier makes E infinite for an inverted tet).

Each Newton step solves with the exact Hessian first: near equilibrium it converges in far
fewer steps than a matrix projected to PSD. When the factorisation fails or the step is not
a descent direction, it climbs a ladder of altered matrices (``sim.ladder.NewtonLadder``): with
contacts, the exact Hessian with the acting contacts' 12x12 Hessians projected to PSD (every
contact's Hessian is indefinite: its plane turns with the triangle), then that matrix with a
Levenberg-Marquardt shift of its diagonal, then the per-element definiteness-projected
matrix. Projecting only the contacts keeps the flesh's curvature, where a shift large enough
to cover the contacts would damp every direction; near a crushed tet a small shift converges
where the projected matrix converges only linearly, and beyond a shift of 1e-2 the projected
matrix is the faster. The next step starts one rung below the one that worked: a failed
factorisation costs as much as one that succeeds, and a step rarely succeeds on a rung below
the last one's. A
backtracking Armijo line search on E follows (it refuses inverting steps: E is infinite
there). Once a step has factorised the exact Hessian, the next steps first try conjugate
gradients on their own exact Hessian preconditioned with that factorisation (inexact Newton
steps; ``_newton_step``), and factorise only when those do not converge. When Newton
cannot reach the target from its start, the solve steps the inputs along the path from the
start's (load stepping, ``Simulator.solve``).
The exact Hessian at the solution is kept on the result; its factorisation
(``SimResult.solver``) is made on first use by the tangent solves (sim.adjoint). An adjoint
solve needs none while the solve's last factorisation of an exact Hessian is still held: it
preconditions conjugate gradients on the matrix at the solution (``SimResult.solve_adjoint``).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import InvfaceError, MeshError, SimulationError
from ..mesh.tets import face_use, mean_edge_length, tet_adjacency
from . import linsolve
from .contact import MIN_CONTACT_RADIUS, ContactSet, default_contacts
from .fem import Elements, FleshModel, Pattern
from .materials import Material
from .ladder import NewtonLadder
from .tracks import Tracks
from .warmstart import WarmStarts

@dataclass
class SimResult:
    """A converged (or reported) quasistatic state.

    X (N,3) m flesh positions; activations (M,); jaw (6,); iterations; residuals: relative
    residual per iteration; energy J; inverted: number of inverted tets; min_J: smallest
    volume ratio; seconds: wall time by phase; newton_data: the exact Newton matrix at X
    (upper CSR data over the free DOFs of the simulator's pattern); load_steps: the load
    steps the solve needed (0: Newton went straight there); tracks: the Tracks it was solved
    with.
    """
    X: np.ndarray
    activations: np.ndarray
    jaw: np.ndarray
    converged: bool
    iterations: int
    residuals: list
    energy: float
    inverted: int
    min_J: float
    seconds: dict = field(default_factory=dict)
    newton_data: np.ndarray = None
    load_steps: int = 0
    tracks: Tracks = None
    _make_solver: object = field(default=None, repr=False)
    _solver: object = field(default=None, repr=False)
    _newton_factor: tuple = field(default=None, repr=False)
    ADJOINT_CG_RTOL = 1e-6      # |b - H x| <= this |b|: the gradient's error is then the size of the
    #                             forward solve's own tolerance's effect
    ADJOINT_CG_ITER = 50        # a back-substitution each: still far below a factorisation's cost

    @property
    def solver(self):
        """The factorised exact Newton matrix at X (for tangent/adjoint solves), made on first
        use and kept. Raises SimulationError if the matrix at the solution is not positive
        definite: not a stable equilibrium, so no derivatives there (a fit rejects the point)."""
        if self._solver is None:
            s = self._make_solver()
            try:
                s.factor(self.newton_data)
            except linsolve.NotSPD as e:
                raise SimulationError(f"no derivatives at this state: {e} there, so it is not a "
                                      f"stable equilibrium ({self.report()})") from e
            self._solver = s
        return self._solver

    @property
    def factorised(self):
        """Whether this result holds a factorisation of its own (``solver`` made one)."""
        return self._solver is not None

    def solve_adjoint(self, b):
        """x (n,) with H x = b for b (n,) on the free DOFs, H the exact Newton matrix at X.

        While the simulator still holds this solve's last factorisation of an exact Hessian
        (``_newton_factor``; a step away from X, or a few when the last steps were inexact
        Newton steps on it), by conjugate gradients with that factorisation as the
        preconditioner, to |H x - b| <= ADJOINT_CG_RTOL |b|: a few back-substitutions and
        products with H, far cheaper than a factorisation of its own. Otherwise, or
        when that does not converge in ADJOINT_CG_ITER iterations or meets non-positive
        curvature, with this result's own factorisation (``solver``, which raises
        SimulationError where H is not positive definite)."""
        b = np.asarray(b, float)
        if self._solver is None and self._newton_factor is not None:
            sim, count = self._newton_factor
            if sim._factorisations == count:
                x = linsolve.preconditioned_cg(sim.pattern.matvec(self.newton_data), sim._solver.solve, b,
                                               rtol=self.ADJOINT_CG_RTOL, max_iter=self.ADJOINT_CG_ITER)
                if x is not None:
                    return x
        return self.solver.solve(b)

    def report(self):
        """One-paragraph status line for logs and errors."""
        r = self.residuals[-1] if self.residuals else float("nan")
        state = "converged" if self.converged else "did NOT converge"
        steps = f" over {self.load_steps} load steps" if self.load_steps else ""
        return (f"Newton {state} in {self.iterations} iterations{steps}: relative residual {r:.2e}, "
                f"{self.inverted} inverted tets (min volume ratio {self.min_J:.3f}), "
                f"{sum(self.seconds.values()):.2f} s")

def _check_manifold(tets):
    _, use = face_use(tets)
    if np.any(use > 2):
        n = int(round(np.sum(1.0 / use[use > 2])))     # each such triangle appears `use` times
        raise MeshError(f"the flesh tet mesh is non-manifold: {n} triangles are shared by more than two tets")
    if len(np.unique(np.sort(tets, axis=1), axis=0)) != len(tets):
        raise MeshError("the flesh tet mesh has duplicated tets")


class Simulator(NewtonLadder, WarmStarts):
    """Quasistatic muscle simulation of a FaceModel's flesh.

    material: Material constants; contact: include the face's contacts (``contact.default_contacts``:
    lips, lids and bone, eyeballs); contact_stiffness (N/m; default 50 x shear modulus x mean
    edge length); solver: 'pardiso' | 'superlu' | None; contacts: more contact models
    (``contact.ContactModel``), added to the face's. ``self.contacts`` is their ContactSet, or
    None when there are none. Its parts: the Newton loop with load stepping here, the Newton
    step's fallback ladder (``ladder.NewtonLadder``) and the start states
    (``warmstart.WarmStarts``).
    """

    def __init__(self, model, material: Material | None = None, contact=True,
                 contact_stiffness=None, solver=None, contacts=()):
        self.model = model
        self.material = material or Material()
        X0 = np.asarray(model.rest_positions, float)
        tets = np.asarray(model.tets, np.int64)
        N = len(X0)
        if not np.all(np.isfinite(X0)):
            raise MeshError("the rest flesh positions contain NaN or infinite values")
        _check_manifold(tets)
        self.elements = Elements(X0, tets)
        self.N = N
        constrained = np.zeros(N, bool)
        constrained[model.fixed_cranium] = True
        constrained[model.fixed_jaw] = True
        if constrained.all():
            raise MeshError("every flesh vertex is constrained: nothing to simulate")
        self.free = np.flatnonzero(~constrained)
        dof = np.full(N, -1, np.int64)
        dof[self.free] = np.arange(len(self.free))
        self.dof_of_vertex = dof
        # the element stiffness matrices (T,12,12) of every assembly, written into one array kept
        # between assemblies: at paper scale a new array per assembly costs more in page faults
        # than the kernel that fills it
        self._element_work = None
        # the tets on the jaw's constrained vertices: where H_UC meets dX^C/dj (sim.adjoint)
        self.jaw_tets = np.flatnonzero(np.isin(tets, model.fixed_jaw).any(1))

        self.muscle_names = [m.name for m in model.muscles]
        ft = [m.tets for m in model.muscles]
        self.flesh = FleshModel(
            self.elements, self.material,
            np.concatenate(ft) if ft else np.zeros(0, np.int64),
            np.concatenate([m.fibers for m in model.muscles]) if ft else np.zeros((0, 3)),
            np.repeat(np.arange(len(ft)), [len(t) for t in ft]))

        self.edge_length = mean_edge_length(X0, tets)
        shear = self.material.shear_modulus
        self._adjacency = None
        models = list(contacts)
        if contact:
            k = contact_stiffness or 50.0 * shear * self.edge_length
            # contacts pair and gate over 1.5 tet edges, but never less than MIN_CONTACT_RADIUS:
            # a gate that narrows with the mesh hands a sliding lip from plane to plane abruptly
            models = default_contacts(model, ~constrained, k, max(1.5 * self.edge_length, MIN_CONTACT_RADIUS),
                                      self.adjacency) + models
        self.contacts = ContactSet(models, N) if models else None
        self.pattern = Pattern(dof, tets, self.contacts.coupled_pairs() if self.contacts else None)
        self._solver_name = solver
        self._solver = self.make_solver()                                # symbolic analysis once
        self._factorisations = 0        # factorisations of _solver so far (see SimResult.solve_adjoint)
        self._exact_factor = -1         # ... the count after the last one of an exact Hessian
        # force scale for the absolute convergence floor: shear x edge^2 per vertex
        self.force_scale = shear * self.edge_length ** 2
        # the rest state's energy and Newton matrix: a check, and the compiled kernels loaded and
        # their thread pool started here (0.2 s once per process), not in the first solve
        E, _, _ = self._total(X0, np.zeros(len(self.muscle_names)), np.eye(4), None, 2)
        if not np.isfinite(E):        # Elements has refused inverted and degenerate tets already
            raise InvfaceError(f"the rest state's energy is {E}: check the material constants "
                               f"{self.material.as_dict()}")

    # -- inputs ---------------------------------------------------------------------------
    def activation_vector(self, activations):
        """Validated activations (M,) from a dict name -> a, an array (M,), or None (zeros)."""
        M = len(self.muscle_names)
        if activations is None:
            return np.zeros(M)
        if isinstance(activations, dict):
            a = np.zeros(M)
            index = {n: i for i, n in enumerate(self.muscle_names)}
            for name, value in activations.items():
                if name not in index:
                    raise InvfaceError(f"unknown muscle {name!r}; the model's muscles are: "
                                       + ", ".join(self.muscle_names))
                a[index[name]] = _scalar(value, name)
        else:
            a = np.asarray(activations, float).reshape(-1)
            if a.shape != (M,):
                raise InvfaceError(f"activations: expected {M} values (one per muscle), got {a.size}")
        for i in np.flatnonzero(~np.isfinite(a)):
            raise InvfaceError(f"activation of {self.muscle_names[i]} is {a[i]} (must be a number in [0, 1])")
        for i, m in enumerate(self.model.muscles):
            lo, hi = m.activation_curve[:, 1].min(), m.activation_curve[:, 1].max()
            if not (lo - 1e-12 <= a[i] <= hi + 1e-12):
                raise InvfaceError(f"activation of {m.name} is {a[i]:g}, outside its activation curve's "
                                   f"range [{lo:g}, {hi:g}]")
        return a

    @property
    def adjacency(self):
        """The tet mesh's vertex connectivity (N,N) sparse, nonzero where two vertices share a
        tet: the contacts' pair filter and the contact-region test use it. Built on first use."""
        if self._adjacency is None:
            self._adjacency = tet_adjacency(self.elements.tets, self.N)
        return self._adjacency

    def constrained_positions(self, jaw):
        """Rest positions with the jaw vertices moved by the jaw transform (N,3); jaw (6,)."""
        jaw = _jaw_vector(jaw)
        X = self.model.rest_positions.astype(float).copy()
        M = self.model.jaw_matrix(jaw)
        j = self.model.fixed_jaw
        X[j] = X[j] @ M[:3, :3].T + M[:3, 3]
        return X

    # -- energy -----------------------------------------------------------------------------
    def _total(self, X, act, jm, tracks, order, project=False):
        """Total energy, free-DOF gradient and Newton matrix data at X for activations act,
        jaw transform jm (4,4) (the bone contacts' planes) and tracks."""
        if order == 2 and self._element_work is None:
            self._element_work = np.empty((len(self.elements.tets), 12, 12))
        E, g_nodes, Ke = self.flesh.evaluate(X, act, order, project, self._element_work)      # Ke: order 2 only
        col = self.contacts
        if col is not None:
            E += col.energy(X, jm)
        if tracks is not None:
            E += tracks.energy(X)
        if order == 0 or not np.isfinite(E):
            return E, None, None
        g = self.pattern.scatter(g_nodes)
        gv = col.gradient(X, jm) if col is not None else np.zeros((self.N, 3))
        if tracks is not None:
            np.add.at(gv, tracks.vertices, tracks.gradient(X))
        g += gv[self.free].reshape(-1)
        if order == 1:
            return E, g, None
        blocks = col.blocks(X, jm, project) if col is not None else []
        if tracks is not None:
            blocks.append(tracks.blocks())
        return E, g, self.pattern.assemble(Ke, blocks)

    def energy(self, X, activations=None, tracks=None, jaw=None, order=1):
        """Total energy (J), free-DOF gradient and Newton matrix data (upper CSR) at X (N,3)
        for activations, tracks and jaw parameters (6,) (the jaw's contact planes)."""
        act = self.activation_vector(activations)
        return self._total(np.asarray(X, float), act, self.model.jaw_matrix(_jaw_vector(jaw)), tracks, order)

    def make_solver(self):
        """A new solver for this simulator's sparsity pattern (symbolic analysis done)."""
        return linsolve.make_solver(self.pattern, self._solver_name)

    # -- Newton -----------------------------------------------------------------------------
    def solve(self, activations=None, jaw=None, tracks=None, warm=None, rtol=1e-6,
              max_iter=80, raise_on_failure=True, progress=None, guess=None):
        """Steady state for muscle activations (dict or (M,)), jaw parameters (6,), optional
        Tracks (Eq. 5), warm start from a previous SimResult, and a guess (N,3) m of the
        state (its constrained vertices are placed exactly; Newton starts from it when it is
        lower in energy than the warm start). Returns a SimResult.

        Converged when the free-DOF residual |f| <= rtol * force scale * sqrt(DOFs) (force
        scale: shear modulus x edge length^2 per DOF), wherever the solve started: a residual
        measured against the start's would call a cold solve converged far from equilibrium.

        Newton goes straight to the target from the warm state (or the jaw-skinned rest
        state). If that fails, the solve follows the straight path from the start's inputs
        (the warm result's, or rest) to the target's in load steps: each step is Newton-solved
        from the previous step's state moved by the Euler predictor (``_tangent_start``) or by
        the jaw skinning, whichever is lower in energy; a failed step is halved and a good one doubles the
        next, down to 1/``MIN_STEP`` of the path. The energy is a function of the state and
        the inputs alone, so the equilibrium reached does not depend on the path taken
        (up to the Newton tolerance) as long as it is the same local minimum.
        """
        t_all = time.perf_counter()
        first_factor = self._factorisations
        act = self.activation_vector(activations)
        jaw = _jaw_vector(jaw)
        secs = {"assembly": 0.0, "factor": 0.0, "solve": 0.0, "line_search": 0.0}
        if warm is not None:
            X0, a0, j0 = warm.X, warm.activations, warm.jaw
            T0 = warm.tracks.targets if _same_tracks(warm.tracks, tracks) else None
        else:
            X0, a0, j0, T0 = self.model.rest_positions.astype(float), np.zeros_like(act), np.zeros(6), None
        if tracks is not None and T0 is None:
            T0 = X0[tracks.vertices]
        start = self._start(X0, j0, jaw)
        if guess is not None:
            fixed = self.dof_of_vertex < 0
            guess = np.array(guess, float)
            guess[fixed] = start[fixed]
            start = self._better_start(start, guess, act, jaw, tracks)
        out = self._newton(start, act, jaw, tracks, rtol, max_iter, progress, secs)
        steps, total = 0, out[2]
        if not out[1]:

            def inputs(t):
                tr = None if tracks is None else Tracks(tracks.vertices, T0 + t * (tracks.targets - T0),
                                                        tracks.stiffness)
                return a0 + t * (act - a0), j0 + t * (jaw - j0), tr

            X, t, h = X0, 0.0, 0.5
            H = warm.newton_data if warm is not None and warm.converged else None
            while h >= 1.0 / self.MIN_STEP:
                t1 = min(1.0, t + h)
                here, there = inputs(t), inputs(t1)
                a_t, j_t, tr = there
                start = self._start(X, here[1], j_t)
                if H is not None:
                    start = self._better_start(start, self._tangent_start(X, H, here, there, secs), a_t, j_t, tr)
                step = self._newton(start, a_t, j_t, tr, rtol if t1 == 1.0 else 1e-4,
                                    max_iter, progress, secs)
                steps, total = steps + 1, total + step[2]
                if step[1]:
                    X, t, h, H = step[0], t1, 2 * h, step[5]
                    if t1 == 1.0:
                        out = step
                        break
                else:
                    if t1 == 1.0 and _closer(step, out):
                        out = step           # a failure reports the closest attempt at the target
                    h = (t1 - t) / 2         # not h / 2: t + h may overshoot the target
        X, converged, _, residuals, E, data = out
        vols = self.elements.volumes(X) / self.elements.volume
        res = SimResult(X=X, activations=act, jaw=jaw, converged=converged, iterations=total,
                        residuals=residuals, energy=float(E), inverted=int((vols <= 0).sum()),
                        min_J=float(vols.min()), seconds=secs, newton_data=data, load_steps=steps,
                        tracks=tracks, _make_solver=self.make_solver)
        if converged and first_factor < self._exact_factor == self._factorisations:
            res._newton_factor = (self, self._factorisations)     # this solve's last exact factorisation
        secs["other"] = time.perf_counter() - t_all - sum(secs.values())
        if not converged and raise_on_failure:
            raise SimulationError(res.report())
        return res

    MIN_STEP = 64           # the smallest load step is 1/64 of the path from start to target
    STALL = 40              # Newton is stalled after this many iterations without halving the residual in 5

    def _newton(self, X, act, jaw, tracks, rtol, max_iter, progress, secs):
        """Newton from X: (X, converged, iterations, relative residuals, energy, matrix data).

        Stops early when stalled: after STALL iterations, a residual above half the one five
        iterations before (a state the line search cannot leave; load stepping takes over)."""
        jm = self.model.jaw_matrix(jaw)
        residuals, ref, data = [], None, None
        converged, it, E, memory = False, 0, np.inf, [0, None]
        while True:
            t = time.perf_counter()
            E, g, data = self._total(X, act, jm, tracks, 2)
            secs["assembly"] += time.perf_counter() - t
            if not np.isfinite(E):          # an inverted start: outside the energy's domain
                break
            r = float(np.linalg.norm(g))
            if ref is None:
                ref = self.force_scale * np.sqrt(len(g))
            residuals.append(r / ref)
            if progress:
                progress(it, r / ref)
            if not np.isfinite(r):
                break
            if r <= rtol * ref:
                converged = True
            stalled = it >= self.STALL and residuals[-1] > 0.5 * residuals[-6]
            if converged or stalled or it >= max_iter:
                break
            it += 1
            dx = self._newton_step(X, act, jm, tracks, data, g, secs, memory)
            t = time.perf_counter()
            X = self._line_search(X, dx, E, g, act, jm, tracks)
            secs["line_search"] += time.perf_counter() - t
        return X, converged, it, residuals, E, data

    def _line_search(self, X, dx, E, g, act, jm, tracks):
        """Backtracking Armijo on the energy (infinite for an inverted tet, so a step that
        inverts one is refused); near convergence, where the energy decrease is below its
        round-off, the longest step that reduces the residual."""
        step = np.zeros_like(X)
        step[self.free] = dx.reshape(-1, 3)
        slope = float(dx @ g)
        alpha = 1.0
        for _ in range(40 if -slope > 1e-9 * abs(E) else 0):
            Xn = X + alpha * step
            En, _, _ = self._total(Xn, act, jm, tracks, 0)
            if np.isfinite(En) and En <= E + 1e-4 * alpha * slope:
                return Xn
            alpha *= 0.5
        r0 = np.linalg.norm(g)
        alpha = 1.0
        for _ in range(12):
            Xn = X + alpha * step
            En, gn, _ = self._total(Xn, act, jm, tracks, 1)
            if np.isfinite(En) and np.linalg.norm(gn) < r0:
                return Xn
            alpha *= 0.5
        return X

    def volume_change(self, result):
        """Relative change of the total flesh volume of a SimResult (dimensionless)."""
        return float(self.elements.volumes(result.X).sum() / self.elements.volume.sum() - 1)

    def surface(self, result):
        """Render-surface vertices (V,3) of a SimResult through the model's embedding."""
        return self.model.embedded_surface(result.X)

def _closer(a, b):
    """Whether Newton outcome a ended nearer equilibrium than b (an inverted start, with no
    residual, is the farthest)."""
    return bool(a[3]) and (not b[3] or a[3][-1] < b[3][-1])

def _scalar(value, name):
    try:
        return float(value)
    except (TypeError, ValueError):
        raise InvfaceError(f"activation of {name} must be a number, got {value!r}") from None

def _same_tracks(a, b):
    """Whether two Tracks (or None) act on the same vertices."""
    return a is not None and b is not None and np.array_equal(a.vertices, b.vertices)

def _jaw_vector(jaw):
    if jaw is None:
        return np.zeros(6)
    j = np.asarray(jaw, float).reshape(-1)
    if j.shape != (6,) or not np.all(np.isfinite(j)):
        raise InvfaceError(f"jaw parameters must be 6 finite numbers (3 rotations rad, 3 translations m), got {jaw!r}")
    return j
