"""The simulation at the paper's size (issue 30): paper 000's face mesh has 302k vertices and
1.47M tets. The template's own grid cannot go there (from resolution 4.5 on, slivers on the
side of the nose fail its quality bounds), so the bench refines it: ``--resolution 4 --refine
1`` (the default) has 1.14M tets, ``--resolution 1 --refine 2`` 2.27M.

    python bench/paper_scale.py [--resolution 4] [--refine 1] [--max-iter 40] [--solver pardiso] [--solves smile jaw]
                                [--no-contact]

Stages, each printed with its seconds and the process's peak resident memory so far: the
template build (anatomy only; cached like every template), its 1:8 refinement
(``invface.morph.refine``), the simulator's set-up (sparsity
pattern, contacts, symbolic analysis), a cold solve of a smile (zygomaticus major + levator
anguli oris at 0.8) and of a jaw opening (0.2 rad), each with its Newton iterations and
seconds per iteration by phase and, when it converged, the adjoint gradient of a loss on its
state with respect to the muscle activations (``sim.adjoint.activation_gradient``:
conjugate gradients preconditioned with the solve's last factorisation of an exact Hessian),
then, for comparison, the same gradient by the factorisation at the solution. Load stepping
is off: a solve that does not converge in ``--max-iter`` is reported as it is.
"""
from __future__ import annotations

import argparse
import resource
import time

import numpy as np

import invface
from invface.mesh.tets import quality_summary
from invface.morph.refine import refine
from invface.sim.adjoint import activation_gradient
from invface.sim.quasistatic import Simulator


def peak_gib():
    """Peak resident memory of this process so far (GiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2 ** 20


def stage(label, t0):
    print(f"{label:38s} {time.perf_counter() - t0:8.1f} s   peak {peak_gib():5.2f} GiB", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolution", type=float, default=4.0)
    ap.add_argument("--refine", type=int, default=1)
    ap.add_argument("--max-iter", type=int, default=40)
    ap.add_argument("--solver", default=None)
    ap.add_argument("--solves", nargs="+", default=["smile", "jaw"], choices=["smile", "jaw"],
                    help="which cold solves: the smile, the jaw opening (0.2 rad)")
    ap.add_argument("--no-contact", action="store_true", help="the flesh alone, without collision penalties")
    args = ap.parse_args()

    t = time.perf_counter()
    model = invface.template.build(resolution=args.resolution, expressions=False, progress=print)
    stage(f"template: {len(model.tets):,} tets, {len(model.rest_positions):,} vertices", t)
    if args.refine:
        t = time.perf_counter()
        model = refine(model, args.refine)
        stage(f"refined: {len(model.tets):,} tets, {len(model.rest_positions):,} vertices", t)
    q = quality_summary(model.rest_positions, model.tets)
    print(f"    min dihedral {q['min_dihedral_deg']:.2f} deg, min radius ratio {q['min_radius_ratio']:.4f}")
    t = time.perf_counter()
    sim = Simulator(model, solver=args.solver, contact=not args.no_contact)
    sim.MIN_STEP = 1          # no load stepping: a solve that does not converge is reported, not retried
    stage(f"set-up: {sim.pattern.n:,} free DOFs", t)

    def newton(it, r):
        print(f"    iteration {it:2d}  relative residual {r:.2e}  at {time.perf_counter() - t0:7.1f} s", flush=True)

    smile = {n: 0.8 for n in sim.muscle_names if n.startswith(("zygomaticus_major", "levator_anguli_oris"))}
    solves = {"smile": dict(activations=smile), "jaw": dict(jaw=[0.2, 0, 0, 0, 0, 0])}
    for label in args.solves:
        kw = solves[label]
        t0 = time.perf_counter()
        r = sim.solve(max_iter=args.max_iter, raise_on_failure=False, progress=newton, **kw)
        it = max(r.iterations, 1)
        per = "  ".join(f"{k} {v / it:.2f}" for k, v in r.seconds.items())
        stage(f"{label}: {r.iterations} it, {'converged' if r.converged else 'NOT converged'}", t0)
        print(f"    per iteration (s): {per}; load steps {r.load_steps}; min volume ratio {r.min_J:.3f}")
        if r.converged:
            gX = np.random.default_rng(0).normal(size=r.X.shape)
            t = time.perf_counter()
            g = activation_gradient(sim, r, gX)       # CG on the last Newton step's factorisation
            how = "own factorisation" if r.factorised else "no factorisation"
            stage(f"adjoint at the {label} ({how}), |dL/da| {np.linalg.norm(g):.3g}", t)
            if not r.factorised:                      # against the factorisation at the solution
                t = time.perf_counter()
                r.solver
                stage(f"    for comparison: factorisation at the {label}", t)
                t = time.perf_counter()
                ge = activation_gradient(sim, r, gX)
                stage(f"    ... its solve + contraction; rel. diff {np.abs(g - ge).max() / np.abs(ge).max():.1e}", t)
        del r                                         # its factorisation is not held through the next solve
    print(f"peak memory {peak_gib():.2f} GiB")


if __name__ == "__main__":
    main()
