"""Eq. 16's curve weight lambda_1 on a real clip: curve and image RMS after the shading stage.

    python bench/shading_weight.py --model DIR/actor.npz --calib DIR/calib.npz
                                   [--video ../shared/data/real/video/single_face.mp4]
                                   [--frames 0:72:24] [--lambdas 1e-4,1e-3,1e-2,1e-1]

Each selected frame is fitted alone (blendshape kind, the curves of Eq. 15, then shading,
``fit.plate.fit_plate``) with ``fit.shading.fit_shading``'s lambda_1 set to each value; prints
the curve RMS (px), the image RMS (linear) and the seconds. The model and calibration are a
sequence run's (``invface fit-plate CLIP.mp4 -o DIR`` writes both).
"""
import argparse
import functools
import time

from _common import SHARED

import invface
import invface.fit.plate as plate_fit
from invface.fit.calibrate import Calibration
from invface.fit.shading import fit_shading
from invface.pipeline import find_curves, open_clip

VIDEO = SHARED / "real" / "video" / "single_face.mp4"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--model", required=True)
    ap.add_argument("--calib", required=True)
    ap.add_argument("--video", default=str(VIDEO))
    ap.add_argument("--frames", default="0:72:24")
    ap.add_argument("--lambdas", default="1e-4,1e-3,1e-2,1e-1")
    a = ap.parse_args()
    m = invface.FaceModel.load(a.model)
    cal = Calibration.load(a.calib, vertex_count=len(m.neutral))
    frames = list(open_clip(a.video, a.frames).frames())
    curves = [find_curves(m, f.plate, None)[0] for f in frames]
    for lam1 in (float(v) for v in a.lambdas.split(",")):
        plate_fit.fit_shading = functools.partial(fit_shading, lam1=lam1)
        for f, c in zip(frames, curves):
            t = time.perf_counter()
            pf = plate_fit.fit_plate(m, f.plate, cal, c, kind="blendshape", shading=True)
            print(f"lambda_1 {lam1:g} {f.name}: curves {pf.curve_rms_px:.2f} px, image RMS {pf.image_rms:.4f}, "
                  f"{time.perf_counter() - t:.0f} s", flush=True)


if __name__ == "__main__":
    main()
