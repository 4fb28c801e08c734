"""Preview sheet of a morphed model (build-model --neutral ... --preview DIR).

Row 1: the aligned target with its landmarks (red) and feature curves (blue), front and 3/4.
Row 2: the template with its landmarks and curves, the same views.
Row 3: the morphed skin; row 4: skin with the morphed muscles; row 5: the morphed bones.
When the build stops, ``write_failure_preview`` draws the scan with what was found.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io.images import write_display_image
from ..render.preview import look_at_camera, render_meshes, to_srgb8
from .preview import SKIN, VIEWS, scenes

GREY = (0.72, 0.72, 0.72)


def _dots(points, radius, color):
    import trimesh
    s = trimesh.creation.icosphere(1, radius=radius)
    P = np.asarray(points).reshape(-1, 3)
    V = (s.vertices[None] + P[:, None]).reshape(-1, 3)
    F = (s.faces[None] + len(s.vertices) * np.arange(len(P))[:, None, None]).reshape(-1, 3)
    return V, F, color


def marked_meshes(V, F, landmarks, curves, color):
    """Preview meshes of a surface with its landmarks (red) and curves (blue), either empty."""
    meshes = [(V, F, color)]
    if landmarks:
        meshes.append(_dots(list(landmarks.values()), 0.0022, (0.9, 0.1, 0.1)))
    if curves:
        meshes.append(_dots(np.concatenate(list(curves.values())), 0.0008, (0.1, 0.3, 0.95)))
    return meshes


def render_row(meshes, size, spp):
    """The meshes rendered from each of the preview VIEWS, side by side (size, size * views, 3) uint8."""
    row = []
    for eye in VIEWS.values():
        cam = look_at_camera(np.array(eye), (0.0, 0.02, 0.04), fov=30, width=size, height=size, spp=spp)
        row.append(to_srgb8(render_meshes(meshes, cam)))
    return np.concatenate(row, 1)


def write_morph_preview(model, result, folder, template=None, size=420, spp=12):
    """Write the morph contact sheet ``morph_sheet.png`` (and its panels) into ``folder``."""

    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    sc = scenes(model)
    rows = {"target": marked_meshes(result.aligned, result.target.faces, result.landmarks, result.curves, GREY)}
    if template is not None:
        rows["template"] = marked_meshes(template.neutral, template.triangles, result.template_landmarks,
                                   result.template_curves, SKIN)
    rows.update({"morphed_skin": sc["skin"], "muscles": sc["skin_muscles"], "bone": sc["bone"]})
    images = [render_row(meshes, size, spp) for meshes in rows.values()]
    sheet = folder / "morph_sheet.png"
    return write_display_image(sheet, np.concatenate(images, 0))


def write_failure_preview(found, folder, size=420, spp=12):
    """When the builder stopped (morph.build.BuildFailed.found): the aligned scan with the
    landmarks and curves found by then, front and 3/4, as ``failed_build.png`` in ``folder``.
    Returns its path, or None when the scan was never aligned."""

    if found.get("aligned") is None:
        return None
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    meshes = marked_meshes(found["aligned"], found["target"].faces, found.get("landmarks"), found.get("curves"), GREY)
    path = folder / "failed_build.png"
    return write_display_image(path, render_row(meshes, size, spp))
