"""The shared photos as VFX would deliver them (issue 60 item 0): each photo converted to a
10-bit Cineon-log DPX and a half-float EXR, fitted with the rig, against 3 runs of the original.

    python bench/plate_formats.py OUT [--photos DIR] [--runs 3] [--json figures/plate_formats.json]

Per photo, the JPEG is read into linear light (sRGB decoding), written as ``NAME.dpx`` (10-bit
codes, Kodak Cineon log, header transfer "Printing density": read back as Cineon by default)
and ``NAME.exr`` (half floats, linear), and each file is fitted by
``invface fit-plate FILE --model-kind blendshape``. The figures: the largest distance (px)
between the fitted model curves of a converted file and of the original's first run, next to
the same distance between the original's runs (the run-to-run spread), and the curve RMS of
each.
"""
import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from _common import REPO, SHARED, write_json

PHOTOS = SHARED / "real" / "photos"


def convert(photo, folder):
    """Write the photo as NAME.dpx (Cineon log, 10-bit) and NAME.exr (half); return their paths."""
    import OpenImageIO as oiio
    from invface.io.colorspaces import from_linear
    from invface.io.images import load_image
    lin = load_image(photo).rgb
    paths = []
    for ext, td, attrs, code in ((".dpx", oiio.UINT16, {"oiio:BitsPerSample": 10, "dpx:Transfer": "Printing density"},
                                  from_linear(lin, "Cineon")), (".exr", oiio.HALF, {}, lin)):
        path = folder / (photo.stem + ext)
        spec = oiio.ImageSpec(lin.shape[1], lin.shape[0], 3, td)
        for k, v in attrs.items():
            spec.attribute(k, v)
        if ext == ".dpx":        # exact 10-bit codes in OpenImageIO's 16-bit container
            code = np.round(np.clip(code, 0, 1) * 1023).astype(np.uint16) * 64 + np.uint16(32)
        out = oiio.ImageOutput.create(str(path))
        out.open(str(path), spec)
        out.write_image(np.ascontiguousarray(code))
        out.close()
        paths.append(path)
    return paths


def fit(plate, out):
    """Run fit-plate (rig only) on one file; returns (fit.json, fit.npz's model curves, seconds)."""
    t = time.perf_counter()
    env = dict(os.environ, PYTHONPATH=str(REPO))
    log_path = out.parent / (out.name + ".log")
    with open(log_path, "w") as log:
        rc = subprocess.call([sys.executable, "-m", "invface.cli", "fit-plate", str(plate), "--model-kind", "blendshape",
                              "-o", str(out)], stdout=log, stderr=subprocess.STDOUT, env=env)
    if rc:
        sys.exit(f"{plate}: fit-plate failed (exit {rc}); see {log_path}")
    s = json.loads((out / "blendshape" / "fit.json").read_text())
    d = np.load(out / "blendshape" / "fit.npz")
    curves = {str(n): d[f"model_curve_{i}"] for i, n in enumerate(d["curve_names"])}
    return s, curves, time.perf_counter() - t


def distance(a, b):
    """Largest distance (px) between the same model curves' points of two fits."""
    return max(float(np.linalg.norm(a[n] - b[n], axis=1).max()) for n in a if n in b)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", type=Path)
    ap.add_argument("--photos", type=Path, default=PHOTOS)
    ap.add_argument("--runs", type=int, default=3, help="runs of each original")
    ap.add_argument("--json", type=Path, default=REPO / "bench" / "figures" / "plate_formats.json")
    a = ap.parse_args()
    photos = sorted(p for p in a.photos.iterdir() if p.suffix.lower() in (".jpg", ".jpeg", ".png"))
    if not photos:
        print(f"skipped: no photos in {a.photos}")
        return
    a.out.mkdir(parents=True, exist_ok=True)
    rows = []
    for photo in photos:
        runs = [fit(photo, a.out / f"{photo.stem}.orig{r}") for r in range(a.runs)]
        spread = max([distance(runs[0][1], r[1]) for r in runs[1:]] or [0.0])
        row = {"photo": photo.name, "spread_px": spread, "rms_px": {"original": [r[0]["curve_rms_px"] for r in runs]},
               "seconds": {"original": [r[2] for r in runs]}, "distance_px": {}}
        for path in convert(photo, a.out):
            s, curves, sec = fit(path, a.out / path.name.replace(".", "_"))
            kind = path.suffix.lstrip(".")
            row["distance_px"][kind] = distance(runs[0][1], curves)
            row["rms_px"][kind] = s["curve_rms_px"]
            row["seconds"][kind] = sec
            row.setdefault("colorspace", {})[kind] = s.get("plate_colorspace")
        rows.append(row)
        print(f"{photo.stem:16s} run-to-run {spread:.3f} px; DPX {row['distance_px']['dpx']:.3f} px "
              f"({row['colorspace']['dpx']}), EXR {row['distance_px']['exr']:.3f} px; curve RMS original "
              + "/".join(f"{v:.3f}" for v in row["rms_px"]["original"])
              + f", DPX {row['rms_px']['dpx']:.3f}, EXR {row['rms_px']['exr']:.3f}", flush=True)
    write_json(a.json, {"photos": rows, "runs": a.runs})
    print(f"wrote {a.json}")


if __name__ == "__main__":
    main()
