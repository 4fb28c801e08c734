"""The real photos end to end (issue 26): one ``fit-plate`` command per photo, both model kinds.

    python bench/real_photos.py OUT [--photos DIR] [--model-kind both] [--report-only]

Runs ``invface fit-plate PHOTO --model-kind both -o OUT/<name>`` (or one kind) for every JPEG/PNG in DIR
(default ``../shared/data/real/photos``), then prints per photo and kind: curve RMS (px), curves
within 2 px, the fit's seconds, the lips' volume change, the image RMS (linear) in the mouth
(inside the outer lip curves) and over the face (``mouth_rms.py``), the blendshape weights above
0.05, the simulation's muscles activated above 0.05 (paper 000 Fig. 6's sparsity), every
curve over 2 px, each eye's gaze (yaw, pitch rad) and its pupil's distance from the plate's
iris (px), and the fitted ARKit values against MediaPipe's own scores. With
``--report-only`` it prints the table of an earlier run in OUT.
"""
import argparse
import json
import subprocess
import sys
import time
from pathlib import Path

from _common import SHARED

from mouth_rms import npz_region_rms

PHOTOS = SHARED / "real" / "photos"


def table(out):
    for d in sorted(p for p in out.iterdir() if p.is_dir()):
        for kind in ("blendshape", "simulation"):
            f = d / kind / "fit.json"
            if not f.is_file():
                print(f"{d.name:16s} {kind:10s} missing")
                continue
            s = json.loads(f.read_text())
            by = s["curve_rms_px_by_curve"]
            over = ", ".join(f"{n} {v:.1f}" for n, v in sorted(by.items()) if v > 2)
            img = npz_region_rms(d / kind / "fit.npz")
            muscles = sum(v > 0.05 for v in s.get("activations", {}).values())
            controls = sum(v > 0.05 for v in s["weights"].values())
            print(f"{d.name:16s} {kind:10s} {s['curve_rms_px']:.2f} px  {sum(v <= 2 for v in by.values())}/{len(by)}"
                  f"  {s['seconds']['total']:5.1f} s  lips {100 * s['lip_volume_change']:+.1f} %  image RMS mouth "
                  f"{img['mouth'][0]:.4f} face {img['face'][0]:.4f}  weights > 0.05: {controls}"
                  + (f", muscles > 0.05: {muscles}/{len(s['activations'])}" if kind == "simulation" else "")
                  + f"  over 2 px: {over}"
                  + "  gaze " + " ".join(f"{e} yaw {a['yaw']:+.2f} pitch {a['pitch']:+.2f}" for e, a in s.get("eyes", {}).items())
                  + "  iris px " + " ".join(f"{v:.1f}" for v in s.get("iris_px", {}).values())
                  + peer_line(s))


def peer_line(s, top=4):
    """The fit's ARKit values against MediaPipe's own scores: mean |difference| and the largest."""
    peer = s.get("peer_arkit") or {}
    diff = peer.get("fitted_minus_peer") or {}
    if not diff:
        return ""
    worst = sorted(diff.items(), key=lambda kv: -abs(kv[1]))[:top]
    return (f"  vs MediaPipe: mean |d| {peer['mean_abs_difference']:.3f}, largest "
            + ", ".join(f"{k} {peer['scores'][k]:.2f}->{s['arkit'][k]:.2f}" for k, _ in worst))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path)
    ap.add_argument("--photos", type=Path, default=PHOTOS)
    ap.add_argument("--report-only", action="store_true")
    ap.add_argument("--model-kind", default="both", choices=("both", "blendshape", "simulation"))
    a = ap.parse_args()
    if not a.report_only:
        photos = sorted(p for p in a.photos.iterdir() if p.suffix.lower() in (".jpg", ".jpeg", ".png"))
        if not photos:
            sys.exit(f"{a.photos}: no photos")
        a.out.mkdir(parents=True, exist_ok=True)
        for p in photos:
            t = time.perf_counter()
            with open(a.out / f"{p.stem}.log", "w") as log:
                rc = subprocess.call(["invface", "fit-plate", str(p), "--model-kind", a.model_kind, "-o", str(a.out / p.stem)],
                                     stdout=log, stderr=subprocess.STDOUT)
            print(f"{p.stem}: exit {rc}, {time.perf_counter() - t:.0f} s wall", flush=True)
    table(a.out)


if __name__ == "__main__":
    main()
