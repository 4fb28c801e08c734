"""Small faces in wide frames: each real photo's face pasted into a 2000x1500 frame at 1/25 and
1/50 of its width, found by the landmark detector (the whole frame, then crops around face
proposals), and its points against the photo's own detection scaled and moved.

    python bench/small_faces.py [--photos DIR] [--json F]

Prints per photo and size: found or not, the median point error as a share of the face's
width, seconds. The photos are ../shared/data/real/photos (not used to tune the proposals:
those were set on scikit-image's astronaut, tests/test_landmarks.py).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import cv2
import numpy as np
from _common import SHARED, add_json_option, write_json

from invface.errors import InvfaceError
from invface.fit.landmarks import detect_landmarks
from invface.io.images import linear_to_srgb, read_image


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--photos", type=Path, default=SHARED / "real" / "photos")
    add_json_option(ap)
    a = ap.parse_args()
    if not a.photos.is_dir():
        print(f"skipped: no photos at {a.photos}")
        return
    W, H = 2000, 1500
    rows = []
    for path in sorted(p for p in a.photos.iterdir() if p.suffix.lower() in (".png", ".jpg", ".jpeg")):
        photo = (np.clip(linear_to_srgb(read_image(path)[0]), 0, 1) * 255 + 0.5).astype(np.uint8)
        try:
            own = detect_landmarks(photo, path.name)
        except InvfaceError:
            print(f"{path.name}: no face in the photo itself; skipped")
            continue
        width = np.ptp(own[:, 0])
        for share in (1 / 25, 1 / 50):
            k = share * W / width
            small = cv2.resize(photo, (max(1, round(photo.shape[1] * k)), max(1, round(photo.shape[0] * k))),
                               interpolation=cv2.INTER_AREA)
            frame = np.full((H, W, 3), 96, np.uint8)
            x0, y0 = 1300, 600
            frame[y0:y0 + small.shape[0], x0:x0 + small.shape[1]] = small[:H - y0, :W - x0]
            expect = np.stack([x0 + (own[:, 0] + 0.5) * k - 0.5, y0 + (own[:, 1] + 0.5) * k - 0.5], 1)
            t = time.perf_counter()
            try:
                got = detect_landmarks(frame, path.name)
                err = float(np.median(np.linalg.norm(got - expect, axis=1)) / np.ptp(expect[:, 0]))
            except InvfaceError:
                err = None
            sec = time.perf_counter() - t
            print(f"{path.name:28s} face 1/{round(1 / share)} ({np.ptp(expect[:, 0]):.0f} px): "
                  + ("NOT found" if err is None else f"found, median error {100 * err:.1f} % of its width")
                  + f", {sec:.1f} s", flush=True)
            rows.append({"photo": path.name, "share": share, "face_px": float(np.ptp(expect[:, 0])),
                         "found": err is not None, "median_error_of_width": err, "seconds": sec})
    found = sum(r["found"] for r in rows)
    print(f"found {found} of {len(rows)}")
    write_json(a.json, {"found": found, "cases": len(rows), "rows": rows})


if __name__ == "__main__":
    main()
