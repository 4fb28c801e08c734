"""Quasistatic simulation benchmark: per-iteration phase times, cold and warm solves.

    python bench/sim.py [--resolutions 1 4 10] [--solver pardiso|superlu]

Prints, per template resolution: tets, free DOFs, seconds per Newton iteration split into
assembly / factorisation / solve, iterations and seconds from rest for a strong smile and
for jaw open, the flesh kernel's seconds with the exact and with the definiteness-projected
material stiffness, a warm-started re-solve (median and range of five), and peak memory
(ru_maxrss).
"""
import argparse
import time

import numpy as np
from _common import add_json_option, peak_rss_mib, write_json

import invface
from invface.sim.quasistatic import Simulator


def flesh_kernel(sim, result, repeats=10):
    """Seconds of one flesh evaluation (energy, gradient, element matrices) with the exact and
    with the definiteness-projected dP/dF at a solved state, and how many tets need the fix."""
    act = sim.activation_vector(result.activations)
    out = []
    for project in (False, True):
        sim.flesh.evaluate(result.X, act, 2, project)
        t = time.perf_counter()
        for _ in range(repeats):
            sim.flesh.evaluate(result.X, act, 2, project)
        out.append((time.perf_counter() - t) / repeats)
    _, _, K = sim.flesh.evaluate(result.X, act, 2)
    indefinite = int((np.linalg.eigvalsh(K)[:, 0] < -1e-9 * np.abs(K).max(axis=(1, 2))).sum())
    print(f"  flesh kernel at the smile: exact {out[0]:.4f} s, projected {out[1]:.4f} s "
          f"({indefinite} of {len(K)} element matrices indefinite)")


def run(resolution, solver):
    model = invface.template.build(resolution=resolution, expressions=False)
    t = time.perf_counter()
    sim = Simulator(model, solver=solver)
    setup = time.perf_counter() - t
    smile = {n: 0.8 for n in sim.muscle_names if n.startswith(("zygomaticus_major", "levator_anguli_oris"))}
    rows = []
    for label, kw in (("smile", dict(activations=smile)), ("jaw open 0.2 rad", dict(jaw=[0.2, 0, 0, 0, 0, 0]))):
        r = sim.solve(**kw)
        it = max(r.iterations, 1)
        rows.append((label, r))
        print(f"  {label:17s} {r.iterations:2d} it  {sum(r.seconds.values()):6.2f} s  "
              f"per it: assembly {r.seconds['assembly'] / it:.3f}  factor {r.seconds['factor'] / it:.3f}  "
              f"solve {r.seconds['solve'] / it:.3f}  line search {r.seconds['line_search'] / it:.3f} s")
    flesh_kernel(sim, rows[0][1])
    figures = {label: {"iterations": r.iterations, "seconds": sum(r.seconds.values())} for label, r in rows}
    times = []
    for _ in range(5):          # the same solve five times: a quarter-second's spread is the machine's
        warm = sim.solve({k: 0.85 for k in smile}, warm=rows[0][1])
        times.append(sum(warm.seconds.values()))
    print(f"  warm re-solve      {warm.iterations:2d} it  {np.median(times):6.2f} s median of 5, "
          f"{min(times):.2f}-{max(times):.2f} s  (smile 0.80 -> 0.85)")
    peak = peak_rss_mib()
    print(f"  set-up {setup:.2f} s; peak memory {peak:.0f} MB")
    figures.update(warm_resolve_median_s=float(np.median(times)), warm_iterations=warm.iterations, setup_s=setup,
                   peak_mib=peak)
    return figures


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--resolutions", type=float, nargs="+", default=[1.0, 4.0, 10.0])
    ap.add_argument("--solver", default=None)
    add_json_option(ap)
    a = ap.parse_args()
    figures = {}
    for res in a.resolutions:
        m = invface.template.build(resolution=res, expressions=False)
        print(f"resolution {res:g}: {len(m.tets)} tets, {len(m.rest_positions)} vertices", flush=True)
        figures[f"resolution {res:g}"] = dict(run(res, a.solver), tets=len(m.tets))
    write_json(a.json, figures)


if __name__ == "__main__":
    main()
