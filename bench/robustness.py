"""Does the simulation answer everywhere in the fitting box? (issue 25)

    python bench/robustness.py [--model default|ict|FILE.npz] [--count 256] [--singles] [--pairs]
                               [--resolution 1.0] [--results FILE.jsonl] [--only TEXT]

Cold solves (each from rest, as a freshly loaded model) of the driven simulation at:
  * ``--count`` quasi-random control vectors (scrambled Sobol) over the box the fits use:
    every blendshape weight in [0, 1], the jaw in [JAW_LOWER, JAW_UPPER];
  * ``--singles``: every control alone at its upper bound (and the jaw entries at their
    lower bounds too);
  * ``--pairs``: every pair of the strongest mouth shapes (the six that move the lips most)
    and the jaw opened to its upper bound, each at its bound.
Prints per group and in all: converged / total, the worst final relative residual, inverted
tets, the smallest volume ratio, load steps used, the deepest penetration of an acting contact
(how far a flesh vertex ended up behind the surface it touches), seconds (median / max), and
every failure or load-stepped solve.

``--results FILE.jsonl`` appends one line per case as it finishes and skips the cases already
there, so a sweep of several hours can be stopped and resumed (the tallies cover every case in
the file). ``--only TEXT`` runs the cases whose label contains TEXT and prints each one
(``--only "sample 187"``; ``--pairs --only jaw_rx``: the lip shapes against the open jaw).
``--model ict`` builds an actor from ../shared/data/ict-facekit's neutral with its imported
blendshapes (``build-model --blendshapes``).
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
from itertools import combinations
from pathlib import Path

import numpy as np
from _common import SHARED
from scipy.stats import qmc

import invface
from invface.errors import SimulationError
from invface.model.rig import JAW_LOWER, JAW_NAMES, JAW_UPPER
from invface.sim.contact import TriangleContacts

ICT = SHARED / "ict-facekit"


def load(name, resolution):
    if name == "default":
        return invface.template.build(resolution=resolution)
    if name == "ict":
        import trimesh

        from invface.io.meshes import read_mesh
        from invface.morph.build import build_model
        V, F = read_mesh(ICT / "neutral.obj")
        ex = np.load(ICT / "expressions.npz")
        tpl = invface.template.build(resolution=resolution, expressions=False)
        with tempfile.TemporaryDirectory() as tmp:
            for n, d in zip(ex["names"], ex["deltas"]):
                trimesh.Trimesh(V + d, F, process=False).export(Path(tmp) / f"{n}.obj")
            model, _ = build_model(ICT / "neutral.obj", blendshapes=tmp, template=tpl, expressions="none")
        return model
    return invface.FaceModel.load(name)


def cases(model, count, singles, pairs, seed=0):
    """(group, label, p (K+6,)) of the sweep: singles, pairs, then the quasi-random samples."""
    K = len(model.blendshape_names)
    lo = np.concatenate([np.zeros(K), JAW_LOWER])
    hi = np.concatenate([np.ones(K), JAW_UPPER])
    names = list(model.blendshape_names) + JAW_NAMES
    out = []
    if singles:
        for i, n in enumerate(names):
            p = np.zeros(K + 6)
            p[i] = hi[i]
            out.append(("singles", f"{n}={hi[i]:g}", p))
            if i >= K:
                p = np.zeros(K + 6)
                p[i] = lo[i]
                out.append(("singles", f"{n}={lo[i]:g}", p))
    if pairs:
        lips = np.concatenate([model.curves[c] for c in model.curves if c.startswith("lip")])
        move = np.linalg.norm(model.blendshapes[:, lips], axis=2).max(1)
        strong = [names[i] for i in np.argsort(move)[::-1][:6]] + ["jaw_rx"]
        for a, b in combinations(strong, 2):
            p = np.zeros(K + 6)
            for n in (a, b):
                p[names.index(n)] = hi[names.index(n)]
            out.append(("pairs", f"{a}+{b}", p))
    if count:
        u = qmc.Sobol(K + 6, scramble=True, seed=seed).random(count)
        out += [("quasi-random", f"sample {i}", lo + s * (hi - lo)) for i, s in enumerate(u)]
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", default="default")
    ap.add_argument("--resolution", type=float, default=1.0)
    ap.add_argument("--count", type=int, default=256)
    ap.add_argument("--singles", action="store_true")
    ap.add_argument("--pairs", action="store_true")
    ap.add_argument("--results", help="JSON-lines file: append each case, skip the cases already in it")
    ap.add_argument("--only", help="run only the cases whose label contains this text, printing each")
    a = ap.parse_args()
    t0 = time.perf_counter()
    model = load(a.model, a.resolution)
    ds = model.surface_model("simulation")
    print(f"model {a.model}: {len(model.tets)} tets, {len(model.blendshape_names)} blendshapes, "
          f"{len(ds.sim.contacts or [])} contacts; ready in {time.perf_counter() - t0:.0f} s", flush=True)
    rows, done = [], {}
    if a.results and Path(a.results).is_file():
        for line in Path(a.results).read_text().splitlines():
            r = json.loads(line)
            done[r[0], r[1]] = tuple(r)
    for group, label, p in cases(model, a.count, a.singles, a.pairs):
        if a.only is not None and a.only not in label:
            continue
        if (group, label) in done:
            rows.append(done[group, label])
            continue
        t = time.perf_counter()
        try:
            r = ds.solve(p, warm=None, raise_on_failure=False).sim
        except SimulationError as e:          # a failure outside Newton (none expected)
            print(f"  {group} {label}: {e}")
            rows.append((group, label, False, np.nan, 0, np.nan, 0, time.perf_counter() - t, 0.0))
            continue
        sec = time.perf_counter() - t
        depth = penetration(ds.sim.contacts.of(TriangleContacts), r.X, model.jaw_matrix(r.jaw))
        rows.append((group, label, bool(r.converged), float(r.residuals[-1]) if r.residuals else np.nan,
                     int(r.inverted), float(r.min_J), int(r.load_steps), sec, depth))
        if a.results:
            with open(a.results, "a") as f:
                f.write(json.dumps(rows[-1]) + "\n")
        if not r.converged or r.load_steps or a.only is not None:
            print(f"  {group} {label}: {r.report()}; deepest penetration {depth * 1e3:.2f} mm", flush=True)
        if len(rows) % 32 == 0:
            print(f"  [{len(rows)} done, {time.perf_counter() - t0:.0f} s]", end=" ")
            summary(rows, ["all"])
    summary(rows)


def penetration(col, X, M):
    """Deepest penetration (m) of a flesh vertex behind a surface it touches: the largest
    negative gap of an acting contact whose vertex projects inside its triangle (a vertex off
    to the side is behind the triangle's plane where the surface bends away, not behind the
    surface)."""
    acting = np.flatnonzero(col.acting(X, M))
    if not len(acting):
        return 0.0
    Q = col.points(X, M)
    x, (a, b, c) = Q[col.v[acting]], np.moveaxis(Q[col.tri[acting]], 1, 0)
    n = np.cross(b - a, c - a)
    nn = np.einsum("ci,ci->c", n, n)
    inside = np.ones(len(acting), bool)
    for p, q in ((a, b), (b, c), (c, a)):            # the projection is on each edge's inner side
        inside &= np.einsum("ci,ci->c", np.cross(q - p, x - p), n) >= -1e-12 * nn
    gaps = col.gaps(X, M)[acting][inside]
    return float(max(0.0, -gaps.min())) if len(gaps) else 0.0


def summary(rows, groups=None):
    """Print the figures per group and in all."""
    for group in groups or dict.fromkeys([r[0] for r in rows] + ["all"]):
        g = [r for r in rows if group in ("all", r[0])]
        conv = sum(r[2] for r in g)
        sec = np.array([r[7] for r in g])
        print(f"{group}: {conv} / {len(g)} converged; worst residual {max(r[3] for r in g):.1e}; "
              f"inverted tets {sum(r[4] for r in g)}; min volume ratio {min(r[5] for r in g):.3f}; "
              f"load-stepped {sum(r[6] > 0 for r in g)}; deepest contact penetration "
              f"{max(r[8] for r in g) * 1000:.2f} mm; seconds median {np.median(sec):.1f} max {sec.max():.1f}",
              flush=True)


if __name__ == "__main__":
    main()
