"""Cold simulation solves at real-photo controls: Newton alone, without a fit's path.

    python bench/cold_solves.py OUT [--kinds blendshape,simulation]

OUT is a ``bench/real_photos.py`` output folder. For every photo in it and every kind, the
actor's model (``OUT/<photo>/actor.npz``) is solved from rest (``DrivenSimulation.solve(p,
warm=None)``) at the controls the kind's fit ended at (``OUT/<photo>/<kind>/fit.json``):
jaws twisted and slid by real faces, lips pressed and pouted, the solves a photo fit starts
with. A fit's seconds move with its path (the renderer's last-bit noise changes which trials
the dogleg makes); these solves are the same every run, so Newton changes are measured here.
Prints per solve: Newton iterations, load steps, seconds, the phases' seconds; then totals.
"""
import argparse
import json
import time
from pathlib import Path

from invface.model import FitVector
from invface.model.facemodel import FaceModel
from invface.sim.driven import DrivenSimulation


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path)
    ap.add_argument("--kinds", default="blendshape,simulation")
    a = ap.parse_args()
    iterations, seconds, count = 0, 0.0, 0
    for d in sorted(p for p in a.out.iterdir() if (p / "actor.npz").is_file()):
        model = FaceModel.load(d / "actor.npz")
        vec = FitVector.of(model)
        for kind in a.kinds.split(","):
            f = d / kind / "fit.json"
            if not f.is_file():
                continue
            s = json.loads(f.read_text())
            p = vec.from_dict(s, what=str(f))[vec.controls]
            ds = DrivenSimulation(model)
            t = time.perf_counter()
            r = ds.solve(p, warm=None).sim
            dt = time.perf_counter() - t
            iterations, seconds, count = iterations + r.iterations, seconds + dt, count + 1
            phases = "  ".join(f"{k} {v:.2f}" for k, v in r.seconds.items())
            print(f"{d.name:16s} {kind:10s} {r.iterations:3d} it  {r.load_steps} load steps  {dt:6.2f} s  ({phases})",
                  flush=True)
    print(f"{count} solves: {iterations} iterations, {seconds:.1f} s")


if __name__ == "__main__":
    main()
