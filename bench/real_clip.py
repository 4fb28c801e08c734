"""The shared 72-frame phone clip through the CLI's own path, timed as a user would see it.

    python bench/real_clip.py OUT [--frames 36:72:2] [--workers 2] [--kinds both] [--json F]
    python bench/real_clip.py OUT --summarise          # an earlier run in OUT, not rerun

Runs ``invface fit-plate single_face.mp4 --model-kind both --workers 2 -o OUT`` with the CLI's
defaults (calibration and identity on the clip's own neutral frame, reports, overlay MP4s and
exports included) and prints:
- the command's wall time divided by the frames;
- per kind, the mean per frame of each stage's seconds, its accepted dogleg steps, and the
  simulation's quasistatic solves and Newton iterations;
- per kind, the accuracy (medians over the frames): curve RMS, image RMS over the plate and the mouth region (linear),
  lip volume within +-5 %, and the frame-to-frame jitter of the controls
  (``pipeline.outputs.jitter``).
The run folder is kept, with the wall time in OUT/real_clip_wall.json, so ``--summarise`` can
compare runs made at other commits.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from _common import add_json_option, shared, steps_per_frame, write_json
from invface.pipeline.outputs import curve_rows, jitter, sequence_records

KINDS = {"both": ("blendshape", "simulation"), "blendshape": ("blendshape",), "simulation": ("simulation",)}


def run(out, frames, workers, kinds):
    """Run the CLI on the clip into ``out``; returns its wall time (s)."""
    clip = shared("real", "video", "single_face.mp4", what="the shared phone clip")
    cmd = [sys.executable, "-m", "invface.cli", "fit-plate", str(clip), "--model-kind", kinds, "-o", str(out)]
    cmd += ["--frames", frames] if frames else []
    cmd += ["--workers", str(workers)] if workers else []
    print("$", " ".join(cmd[2:]), flush=True)
    t = time.perf_counter()
    subprocess.run(cmd, check=True)
    return time.perf_counter() - t


def per_kind(records):
    """The figures of one kind's frame records (fit.json dicts in frame order)."""
    med = lambda values: float(np.median(values)) if len(values) else float("nan")
    mean = lambda values: float(np.mean(values)) if len(values) else float("nan")
    stages = sorted({s for r in records for s in r.get("seconds", {})})
    steps = steps_per_frame(records)
    work = lambda key: [r["work"][key] for r in records if key in r.get("work", {})]
    lips = [r["lip_volume_change"] for r in records]
    return {
        "frames": len(records),
        "seconds_per_frame": {s: mean([r["seconds"].get(s, 0.0) for r in records]) for s in stages},
        "steps_per_frame": {s: steps[s] for s in sorted(steps)},
        "solves_per_frame": mean(work("solves")),
        "newton_iterations_per_frame": mean(work("newton_iterations")),
        "curve_rms_px": med([r["curve_rms_px"] for r in records]),
        "image_rms": med([r["image_rms"] for r in records]),
        "mouth_rms": med([r["image_rms_by_region"].get("mouth", np.nan) for r in records]),
        "lips_within_5pct": int(sum(abs(v) <= 0.05 for v in lips)),
        "jitter": jitter(curve_rows(records)),
        "flagged": int(sum(bool(r.get("flagged")) for r in records)),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path, help="the run's folder (kept)")
    ap.add_argument("--frames", default="", help="START:STOP[:STEP] of the clip (default: all 72)")
    ap.add_argument("--workers", type=int, default=2, help="local Dask workers (0: the frames on this process)")
    ap.add_argument("--kinds", choices=sorted(KINDS), default="both")
    ap.add_argument("--summarise", action="store_true", help="summarise the run already in OUT")
    add_json_option(ap)
    args = ap.parse_args()
    timing = args.out / "real_clip_wall.json"           # the run's wall time, for --summarise later
    if args.summarise:
        made = json.loads(timing.read_text()) if timing.is_file() else {}
        wall, args.workers = made.get("wall_s"), made.get("workers")
    else:
        wall = run(args.out, args.frames, args.workers, args.kinds)
        timing.write_text(json.dumps({"wall_s": wall, "frames": args.frames, "workers": args.workers}))
    records = sequence_records(args.out, KINDS[args.kinds])
    n = max(len(v) for v in records.values())
    figures = {"frames": n, "workers": args.workers, "wall_s": wall,
               "wall_s_per_frame": None if wall is None else wall / n,
               "kinds": {k: per_kind(v) for k, v in records.items() if v}}
    if wall is not None:
        print(f"{n} frames in {wall:.1f} s: {wall / n:.2f} s a frame, everything included")
    for kind, f in figures["kinds"].items():
        print(f"{kind}: curve RMS {f['curve_rms_px']:.2f} px, image RMS {f['image_rms']:.4f}, mouth "
              f"{f['mouth_rms']:.4f}, lips within 5 % on {f['lips_within_5pct']} of {f['frames']}, jitter "
              f"{f['jitter']:.3f}, flagged {f['flagged']}")
        print("  seconds a frame: " + ", ".join(f"{s} {v:.2f}" for s, v in f["seconds_per_frame"].items()))
        print("  accepted steps a frame: " + ", ".join(f"{s} {v:.1f}" for s, v in f["steps_per_frame"].items())
              + (f"; solves {f['solves_per_frame']:.1f}, Newton iterations {f['newton_iterations_per_frame']:.1f}"
                 if np.isfinite(f["solves_per_frame"]) else ""))
    write_json(args.json, figures)


if __name__ == "__main__":
    main()
