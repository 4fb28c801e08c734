"""Reading triangle meshes (OBJ, PLY) through trimesh, with errors that name the file."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import MeshError


def read_mesh(path):
    """(vertices (n,3), faces (f,3)) of an OBJ/PLY file in its own units, unprocessed."""
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise MeshError(f"{path}: mesh file not found")
    try:
        mesh = trimesh.load(path, process=False, force="mesh")
    except Exception as e:  # noqa: BLE001 - trimesh raises many kinds
        raise MeshError(f"{path}: not a readable mesh ({e})") from None
    V = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), float)
    F = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), np.int64)
    if len(V) == 0 or len(F) == 0:
        raise MeshError(f"{path}: the file holds no triangle mesh")
    return V, F
