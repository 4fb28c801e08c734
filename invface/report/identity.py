"""The actor's identity on a run's page: how far the adapted head is from the model it came
from, and the face-shape space's coefficients."""
from __future__ import annotations

import numpy as np

from ..io.images import save_figure

NAME = "identity.png"


def write_identity_figure(path, before, after, triangles, coefficients=()):
    """One PNG at ``path``: the adapted neutral ``after`` (V,3) m front on and from the actor's
    left, coloured by its distance from ``before`` (V,3) m (magma, 0 to its 99th percentile,
    in mm), and the face-shape space's ``coefficients`` (K,) in standard deviations. Returns
    the file's name."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import colormaps

    from ..render.preview import look_at_camera, render_meshes, to_srgb8
    d = np.linalg.norm(np.asarray(after) - np.asarray(before), axis=1) * 1000
    vmax = max(float(np.percentile(d, 99)), 0.1)
    colours = colormaps["magma"](np.clip(d / vmax, 0, 1))[:, :3]
    c = after.mean(0)
    size = float(np.ptp(after, axis=0).max())
    tiles = [to_srgb8(render_meshes([(after, triangles, colours)],
                                    look_at_camera(c + np.array(eye) * 2.2 * size, c, width=300, height=300, spp=16),
                                    key_dir=(0, 0.3, 1.0)))
             for eye in ((0, 0, 1), (0.8, 0, 0.6))]
    coefficients = np.asarray(coefficients, float)
    fig, axes = plt.subplots(1, 3 if len(coefficients) else 2, figsize=(11 if len(coefficients) else 7, 3.4), dpi=110,
                             gridspec_kw={"width_ratios": [1, 1, 1.4][:3 if len(coefficients) else 2]})
    for ax, tile, title in zip(axes, tiles, ("front", "from the actor's left")):
        ax.imshow(tile)
        ax.set_axis_off()
        ax.set_title(f"{title}: moved 0-{vmax:.1f} mm (median {np.median(d):.1f})", fontsize=8)
    if len(coefficients):
        ax = axes[2]
        ax.bar(range(len(coefficients)), coefficients, color="#2c7fb8")
        ax.axhline(0, color="#555", lw=0.5)
        ax.set_xticks(range(len(coefficients)))
        ax.set_xticklabels([str(i) for i in range(len(coefficients))], fontsize=6)
        ax.set_ylabel("standard deviations")
        ax.set_title(f"face-shape space (ICT-FaceKit identities): |c| = {np.linalg.norm(coefficients):.2f}", fontsize=8)
    fig.tight_layout()
    try:
        return save_figure(path, fig).name
    finally:
        plt.close(fig)
