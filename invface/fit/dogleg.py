"""Powell's dogleg trust-region method for nonlinear least squares, with box constraints.

    result = dogleg(fun, x0, lower, upper)      # fun(x) -> (r (m,), J (m, n))
                                                #     or a NormalEquations

Minimises 0.5 |r(x)|^2 (paper 000 fits Eq. 12-16 with Chumpy's dogleg). Each step combines
the Gauss-Newton step (J^T J p = -J^T r) and the Cauchy point inside a trust region; the
region grows after good steps and shrinks after poor ones, by the ratio of actual to
predicted decrease. Only the normal equations (cost, g = J^T r, H = J^T J: n x n) are used,
so a residual with millions of rows (an image pyramid) can hand them over directly, and a
trial point that is rejected never computes its derivatives (``NormalEquations`` may be
lazy). A trial point where the model cannot be evaluated (the simulation raises
SimulationError) is a rejected step: the trust radius shrinks.

Box constraints (blendshape weights in [0, 1]): the Gauss-Newton step is the bounded
least-squares solution inside the box (a projected unconstrained step stalls where the box
cuts it: a plate's curve fit crawled 2e-5 per iteration for 200 iterations), and the Cauchy
point is taken along the projected gradient of the variables free to move; the dogleg path
between them stays in the box.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError, SimulationError


@dataclass
class DoglegResult:
    """x (n,), cost 0.5|r|^2, iterations, why it stopped, and the per-iteration log."""

    x: np.ndarray
    cost: float
    iterations: int
    status: str
    history: list = field(default_factory=list)


class NormalEquations:
    """0.5 |r|^2 and its Gauss-Newton pieces at one point: ``cost``, ``gradient`` g = J^T r
    (n,) and ``hessian`` H = J^T J (n, n). ``derivatives`` (a callable returning (g, H)) is
    called on first use, so a rejected trial point costs only its residual. Or, split:
    ``gradient_fn()`` -> g and ``hessian_fn(free)`` -> H, exact on the rows and columns of
    the variables ``free`` (n,) bool and anything finite elsewhere: ``hessian_on(free)``,
    which the dogleg asks for with the variables not held at a bound (their columns would
    multiply zero steps), so a costly H is made only for the variables that can move.
    (Any object with ``cost``, ``gradient`` and ``hessian`` will do.)"""

    def __init__(self, cost, gradient=None, hessian=None, derivatives=None, gradient_fn=None, hessian_fn=None):
        self.cost = float(cost)
        self._g, self._H, self._derivatives = gradient, hessian, derivatives
        self._gradient_fn, self._hessian_fn, self._free = gradient_fn, hessian_fn, None

    @classmethod
    def from_residuals(cls, r, J):
        r, J = np.asarray(r, float), np.asarray(J, float)
        return cls(0.5 * float(r @ r), J.T @ r, J.T @ J)

    def _ensure(self):
        if self._g is None and self._gradient_fn is not None:
            self._g, self._gradient_fn = self._gradient_fn(), None
        if self._g is None or (self._H is None and self._hessian_fn is None):
            self._g, self._H = self._derivatives()
            self._derivatives = None

    @property
    def gradient(self):
        if self._g is None:
            self._ensure()
        return self._g

    @property
    def hessian(self):
        return self.hessian_on(None)

    def hessian_on(self, free):
        """H, exact at least on the rows and columns of ``free`` (n,) bool (None: all)."""
        self.gradient
        if self._hessian_fn is None:
            return self._H
        free = np.ones(len(self._g), bool) if free is None else np.asarray(free, bool)
        if self._H is None or np.any(free & ~self._free):
            self._H, self._free = self._hessian_fn(free), free.copy()
        return self._H


def _box_gauss_newton(H, g, lo, hi, free):
    """Gauss-Newton step p for g.p + p.H.p/2 inside lo <= p <= hi (offsets from x), by an
    active set: solve for the free variables, hold at its bound each one the solution
    would carry out of the box, solve again for the rest (a projected step whose clipped
    variables were solved as if they moved stalls: a plate's curve fit crawled 2e-5 per
    iteration for 200 iterations)."""
    n = len(g)
    free = free & (lo < hi)
    p = np.zeros(n)
    for _ in range(n):
        if not free.any():
            return p
        f = np.flatnonzero(free)
        Hf = H[np.ix_(f, f)]
        # rhs: the held variables sit at their bound offsets (p[~free])
        rhs = -(g[f] + H[np.ix_(f, np.flatnonzero(~free))] @ p[~free])
        reg = 1e-12 * max(np.trace(Hf) / len(f), 1e-300) * np.eye(len(f))
        try:
            q = np.linalg.solve(Hf + reg, rhs)
        except np.linalg.LinAlgError:
            q = np.linalg.lstsq(Hf, rhs, rcond=None)[0]
        out = (q < lo[f]) | (q > hi[f])
        p[f] = np.clip(q, lo[f], hi[f])
        if not out.any():
            return p
        free[f[out]] = False
    return p


def _box_dogleg_step(H, g, free, lo, hi, radius):
    """Dogleg step inside the box lo <= p <= hi and the trust radius: the bounded
    Gauss-Newton step when it fits, else the path from the projected Cauchy point towards
    it (both ends are in the box, so is the path)."""
    p_gn = _box_gauss_newton(H, g, lo, hi, free)
    if np.linalg.norm(p_gn) <= radius:
        return p_gn
    gf = np.where(free, g, 0.0)
    step = min(radius / np.linalg.norm(gf), (gf @ gf) / max(gf @ H @ gf, 1e-300))
    p_sd = np.clip(-step * gf, lo, hi)
    if np.linalg.norm(p_sd) >= radius:
        return radius * p_sd / np.linalg.norm(p_sd)
    d = p_gn - p_sd                      # |p_sd + tau d| = radius
    a, b, c = d @ d, 2 * p_sd @ d, p_sd @ p_sd - radius ** 2
    tau = (-b + np.sqrt(max(b * b - 4 * a * c, 0))) / (2 * a)
    return p_sd + tau * d


class LinearTerm:
    """NormalEquations ``ne`` plus the linear term c . x at x: cost + c . x, gradient + c, the
    same H (an L1 penalty on variables bounded below by 0, where |x| = x)."""

    def __init__(self, ne, c, x):
        self.ne, self.c = ne, c
        self.cost = ne.cost + float(c @ x)

    @property
    def gradient(self):
        return self.ne.gradient + self.c

    @property
    def hessian(self):
        return self.ne.hessian

    def hessian_on(self, free):
        return self.ne.hessian_on(free) if hasattr(self.ne, "hessian_on") else self.ne.hessian


def with_linear_term(fun, c):
    """``fun`` (as ``dogleg`` takes it) with c . x (c (n,)) added to its cost."""
    c = np.asarray(c, float)
    return lambda x: LinearTerm(_evaluate(fun, x), c, np.asarray(x, float))


def _evaluate(fun, x):
    out = fun(x)
    return NormalEquations.from_residuals(*out) if isinstance(out, tuple) else out


def _bounds(n, lower, upper):
    """(lo, hi) (n,) arrays of the box (None: unbounded); a crossed box is a ConfigError."""
    lo = np.full(n, -np.inf) if lower is None else np.broadcast_to(np.asarray(lower, float), n)
    hi = np.full(n, np.inf) if upper is None else np.broadcast_to(np.asarray(upper, float), n)
    if np.any(lo > hi):
        raise ConfigError("dogleg: a lower bound exceeds its upper bound")
    return lo, hi


def _trial(fun, x):
    """(NormalEquations, cost) at a trial point; (None, inf) where the model cannot reach it
    (a SimulationError), so the step is rejected and the radius shrinks."""
    try:
        ne = _evaluate(fun, x)
    except SimulationError:
        return None, np.inf
    return ne, ne.cost


def _curvature_scale(mu, g, p, pHp, actual):
    """``dogleg``'s adapt_curvature rule: the next mu from the measured curvature along the
    step ``p`` relative to H (pHp = p.H.p without mu), c = 2 (-g.p - actual) / pHp, as the
    geometric mean of mu and c, in [max(0.05, mu / 2), 1]; mu unchanged where pHp <= 0."""
    if pHp <= 0:
        return mu
    c = 2 * (-(g @ p) - actual) / pHp
    # c <= 0: the cost fell at least as fast as its slope said, the model's curvature is too
    # high along p by more than any c > 0 would say: mu falls by the most allowed
    return float(np.clip(np.sqrt(mu * c) if c > 0 else 0.0, max(0.05, 0.5 * mu), 1.0))


def _new_radius(radius, rho, step):
    """The trust radius after a step of length ``step`` whose actual / predicted decrease is
    ``rho``: a quarter of the step below 0.25, doubled above 0.75 at the boundary."""
    if rho < 0.25:
        return 0.25 * step
    if rho > 0.75 and step >= 0.9 * radius:
        return 2 * radius
    return radius


def dogleg(fun, x0, lower=None, upper=None, max_iter=50, radius=1.0, ftol=1e-10, xtol=1e-8,
           gtol=1e-12, min_radius=0.0, adapt_curvature=False, progress=None):
    """Minimise 0.5 |r(x)|^2 with ``fun(x) -> (r, J)`` or ``-> NormalEquations``,
    lower <= x <= upper (None: unbounded).

    adapt_curvature: use mu H for the model's curvature, with mu in [0.05, 1] measured after
    every step as the objective's curvature along the step relative to H,
    c = 2 (-g.p - actual decrease) / p.H.p (exact for a quadratic, as g is exact), and
    mu the geometric mean of its last value and c (one noisy step does not swing it), falling
    by at most half per step; after a step along which the cost fell at least as fast as its
    slope said (c <= 0, rho >= 2 for a Gauss-Newton step) mu halves: held there, every step
    would be a fraction of what the cost allows. For an image with edges J^T J is
    the curvature of sub-pixel motion: for steps of pixels it overestimates it, and plain
    Gauss-Newton steps fell short by half (rho ~ 2 at every step of a plate fit). Unbounded,
    mu swung from 0.3 to its floor 0.05 after such steps, and every third step overshot and
    was rejected: the open-mouth sample plate's rig fit ended 1.3 mm off after 38 iterations,
    and 0.13 mm off after 21 with the bounded rule.

    Stops when the relative cost decrease of an accepted step is below ``ftol``, the step is
    below ``xtol`` (relative to |x| + xtol), the projected gradient is below ``gtol``, the
    trust radius below ``min_radius``, or after ``max_iter`` iterations. ``progress(entry)``
    is called with each log entry."""
    x = np.asarray(x0, float).copy()
    lo, hi = _bounds(len(x), lower, upper)
    x = np.clip(x, lo, hi)
    ne = _evaluate(fun, x)
    cost = ne.cost
    history, status, t0 = [], "max_iter", time.perf_counter()
    it, mu = 0, 1.0
    for it in range(1, max_iter + 1):
        g = ne.gradient
        # variables held at a bound with the gradient pushing out of the box: they do not move,
        # so their rows and columns of H are not needed
        held = ((x <= lo) & (g > 0)) | ((x >= hi) & (g < 0))
        free = ~held
        if np.linalg.norm(g[free], np.inf) <= gtol:
            status = "gradient"
            break
        H = mu * (ne.hessian_on(free) if hasattr(ne, "hessian_on") else ne.hessian)
        p = _box_dogleg_step(H, g, free, lo - x, hi - x, radius)
        predicted = -(g @ p + 0.5 * p @ H @ p)
        x_new = x + p
        ne_new, cost_new = _trial(fun, x_new)
        actual = cost - cost_new
        rho = actual / predicted if predicted > 0 and np.isfinite(cost_new) else -1.0
        if adapt_curvature and np.isfinite(cost_new):
            mu = _curvature_scale(mu, g, p, p @ H @ p / mu, actual)
        radius = _new_radius(radius, rho, np.linalg.norm(p))
        accepted = rho > 1e-4
        entry = {"iteration": it, "cost": cost_new if accepted else cost, "rho": float(rho), "mu": mu,
                 "radius": float(radius), "step": float(np.linalg.norm(p)), "accepted": bool(accepted),
                 "seconds": time.perf_counter() - t0}
        history.append(entry)
        if progress is not None:
            progress(entry)
        if accepted:
            x, ne = x_new, ne_new
            small_decrease = actual <= ftol * cost
            cost = cost_new
            if small_decrease:
                status = "cost"
                break
        if np.linalg.norm(p) <= xtol * (np.linalg.norm(x) + xtol):
            status = "step"
            break
        if radius < min_radius:
            status = "radius"
            break
    return DoglegResult(x=x, cost=cost, iterations=it, status=status, history=history)
