"""Powell's dogleg trust-region method for nonlinear least squares, with box constraints.

    result = dogleg(fun, x0, lower, upper)      # fun(x) -> (r (m,), J (m, n))

A trial point where the model cannot be evaluated (the simulation raises SimulationError)
is a rejected step: the trust radius shrinks.

Minimises 0.5 |r(x)|^2 (paper 000 fits Eq. 12-16 with Chumpy's dogleg). Each step combines
the Gauss-Newton step (J^T J p = -J^T r) and the Cauchy point inside a trust region; the
region grows after good steps and shrinks after poor ones, by the ratio of actual to
predicted decrease. Box constraints (blendshape weights in [0, 1]) use a projected dogleg:
variables at a bound whose gradient pushes outward are held fixed for the step, the step is
projected onto the box, and where that projection leaves no predicted decrease the
projected Cauchy step is taken instead.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConfigError
from ..sim.quasistatic import SimulationError


@dataclass
class DoglegResult:
    """x (n,), cost 0.5|r|^2, iterations, why it stopped, and the per-iteration log."""

    x: np.ndarray
    cost: float
    iterations: int
    status: str
    history: list = field(default_factory=list)


def _dogleg_step(g, H, radius):
    """Dogleg step for gradient g, Gauss-Newton matrix H and trust radius."""
    n = len(g)
    try:
        p_gn = -np.linalg.solve(H + 1e-12 * np.trace(H) / max(n, 1) * np.eye(n), g)
    except np.linalg.LinAlgError:
        p_gn = -np.linalg.lstsq(H, g, rcond=None)[0]
    if np.linalg.norm(p_gn) <= radius:
        return p_gn
    gHg = g @ H @ g
    p_sd = -(g @ g) / gHg * g if gHg > 0 else -radius * g / np.linalg.norm(g)
    if np.linalg.norm(p_sd) >= radius:
        return radius * p_sd / np.linalg.norm(p_sd)
    d = p_gn - p_sd                      # |p_sd + tau d| = radius
    a, b, c = d @ d, 2 * p_sd @ d, p_sd @ p_sd - radius ** 2
    tau = (-b + np.sqrt(max(b * b - 4 * a * c, 0))) / (2 * a)
    return p_sd + tau * d


def dogleg(fun, x0, lower=None, upper=None, max_iter=50, radius=1.0, ftol=1e-10, xtol=1e-8,
           gtol=1e-12, progress=None):
    """Minimise 0.5 |r(x)|^2 with ``fun(x) -> (r, J)``, lower <= x <= upper (None: unbounded).

    Stops when the relative cost decrease of an accepted step is below ``ftol``, the step is
    below ``xtol`` (relative to |x| + xtol), the projected gradient is below ``gtol``, or after
    ``max_iter`` iterations. ``progress(entry)`` is called with each log entry."""
    x = np.asarray(x0, float).copy()
    n = len(x)
    lo = np.full(n, -np.inf) if lower is None else np.broadcast_to(np.asarray(lower, float), n)
    hi = np.full(n, np.inf) if upper is None else np.broadcast_to(np.asarray(upper, float), n)
    if np.any(lo > hi):
        raise ConfigError("dogleg: a lower bound exceeds its upper bound")
    x = np.clip(x, lo, hi)
    r, J = fun(x)
    cost = 0.5 * float(r @ r)
    history, status, t0 = [], "max_iter", time.perf_counter()
    it = 0
    for it in range(1, max_iter + 1):
        g = J.T @ r
        # variables held at a bound with the gradient pushing out of the box
        held = ((x <= lo) & (g > 0)) | ((x >= hi) & (g < 0))
        free = ~held
        if np.linalg.norm(g[free], np.inf) <= gtol:
            status = "gradient"
            break
        Jf = J[:, free]
        p = np.zeros(n)
        p[free] = _dogleg_step(g[free], Jf.T @ Jf, radius)
        p = np.clip(x + p, lo, hi) - x                 # projected onto the box
        Jp = J @ p
        predicted = -(g @ p + 0.5 * Jp @ Jp)
        if predicted <= 0:                             # projection spoilt it: projected Cauchy step
            gf = np.where(free, g, 0.0)
            Jg = J @ gf
            step = min(radius / np.linalg.norm(gf), (gf @ gf) / max(Jg @ Jg, 1e-300))
            p = np.clip(x - step * gf, lo, hi) - x
            Jp = J @ p
            predicted = -(g @ p + 0.5 * Jp @ Jp)
        x_new = x + p
        try:
            r_new, J_new = fun(x_new)
            cost_new = 0.5 * float(r_new @ r_new)
        except SimulationError:       # the model cannot reach this trial point: reject, shrink
            cost_new = np.inf
        actual = cost - cost_new
        rho = actual / predicted if predicted > 0 and np.isfinite(cost_new) else -1.0
        if rho < 0.25:
            radius = 0.25 * np.linalg.norm(p)
        elif rho > 0.75 and np.linalg.norm(p) >= 0.9 * radius:
            radius = 2 * radius
        accepted = rho > 1e-4
        entry = {"iteration": it, "cost": cost_new if accepted else cost, "rho": float(rho),
                 "radius": float(radius), "step": float(np.linalg.norm(p)), "accepted": bool(accepted),
                 "seconds": time.perf_counter() - t0}
        history.append(entry)
        if progress is not None:
            progress(entry)
        if accepted:
            x, r, J = x_new, r_new, J_new
            small_decrease = actual <= ftol * cost
            cost = cost_new
            if small_decrease:
                status = "cost"
                break
        if np.linalg.norm(p) <= xtol * (np.linalg.norm(x) + xtol):
            status = "step"
            break
    return DoglegResult(x=x, cost=cost, iterations=it, status=status, history=history)
