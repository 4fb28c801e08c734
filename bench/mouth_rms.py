"""Image RMS of a plate fit in the mouth (inside the outer lip curves), in its opening
(inside the inner lip curves), in the eyes' openings (inside both lids' curves) and over the
face mask, from fit-plate run folders.

    python bench/mouth_rms.py RUN_DIR [RUN_DIR ...]     # reads RUN_DIR/{blendshape,simulation}/fit.npz
"""
import sys

import numpy as np

from invface.fit.regions import curve_regions


def npz_region_rms(fit_npz):
    """{region: (image RMS, pixels)} of one kind's fit.npz: mouth, opening, eyes, face."""
    z = np.load(fit_npz)
    d = z["render"] - z["plate"]
    names = list(z["curve_names"])
    regions = curve_regions({n: z[f"curve_{i}"] for i, n in enumerate(names)}, d.shape[:2])
    row = {k: (float(np.sqrt(np.mean(d[m] ** 2))), int(m.sum())) for k, m in regions.items()}
    face = z["mask"].astype(bool) if "mask" in z.files else np.ones(d.shape[:2], bool)
    row["face"] = (float(np.sqrt(np.mean(d[face] ** 2))), int(face.sum()))
    return row


if __name__ == "__main__":
    for folder in sys.argv[1:]:
        for kind in ("blendshape", "simulation"):
            try:
                row = npz_region_rms(f"{folder}/{kind}/fit.npz")
            except FileNotFoundError:
                continue
            print(folder, kind, " ".join(f"{k} {v[0]:.4f} ({v[1]} px)" for k, v in row.items()))
