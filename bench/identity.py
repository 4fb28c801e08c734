"""The actor's identity from one frame, checked on the frames it was not fitted on (issue 28).

    python bench/identity.py [--video ../shared/data/real/video/single_face.mp4] [--frames 0:72:6]
                             [--length 0.007] [--silhouette 0.3] [--fit-frame 0]

Detects the curves of the selected frames (image mode), fits Eq. 15 (blendshape kind, curves
only) on ``--fit-frame``, fits the identity there (``fit.identity``: the proportions, then a field
of smoothness ``--length`` m, the jaw line weighted ``--silhouette`` in it),
then fits every selected frame with the model as it is and with the corrected neutral, and
prints each frame's curve RMS before -> after.
"""
import argparse
import time

from _common import SHARED

import invface
from invface.fit.curves import fit_curves
from invface.fit.identity import SILHOUETTE_WEIGHT, fit_identity
from invface.pipeline import find_curves, open_clip
from invface.pipeline.plates import curve_lambda

VIDEO = SHARED / "real" / "video" / "single_face.mp4"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--video", default=str(VIDEO))
    ap.add_argument("--frames", default="0:72:6")
    ap.add_argument("--length", type=float, default=0.007)
    ap.add_argument("--silhouette", type=float, default=SILHOUETTE_WEIGHT)
    ap.add_argument("--fit-frame", type=int, default=0, help="position in the selection")
    a = ap.parse_args()
    m = invface.template.build()
    frames = list(open_clip(a.video, a.frames).frames())
    curves = [find_curves(m, f.plate, None)[0] for f in frames]

    def fit(model, i):
        return fit_curves(model, frames[i].plate.camera, curves[i], lam=curve_lambda(curves[i]))

    f0, t = fit(m, a.fit_frame), time.perf_counter()
    idf = fit_identity(m, frames[a.fit_frame].plate.camera, curves[a.fit_frame], f0.p, f0.rotation, f0.translation,
                       length=a.length, silhouette=a.silhouette)
    print(f"{frames[a.fit_frame].name}: {idf.describe()} ({time.perf_counter() - t:.1f} s)")
    adapted = m.replace(neutral=m.neutral + idf.displacement)
    for i, f in enumerate(frames):
        print(f"{f.name}: curve RMS {fit(m, i).rms_px:.2f} -> {fit(adapted, i).rms_px:.2f} px", flush=True)


if __name__ == "__main__":
    main()
