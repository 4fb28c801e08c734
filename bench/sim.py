"""Quasistatic simulation benchmark: per-iteration phase times, cold and warm solves.

    python bench/sim.py [--resolutions 1 4 10] [--solver pardiso|superlu]

Prints, per template resolution: tets, free DOFs, seconds per Newton iteration split into
assembly / factorisation / solve, iterations and seconds from rest for a strong smile and
for jaw open, a warm-started re-solve, and peak memory (ru_maxrss).
"""
import argparse
import resource
import time

import invface
from invface.sim.quasistatic import Simulator


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
    warm = sim.solve({k: 0.85 for k in smile}, warm=rows[0][1])
    print(f"  warm re-solve      {warm.iterations:2d} it  {sum(warm.seconds.values()):6.2f} s  (smile 0.80 -> 0.85)")
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    print(f"  set-up {setup:.2f} s; peak memory {peak:.0f} MB")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--resolutions", type=float, nargs="+", default=[1.0, 4.0, 10.0])
    ap.add_argument("--solver", default=None)
    a = ap.parse_args()
    for res in a.resolutions:
        m = invface.template.build(resolution=res, expressions=False)
        print(f"resolution {res:g}: {len(m.tets)} tets, {len(m.rest_positions)} vertices", flush=True)
        run(res, a.solver)


if __name__ == "__main__":
    main()
