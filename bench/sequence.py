"""Sequence fitting on one and on two Dask processes, and the temporal term (issue 28).

    python bench/sequence.py [--model FILE.npz] [--frames 24] [--size 320x240] [--shading]
                             [--kind blendshape|simulation]

Writes a synthetic clip with known truth (``fit.samples.write_sample_clip``: a smile rising
and falling, the jaw, brows and head moving) and fits it:
  * ``--workers 1`` and ``--workers 2`` (``distributed.LocalCluster``; the same code path),
    printing the wall time of each and their ratio, and the largest per-frame difference of
    the controls between the two runs;
  * on one process with the temporal term and without it, printing the frame-to-frame jitter
    (RMS second difference of the controls and pose in 0.1 weight / 0.01 rad / 1 mm units)
    of each and of the truth, and the median per-frame shape and posed error against it.
The calibration is the true one (light and albedo are not what this measures). Curves only
(Eq. 15) unless ``--shading``.
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import steps_per_frame

import invface
from invface.fit.calibrate import Calibration
from invface.fit.lambdas import TEMPORAL_LAMBDA
from invface.fit.samples import clip_controls, write_sample_clip
from invface.pipeline.clips import open_clip
from invface.pipeline.distributed import fit_sequence_distributed
from invface.pipeline.outputs import curve_rows, jitter, sequence_records
from invface.pipeline.runs import run_hash
from invface.render.synthetic import skin_albedo, studio_light


def steps(recs):
    """Mean accepted steps a frame of each stage, from the frames' histories, as text."""
    return ", ".join(f"{s} {v:.1f}" for s, v in steps_per_frame(recs).items())


def controls(recs):
    return np.array([list(r["weights"].values()) + r["jaw"] + r["rotation"] + r["translation"] for r in recs])


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model")
    ap.add_argument("--frames", type=int, default=24)
    ap.add_argument("--size", default="320x240")
    ap.add_argument("--shading", action="store_true")
    ap.add_argument("--kind", default="blendshape")
    a = ap.parse_args()
    model = invface.FaceModel.load(a.model) if a.model else invface.template.build()
    cal = Calibration(gamma=studio_light(), albedo=skin_albedo(model))
    size = tuple(int(v) for v in a.size.split("x"))
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        t0 = time.perf_counter()
        frames, _ = write_sample_clip(model, tmp / "clip", n=a.frames, size=size, video=False)
        print(f"clip: {a.frames} frames {size[0]}x{size[1]}, {len(model.tets)} tets, made by the blendshape rig "
              f"in {time.perf_counter() - t0:.1f} s; fits: {a.kind}, {'curves + shading' if a.shading else 'curves only'}")
        clip = open_clip(frames)
        recs, wall = {}, {}
        for t in (TEMPORAL_LAMBDA, 0.0):
            for workers in ((1, 2) if t else (1,)):
                opts = dict(shading=a.shading, temporal=t, iterations=10)
                out = tmp / f"w{workers}_t{t:g}"
                t0 = time.perf_counter()
                fit_sequence_distributed(model, clip, cal, out, (a.kind,), inputs=run_hash(model, cal, opts),
                                         workers=workers, **opts)
                wall[workers, t] = time.perf_counter() - t0
                recs[workers, t] = sequence_records(out, [a.kind])[a.kind]
                errs = [r["truth"] for r in recs[workers, t]]
                print(f"workers {workers}, temporal {t:g}: {wall[workers, t]:.1f} s; jitter "
                      f"{jitter(curve_rows(recs[workers, t])):.3f}; shape error median over frames "
                      f"{np.median([e['shape_median_mm'] for e in errs]):.3f} mm (worst frame "
                      f"{max(e['shape_median_mm'] for e in errs):.3f}), posed "
                      f"{np.median([e['median_mm'] for e in errs]):.3f} mm; curve RMS median "
                      f"{np.median([r['curve_rms_px'] for r in recs[workers, t]]):.2f} px; accepted steps a frame: "
                      f"{steps(recs[workers, t])}", flush=True)
        truth = [{"_name": f"{i}", "frame": i, "time": i / 24,
                  "weights": {n: w.get(n, 0.0) for n in model.blendshape_names}, "jaw": list(j), "rotation": list(r),
                  "translation": list(tr), "flagged": ""}
                 for i, (w, j, r, tr) in enumerate(clip_controls(model, a.frames))]
        print(f"truth jitter {jitter(curve_rows(truth)):.3f}")
        d = np.abs(controls(recs[1, TEMPORAL_LAMBDA]) - controls(recs[2, TEMPORAL_LAMBDA]))
        print(f"wall time 2 workers / 1 worker: {wall[2, TEMPORAL_LAMBDA] / wall[1, TEMPORAL_LAMBDA]:.2f}; "
              f"largest per-frame difference between them: {d.max():.4f} (weights, rad, m), in frame "
              f"{int(np.unravel_index(d.argmax(), d.shape)[0])}")
        print(json.dumps({f"{k[0]}w_t{k[1]:g}": round(v, 1) for k, v in wall.items()}))


if __name__ == "__main__":
    main()
