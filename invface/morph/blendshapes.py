"""Import an actor's blendshapes (OBJ/PLY files sharing the neutral's topology)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import MeshError
from ..io.meshes import read_mesh
from ..model.arkit import ARKIT_NAMES

SUFFIXES = (".obj", ".ply")


def _canonical(name):
    """ARKit names written with _L/_R (ICT-FaceKit style) -> ARKit spelling, for recognition."""
    for s, full in (("_L", "Left"), ("_R", "Right")):
        if name.endswith(s):
            return name[: -len(s)] + full
    return name


def recognised(name):
    """'ARKit', 'FACS' or None for a blendshape name."""
    from ..template.expressions import ACTION_UNITS
    if _canonical(name) in ARKIT_NAMES:
        return "ARKit"
    if name in ACTION_UNITS or name.upper().startswith("AU"):
        return "FACS"
    return None


def read_blendshapes(folder, n_vertices, neutral_raw):
    """(names, deltas (K,n,3) in file units) from every OBJ/PLY in ``folder`` (sorted by
    name), each with ``n_vertices`` vertices in the neutral's order. The neutral itself, if
    present in the folder, is skipped."""
    folder = Path(folder)
    if not folder.is_dir():
        raise MeshError(f"{folder}: blendshape folder not found")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() in SUFFIXES)
    if not files:
        raise MeshError(f"{folder}: no .obj or .ply blendshape files")
    names, deltas = [], []
    for p in files:
        V, _ = read_mesh(p)
        if len(V) != n_vertices:
            raise MeshError(f"{p}: {len(V)} vertices, but the neutral has {n_vertices}: blendshapes "
                            "must share the neutral's topology (same vertices, same order)")
        d = V - neutral_raw
        if not np.isfinite(d).all():
            raise MeshError(f"{p}: NaN or infinite vertex positions")
        if np.abs(d).max() <= 1e-7 * np.ptp(neutral_raw):
            continue                       # the neutral itself (to the file's print precision)
        names.append(p.stem)
        deltas.append(d)
    if len(set(names)) != len(names):
        raise MeshError(f"{folder}: two files give the same blendshape name")
    return names, np.array(deltas)
