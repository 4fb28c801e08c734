"""Replay a fit's chain of simulation solves: Newton on a fit's path, without the fit.

    python bench/replay_solves.py record RUN PHOTO SOLVES.npz
    python bench/replay_solves.py replay ACTOR.npz SOLVES.npz [...]

``record``: fits PHOTO with the simulation kind (``pipeline.plates.fit_frame``) using the
actor and calibration of a ``bench/real_photos.py`` run's folder RUN (RUN/actor.npz,
RUN/calib.npz) and writes the controls of every simulation solve the fit made, in order
(``p`` (n, K+6)), and which started from rest (``cold`` (n,) bool).
``replay``: solves them again in that order, warm from the previous equilibrium (cold where
the fit's was), with no first-order predictor (the fit's came from its tangent solves, which
are not replayed). A fit's seconds move with its path (the renderer's last-bit noise changes
the trials the dogleg makes); a replay is the same every run. Prints per file: solves, Newton
iterations, load steps, solves that did not converge, seconds by phase.
"""
import argparse
import time
from pathlib import Path

import numpy as np

from invface.errors import SimulationError
from invface.model.facemodel import FaceModel
from invface.sim.driven import DrivenSimulation


def record(run, photo, out):
    from invface.fit.calibrate import Calibration
    from invface.pipeline.plates import fit_frame
    model = FaceModel.load(run / "actor.npz")
    cal = Calibration.load(run / "calib.npz", vertex_count=len(model.neutral))
    solves, solve = [], DrivenSimulation.solve

    def recording(self, p, warm="last", **kw):
        solves.append((np.asarray(p, float).copy(), warm is None or (isinstance(warm, str) and self.last is None)))
        return solve(self, p, warm=warm, **kw)

    DrivenSimulation.solve = recording
    try:
        fit_frame(model, str(photo), cal, kinds=("simulation",))
    finally:
        DrivenSimulation.solve = solve
    np.savez(out, p=np.array([s[0] for s in solves]), cold=np.array([s[1] for s in solves]))
    print(f"{out}: {len(solves)} solves, {sum(s[1] for s in solves)} from rest")


def replay(actor, paths):
    model = FaceModel.load(actor)
    for path in paths:
        rec = np.load(path)
        ds = DrivenSimulation(model)
        its = steps = failed = 0
        phases, t = {}, time.perf_counter()
        for p, cold in zip(rec["p"], rec["cold"]):
            try:
                r = ds.solve(p, warm=None if cold else "last").sim
            except SimulationError:
                failed, ds.last = failed + 1, None
                continue
            its, steps = its + r.iterations, steps + r.load_steps
            for k, v in r.seconds.items():
                phases[k] = phases.get(k, 0.0) + v
        print(f"{path}: {len(rec['p'])} solves, {its} iterations, {steps} load steps, {failed} failed, "
              f"{time.perf_counter() - t:.1f} s (" + "  ".join(f"{k} {v:.1f}" for k, v in phases.items()) + ")",
              flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="verb", required=True)
    r = sub.add_parser("record")
    r.add_argument("run", type=Path)
    r.add_argument("photo", type=Path)
    r.add_argument("out", type=Path)
    p = sub.add_parser("replay")
    p.add_argument("actor")
    p.add_argument("solves", nargs="+")
    a = ap.parse_args()
    if a.verb == "record":
        record(a.run, a.photo, a.out)
    else:
        replay(a.actor, a.solves)


if __name__ == "__main__":
    main()
