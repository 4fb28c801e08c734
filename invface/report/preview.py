"""Preview sheets of a FaceModel: skin, skin+muscles, bone, tet cut-away, jaw open.

Writes PNG files (front and 3/4 views) into a folder; used by ``invface build-model
--preview DIR`` and the demo.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..mesh.tets import boundary_faces
from ..io.images import write_display_image
from ..render.preview import look_at_camera, render_meshes, to_srgb8

SKIN = (0.80, 0.60, 0.50)
BONE = (0.92, 0.88, 0.74)
TOOTH = (0.97, 0.96, 0.92)
VIEWS = {"front": (0.0, 0.03, 0.62), "three_quarter": (0.40, 0.05, 0.47)}   # camera positions, m


def _muscle_colors(n):
    import matplotlib
    cmap = matplotlib.colormaps["tab20"]
    return [cmap(i % 20)[:3] for i in range(n)]


def _muscle_meshes(model):
    """Every muscle as a smooth spindle (a ring as a torus) around its centre-line, as wide
    at its belly as its tets reach there (the 90th percentile of their centroids' distance to
    the line), tapering to 40 % at origin and insertion (mesh.tube.spindle), and half as thick
    under the skin: the mimic muscles are straps."""
    from scipy.spatial import cKDTree

    from ..mesh.sections import resample_even
    from ..mesh.tube import spindle, tube
    out = []
    cent = model.rest_positions[model.tets].mean(1)
    middle = model.rest_positions.mean(0)
    for m, c in zip(model.muscles, _muscle_colors(len(model.muscles))):
        line = np.asarray(m.centerline, float)
        closed = len(line) > 2 and np.allclose(line[0], line[-1])
        pts = resample_even(line, 40)
        dist, idx = cKDTree(pts).query(cent[m.tets])
        prof = spindle(len(pts), closed)
        belly = prof[idx] > 0.9
        radius = np.percentile(dist[belly], 90) if belly.any() else 0.003
        V, F = tube(pts, radius * prof, closed=closed, up=pts - middle, flatten=0.5)
        out.append((V, F, tuple(0.35 + 0.65 * np.array(c))))
    return out


def parts_meshes(model, w=None):
    """The inner parts (eyes, teeth, tongue, mouth lining) at controls w as preview meshes
    (V, F, per-vertex colours), brightened like the preview's skin; [] without parts."""
    if model.parts is None:
        return []
    from ..render.shading import SKIN_ALBEDO
    gain = np.mean(np.asarray(SKIN) / SKIN_ALBEDO)
    return [(model.parts_positions(w), model.parts.triangles, np.clip(model.parts.albedo * gain, 0, 1))]


def _half(V, F, keep_left):
    """Triangles of the actor's left (x > 0) or right half."""
    cx = V[F].mean(1)[:, 0]
    return F[(cx > 0) == keep_left]


def scenes(model, jaw_open=0.25):
    """name -> list of meshes (V, F, color) to render."""
    V, F = model.neutral, model.triangles
    X, T = model.rest_positions, model.tets
    bone = [(model.cranium_mesh[0], model.cranium_mesh[1], BONE), (model.jaw_mesh[0], model.jaw_mesh[1], (0.75, 0.82, 0.95))]
    if model.parts is not None:     # the teeth in the skull
        bone += [model.parts.mesh(n) + (TOOTH,) for n in ("upper_teeth", "lower_teeth") if n in model.parts.names]
    cut = T[X[T].mean(1)[:, 0] < 0.0]
    cut_faces, owner = boundary_faces(cut)
    cut_is_plane = np.abs(X[cut_faces].mean(1)[:, 0]) < 0.004
    in_muscle = np.zeros(len(T), bool)
    for m in model.muscles:
        in_muscle[m.tets] = True
    tet_ids = np.nonzero(X[T].mean(1)[:, 0] < 0.0)[0][owner]
    opened = {"jaw": [jaw_open, 0, 0, 0, 0, 0]}
    open_x = model.surface(opened)
    return {
        "skin": [(V, F, SKIN)] + parts_meshes(model),
        "skin_muscles": [(V, _half(V, F, False), SKIN)] + _muscle_meshes(model),
        "bone": bone,
        "tets_cutaway": [(X, cut_faces[~cut_is_plane], SKIN),
                         (X, cut_faces[cut_is_plane & ~in_muscle[tet_ids]], (0.95, 0.85, 0.8)),
                         (X, cut_faces[cut_is_plane & in_muscle[tet_ids]], (0.85, 0.25, 0.2))],
        "jaw_open": [(open_x, F, SKIN)] + parts_meshes(model, opened),
    }


def write_previews(model, folder, size=480, spp=16):
    """Render every preview scene from each view into ``folder``; returns the PNG paths."""

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    rows = []
    for name, meshes in scenes(model).items():
        row = []
        for view, eye in VIEWS.items():
            eye = np.array(eye)
            if name == "tets_cutaway":   # look at the sagittal cut (x = 0) from the actor's left
                eye = np.array([0.6, 0.05, 0.12]) if view == "front" else np.array([0.45, 0.1, 0.42])
            cam = look_at_camera(eye, (0.0, 0.02, 0.04), fov=30, width=size, height=size, spp=spp)
            img = to_srgb8(render_meshes(meshes, cam))
            p = folder / f"{name}_{view}.png"
            paths.append(write_display_image(p, img))
            row.append(img)
        rows.append(np.concatenate(row, 1))
    sheet = folder / "contact_sheet.png"
    write_display_image(sheet, np.concatenate(rows, 0))
    paths.append(sheet)
    return paths
