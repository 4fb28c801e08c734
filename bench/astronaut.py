"""A real photograph (issue 6): the public-domain astronaut portrait shipped in scikit-image
(``skimage.data.astronaut()``, 512x512, NASA), fitted with the built-in model.

    python bench/astronaut.py [--resolution 1] [--kinds blendshape,simulation] [-o reports/astronaut]

1. Curves and mask: the MediaPipe landmark detector (``invface.fit.landmarks``) gives the
   eyelid, lip, nose and jaw curves and the face oval, which masks calibration and shading.
2. Pose: the photo's camera is unknown; the default front camera (30 degree horizontal field
   of view) is assumed, and the pose and expression come from the curves (Eq. 15,
   ``invface calibrate --auto-pose``, ``invface.pipeline.auto_calibrate``). The paper's weights
   are scaled by the face's area in pixels, (d / 224)^2 with d the outer eye-corner distance
   (224 px on the sample plates; ``invface.fit.lambdas.face_scale``): lambda_1 of Eq. 15 (its
   residuals are pixels) and lambda of Eq. 14 (its data term sums over the face's pixels, its
   smoothness over the model's vertices).
3. Calibration (Eq. 14) of SH light and albedo on the photo, with the curve-fitted shape.
4. Plate fit (Eq. 15-16) with each model kind; the report (reports/astronaut/index.html)
   shows plate, render, wipe, error map and the curves; the script prints the curve
   reprojection error per curve in pixels.

The astronaut is not the person the built-in model was made from: the remaining curve and
image error is mostly identity (face proportions, nose, lip shape), which the expression
controls cannot and should not absorb. The report says so.

Needs ``pip install scikit-image`` and the detector (``invface.fit.landmarks.INSTALL``).
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from invface import pipeline
from invface.errors import InvfaceError
from invface.fit import landmarks
from invface.fit.lambdas import face_scale
from invface.render.plates import load_plate, write_image, srgb_to_linear

NOTES = ["The astronaut (skimage.data.astronaut(), public domain) is a different person from the built-in "
         "model: the remaining curve and image error is mostly identity (proportions, nose and lip shape), "
         "not expression; the expression controls cannot absorb it.",
         "The photo's camera is unknown: the default front camera (30 degree field of view) is assumed, "
         "and the pose comes from the detector's curves."]


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolution", type=float, default=1.0, help="template size factor")
    ap.add_argument("--kinds", default="blendshape,simulation", help="model kinds to fit")
    ap.add_argument("--iterations", type=int, default=25, help="shape-from-shading iterations at most")
    ap.add_argument("-o", "--output", default="reports/astronaut")
    a = ap.parse_args()
    try:
        from skimage.data import astronaut
    except ImportError:
        sys.exit("this script needs scikit-image: pip install scikit-image")
    if not landmarks.available():
        sys.exit("this script needs the landmark detector: " + landmarks.INSTALL)
    out = Path(a.output)
    t0 = time.perf_counter()
    photo = write_image(out / "astronaut.png", srgb_to_linear(astronaut() / 255.0))
    model = pipeline.load_model(resolution=a.resolution)
    plate = load_plate(photo)
    try:
        curves, source = pipeline.find_curves(model, plate)
        scale, eye_px = face_scale(curves)
        calib = pipeline.auto_calibrate(model, plate, curves, source)
        print(f"face: {eye_px:.0f} px between the outer eye corners; lambda_1 = {calib.pose.lam:.0f} (Eq. 15), "
              f"lambda = {calib.calibration.lam:.0f} (Eq. 14); face mask {int(plate.mask.sum())} px")
        print(calib.pose.describe())
        print(calib.describe())
        calib.save(out / "calib.npz")
        frame = pipeline.fit_frame(model, plate, calib, curves, kinds=a.kinds.split(","), iterations=a.iterations,
                                   source=source, notes=NOTES,
                                   title="invface: the astronaut photo (a real face, another identity)")
        print(f"report: {frame.save(out)}")
    except InvfaceError as e:
        sys.exit(f"error: {e}")
    for kind, fit in frame.fits.items():
        print(frame.describe(kind))
        per = ", ".join(f"{k} {np.sqrt(np.mean(v ** 2)):.2f}" for k, v in fit.residual_px.items())
        print(f"{kind}: curve reprojection RMS {fit.curve_rms_px:.2f} px ({per})")
    print(f"total {time.perf_counter() - t0:.1f} s")


if __name__ == "__main__":
    main()
