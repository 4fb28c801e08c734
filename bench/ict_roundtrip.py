"""A round trip with no inverse crime (issue 59): plates made by ICT-FaceKit's own sculpted
shapes, fitted with the built-in head's ARKit controls carried onto the same actor.

    python bench/ict_roundtrip.py OUT [--kind blendshape] [--mixes 5] [--single 0.7]
                                  [--limit N] [--json FILE]

1. Two actors from ICT-FaceKit's neutral (``../shared/data/ict-facekit``), built once into OUT:
   - ``truth.npz``: ``build_model(neutral, blendshapes=ICT's 53 expressions)``, ICT's own shapes;
   - ``fitted.npz``: ``build_model(neutral, expressions="copy")``, the built-in head's ARKit shapes
     carried onto the actor (which were themselves carried from ICT onto the template, so the
     two actors' shapes differ by a round trip through the template, and by the template's
     own blinks).
2. Plates of the truth actor in the simulation kind (``fit.samples.write_plate``, 720x540,
   studio light): mixes of 3-6 controls at weights 0.3-0.9 until every control is in at least
   ``--mixes`` of them (no two antagonists, such as mouthLeft and mouthRight, in one), and one
   plate per control alone at ``--single``. Each shape carries its paired jaw, times its
   weight. mouthClose, ICT's corrective, comes with jawOpen at least as large (alone it
   pushes the closed lips into each other). tongueOut is left out: ICT-FaceKit has none. A
   plate whose simulation does not converge is reported and left out.
3. Each plate is fitted with the fitted actor, every control free (``fit.plate.fit_plate``,
   the plate's curve file and the true light and albedo), in ``--kind``.
4. Both sides are read as ARKit values (``model.arkit.arkit_values``: the jaw's controls from the
   jaw bone). Per control: the Pearson correlation of recovered against true values over all
   plates (target >= 0.8). Per single-control plate: the true control's rank among the
   recovered values (target first), its error (target within 0.15) and the largest other
   value (target below 0.1).

Each fit is appended to OUT/fits_KIND.jsonl as it finishes; a second run resumes.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh
from _common import SHARED, add_json_option, write_json

import invface
from invface.fit.calibrate import Calibration
from invface.fit.curves import read_curves
from invface.fit.plate import fit_plate
from invface.fit.samples import write_plate
from invface.errors import SimulationError
from invface.io.meshes import read_mesh
from invface.model.arkit import ARKIT_NAMES, OPPOSITES, arkit_name, arkit_values
from invface.morph.build import build_model
from invface.render.plates import load_plate
from invface.render.synthetic import skin_albedo, studio_light

ICT = SHARED / "ict-facekit"
LEFT_OUT = ("tongueOut",)                    # ICT-FaceKit has no tongueOut
POSE = ((0.03, -0.08, 0.0), (0.0, 0.0, 0.0))  # rad, m: a slight three-quarter view
# a face makes one control of each pair at a time (the fits' prior charges both: ``OPPOSITES``)
ANTAGONISTS = list(OPPOSITES) + [("jawLeft", "jawRight")]


def actors(out, template):
    """The truth actor (ICT's own shapes) and the fitted one (the head's shapes carried), built
    into ``out`` once."""
    paths = out / "truth.npz", out / "fitted.npz"
    if not all(p.exists() for p in paths):
        V, F = read_mesh(ICT / "neutral.obj")
        ex = np.load(ICT / "expressions.npz")
        with tempfile.TemporaryDirectory() as tmp:
            for n, d in zip(ex["names"], ex["deltas"]):
                trimesh.Trimesh(V + d, F, process=False).export(Path(tmp) / f"{n}.obj")
            t0 = time.perf_counter()
            truth, _ = build_model(ICT / "neutral.obj", blendshapes=tmp, template=template, expressions="none")
            print(f"truth actor (ICT's own shapes) built in {time.perf_counter() - t0:.0f} s", flush=True)
        t0 = time.perf_counter()
        fitted, _ = build_model(ICT / "neutral.obj", template=template, expressions="copy")
        print(f"fitted actor (the head's shapes carried) built in {time.perf_counter() - t0:.0f} s", flush=True)
        truth.save(paths[0])
        fitted.save(paths[1])
    return tuple(invface.FaceModel.load(p) for p in paths)


def controls_by_arkit(model):
    """{ARKit control: [the model's blendshape names that drive it]} (browInnerUp: ICT's _L and _R)."""
    out = {}
    for n in model.blendshape_names:
        a = arkit_name(n)
        if a is not None and a not in LEFT_OUT:
            out.setdefault(a, []).append(n)
    return out


def mixes(controls, per_control, rng):
    """Lists of 3-6 controls, no two antagonists in one, until each control is in
    ``per_control`` of them."""
    banned = {a: {b for pair in ANTAGONISTS if a in pair for b in pair if b != a} for a in controls}
    count = dict.fromkeys(controls, 0)
    out = []
    while min(count.values()) < per_control:
        size = int(rng.integers(3, 7))
        need = sorted(controls, key=lambda c: (count[c], rng.random()))
        pick = []
        for c in need:
            if len(pick) == size:
                break
            if not banned[c] & set(pick):
                pick.append(c)
        for c in pick:
            count[c] += 1
        out.append(pick)
    return out


def plate_specs(truth, per_control, single, seed=0):
    """[(name, {"weights", "jaw"})]: the mixes, then one plate per control alone."""
    rng = np.random.default_rng(seed)
    by = controls_by_arkit(truth)
    jaws = truth.meta.get("blendshape_jaw", {})

    def controls(values):
        if "mouthClose" in values:     # a corrective: it closes lips that jawOpen has opened
            values["jawOpen"] = max(values.get("jawOpen", 0.0), values["mouthClose"])
        weights = {n: v for a, v in values.items() for n in by[a]}
        jaw = sum((v * np.asarray(jaws.get(n, np.zeros(6)), float) for n, v in weights.items()), np.zeros(6))
        return {"weights": weights, "jaw": jaw.tolist()}

    specs = [(f"mix{i:03d}", controls({a: float(rng.uniform(0.3, 0.9)) for a in pick}))
             for i, pick in enumerate(mixes(sorted(by), per_control, rng))]
    specs += [(f"one_{a}", controls({a: single})) for a in sorted(by)]
    return specs


def interleave(specs):
    """The mixes and the single-control plates taken in turn, so that a partial run has both."""
    mix = [s for s in specs if s[0].startswith("mix")]
    one = [s for s in specs if not s[0].startswith("mix")]
    out = []
    for i in range(max(len(mix), len(one))):
        out += mix[i:i + 1] + one[i:i + 1]
    return out


def arkit_of(model, controls):
    """The ARKit values of ``controls`` ({"weights", "jaw"}) on ``model``."""
    p, K = model.parameters(controls), len(model.blendshape_names)
    return arkit_values(model.blendshape_names, p[:K], p[K:])


def run(out, kind, per_control, single, limit):
    template = invface.template.build(1.0)
    truth, fitted = actors(out, template)
    specs = interleave(plate_specs(truth, per_control, single))[:limit]
    log = out / f"fits_{kind}.jsonl"
    done = {json.loads(line)["plate"] for line in log.open()} if log.exists() else set()
    cal = Calibration(gamma=studio_light(), albedo=skin_albedo(fitted))
    print(f"{len(specs)} plates ({sum(s[0].startswith('mix') for s in specs)} mixes), {len(done)} already fitted",
          flush=True)
    plates = out / "plates"
    for i, (name, controls) in enumerate(specs):
        if name in done:
            continue
        t0 = time.perf_counter()
        truth.forget_surface_models()          # each plate solved cold, as its own shot
        try:
            path = write_plate(truth, plates, name, "simulation", controls, *POSE, seed=i)
        except SimulationError as e:
            print(f"[{i + 1}/{len(specs)}] {name}: the truth actor's simulation failed ({e}); left out", flush=True)
            continue
        t_plate = time.perf_counter() - t0
        fitted.forget_surface_models()
        fit = fit_plate(fitted, load_plate(path), cal, read_curves(path.with_name(name + ".curves.json"), fitted),
                        kind=kind)
        row = {"plate": name, "kind": kind,
               "true": arkit_of(truth, controls),
               "fitted": arkit_values(fitted.blendshape_names, fit.p[fit.vector.weights], fit.p[fit.vector.jaw]),
               "curve_rms_px": fit.curve_rms_px, "plate_s": round(t_plate, 2), "fit_s": round(fit.seconds["total"], 2)}
        with log.open("a") as f:
            f.write(json.dumps(row) + "\n")
        print(f"[{i + 1}/{len(specs)}] {name}: curves {fit.curve_rms_px:.2f} px, plate {t_plate:.1f} s, "
              f"fit {fit.seconds['total']:.1f} s", flush=True)
    return [json.loads(line) for line in log.open()]


def report(rows, single):
    """Per-control correlations and the single-control plates' ranks, printed; the figures."""
    controls = [a for a in ARKIT_NAMES if a not in LEFT_OUT]
    T = np.array([[r["true"][a] for a in controls] for r in rows])
    R = np.array([[r["fitted"][a] for a in controls] for r in rows])
    corr = {}
    for j, a in enumerate(controls):
        t, r = T[:, j] - T[:, j].mean(), R[:, j] - R[:, j].mean()
        den = np.linalg.norm(t) * np.linalg.norm(r)
        corr[a] = float(t @ r / den) if den > 0 else float("nan")
    print(f"\n{len(rows)} plates; per-control correlation of recovered with true ARKit values (target >= 0.8):")
    print("| control | r | true mean | recovered mean |\n|---|---|---|---|")
    for j, a in enumerate(controls):
        print(f"| {a} | {corr[a]:.2f} | {T[:, j].mean():.2f} | {R[:, j].mean():.2f} |")
    ok = [a for a in controls if corr[a] >= 0.8]
    print(f"{len(ok)} of {len(controls)} controls at r >= 0.8")
    singles = {}
    for r in rows:
        if not r["plate"].startswith("one_"):
            continue
        a = r["plate"][4:]
        vals = sorted(((v, k) for k, v in r["fitted"].items()), reverse=True)
        rank = 1 + [k for _, k in vals].index(a)
        other = max(v for k, v in r["fitted"].items() if k != a)
        singles[a] = {"true": r["true"][a], "recovered": r["fitted"][a], "rank": rank, "largest_other": other,
                      "ok": rank == 1 and abs(r["fitted"][a] - r["true"][a]) <= 0.15 and other < 0.1}
    if singles:
        print(f"\nsingle-control plates at {single} (targets: rank 1, within 0.15, every other below 0.1):")
        print("| control | true | recovered | rank | largest other |\n|---|---|---|---|---|")
        for a, s in singles.items():
            print(f"| {a} | {s['true']:.2f} | {s['recovered']:.2f} | {s['rank']} | {s['largest_other']:.2f} |")
        print(f"{sum(s['ok'] for s in singles.values())} of {len(singles)} meet all three; "
              f"{sum(s['rank'] == 1 for s in singles.values())} rank first")
    secs = [r["fit_s"] for r in rows]
    print(f"fit seconds: median {np.median(secs):.1f}, max {max(secs):.1f}; "
          f"curve RMS median {np.median([r['curve_rms_px'] for r in rows]):.2f} px")
    return {"plates": len(rows), "correlation": corr, "controls_at_0.8": len(ok), "singles": singles,
            "fit_seconds_median": float(np.median(secs))}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path)
    ap.add_argument("--kind", choices=("blendshape", "simulation"), default="blendshape")
    ap.add_argument("--mixes", type=int, default=5, help="plates each control is in, at least (default 5)")
    ap.add_argument("--single", type=float, default=0.7, help="the single-control plates' weight (default 0.7)")
    ap.add_argument("--limit", type=int, help="fit only the first N plates")
    add_json_option(ap)
    a = ap.parse_args()
    if not (ICT / "expressions.npz").exists():
        sys.exit(f"{ICT}: ICT-FaceKit not found (neutral.obj, expressions.npz); this bench needs it")
    a.out.mkdir(parents=True, exist_ok=True)
    rows = run(a.out, a.kind, a.mixes, a.single, a.limit)
    figures = report(rows, a.single)
    write_json(a.json, {"kind": a.kind, **figures})


if __name__ == "__main__":
    main()
