"""Contact sheet of a FaceModel's expression blendshapes (front and 3/4 views, labelled)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import SimulationError
from ..io.images import save_figure, write_display_image
from ..render.preview import look_at_camera, render_meshes, to_srgb8
from .preview import SKIN, VIEWS, parts_meshes


# controls that mean something only over another: ARKit's mouthClose closes the lips of an
# open jaw, and tongueOut shows the tongue through an open mouth; both are shown over jawOpen 1.0
SHOWN_OVER = {"mouthClose": "jawOpen", "tongueOut": "jawOpen"}


def blendshape_pose(model, name):
    """Controls that show blendshape ``name`` as simulated: weight 1 and its paired jaw (over
    ``SHOWN_OVER``'s control at 1 and its jaw, where the model has it)."""
    jaws = model.meta.get("blendshape_jaw", {})
    base = SHOWN_OVER.get(name)
    if base in model.blendshape_names:
        return {"weights": {base: 1.0, name: 1.0}, "jaw": jaws.get(base, [0.0] * 6)}
    return {"weights": {name: 1.0}, "jaw": jaws.get(name, [0.0] * 6)}


def view_tiles(model, x, size=256, spp=8, w=None):
    """Renders (one per VIEWS entry, front then 3/4) of surface positions x (V,3), sRGB uint8,
    with the inner parts (eyes, teeth, mouth) at controls w."""
    cams = [look_at_camera(np.array(eye), (0.0, 0.0, 0.06), fov=19, width=size, height=size, spp=spp)
            for eye in VIEWS.values()]
    meshes = [(x, model.triangles, SKIN)] + parts_meshes(model, w)
    return [to_srgb8(render_meshes(meshes, cam)) for cam in cams]


def write_expression_sheet(model, path, size=256, spp=8, cols=6, progress=None, kind="blendshape"):
    """Render neutral + every blendshape (front and 3/4) into one labelled PNG; returns path.

    kind: the surface model that poses each shape ('blendshape', or 'simulation' for the
    blendshape-driven muscle simulation, paper 000 Sec. 6)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = ["neutral"] + list(model.blendshape_names)
    rows = int(np.ceil(len(names) / cols))
    fig, axes = plt.subplots(rows, cols, figsize=(cols * 3.2, rows * 1.75), dpi=100)
    for ax in np.ravel(axes):
        ax.axis("off")
    for i, name in enumerate(names):
        if progress:
            progress(f"render {name}")
        w = None if name == "neutral" else blendshape_pose(model, name)
        ax = np.ravel(axes)[i]
        title = name + (f" (over {SHOWN_OVER[name]})" if w and len(w["weights"]) > 1 else "")
        try:
            x = model.neutral if w is None else model.surface(w, kind=kind)
        except SimulationError:
            ax.set_title(f"{title}: no equilibrium", fontsize=9)
            continue
        ax.imshow(np.concatenate(view_tiles(model, x, size, spp, w), 1))
        ax.set_title(title, fontsize=9)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        return save_figure(path, fig)
    finally:
        plt.close(fig)


def write_pose_preview(model, x, path, size=400, spp=16, w=None):
    """One PNG: the neutral (top) and the posed skin x (V, 3) m at controls w (bottom),
    front and 3/4, written atomically; returns the path."""
    img = np.concatenate([np.concatenate(view_tiles(model, v, size, spp, c), 1)
                          for v, c in ((model.neutral, None), (x, w))], 0)
    return write_display_image(path, img)
