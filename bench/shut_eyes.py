"""Shut and half-shut eyes fitted from their lids (issue 61 item 4, issue 59's "shut eyes are
fitted as half-open"): sample plates of the built-in head with both eyes shut, and half shut
with the left one squinting, rendered with the rig and fitted by ``invface.fit_plate`` (rig,
curve stage and shading), with the plate's curve file (the truth's lids, 0.3 px of noise) and
with the landmark detector on the render.

    python bench/shut_eyes.py [--resolution 1] [--json bench/figures/shut_eyes.json]

Prints per plate and curve source the fitted eyeBlink and eyeSquint, and the eye curves' RMS.
"""
import argparse
import shutil
import tempfile
import time
from pathlib import Path

import numpy as np

import invface
from invface.fit import samples

from _common import add_json_option, write_json

PLATES = {"shut": ({"eyeBlinkLeft": 1.0, "eyeBlinkRight": 1.0}, (0.03, -0.1, 0.0)),
          "half": ({"eyeBlinkLeft": 0.5, "eyeBlinkRight": 0.5, "eyeSquintLeft": 0.4}, (0.03, -0.1, 0.0))}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolution", type=float, default=1.0)
    add_json_option(ap)
    a = ap.parse_args()
    model = invface.template.build(resolution=a.resolution)
    samples.SAMPLES = {n: ("blendshape", w, None, rot, (0.0, 0.0, 0.0)) for n, (w, rot) in PLATES.items()}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        for path in samples.write_sample_plates(model, tmp / "with_curves"):
            bare = tmp / "detector" / path.name
            bare.parent.mkdir(exist_ok=True)
            shutil.copy(path, bare)
            shutil.copy(path.with_suffix(".json"), bare.with_suffix(".json"))
            for source, plate in (("curve file", path), ("detector", bare)):
                t = time.perf_counter()
                fit = invface.fit_plate(str(plate), model=model, kinds="blendshape")["blendshape"]
                w = fit.vector.weights_dict(fit.p)
                eyes = {k: float(np.sqrt(np.mean(v ** 2))) for k, v in fit.residual_px.items() if k.startswith("eye_")}
                row = {"plate": path.stem, "truth": PLATES[path.stem][0], "curves": source,
                       "fitted": {k: round(float(v), 3) for k, v in w.items() if k.startswith(("eyeBlink", "eyeSquint"))},
                       "eye_rms_px": eyes, "seconds": time.perf_counter() - t}
                rows.append(row)
                print(f"{path.stem:5s} {source:10s} " + " ".join(f"{k} {v:.2f}" for k, v in row["fitted"].items())
                      + f"  eye curves {max(eyes.values()):.2f} px max RMS  {row['seconds']:.1f} s", flush=True)
    write_json(a.json, {"resolution": a.resolution, "fits": rows})


if __name__ == "__main__":
    main()
