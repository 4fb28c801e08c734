"""Reading triangle meshes (OBJ, PLY) through trimesh, with errors that name the file."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from ..errors import MeshError


def read_mesh(path):
    """(vertices (n,3), faces (f,3)) of an OBJ/PLY file in its own units, unprocessed, in the
    file's vertex order (an OBJ's vertices are not split at texture seams), so per-vertex data
    that refers to the file by index (blendshape deltas, landmark ids) stays valid."""
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise MeshError(f"{path}: mesh file not found")
    order = {"maintain_order": True} if path.suffix.lower() == ".obj" else {}
    try:
        with warnings.catch_warnings():      # trimesh's texture bookkeeping warns on seams
            warnings.simplefilter("ignore", RuntimeWarning)
            mesh = trimesh.load(path, process=False, force="mesh", **order)
    except Exception as e:  # noqa: BLE001 - trimesh raises many kinds
        raise MeshError(f"{path}: not a readable mesh ({e})") from None
    V = np.asarray(getattr(mesh, "vertices", np.zeros((0, 3))), float)
    F = np.asarray(getattr(mesh, "faces", np.zeros((0, 3))), np.int64)
    if len(V) == 0 or len(F) == 0:
        raise MeshError(f"{path}: the file holds no triangle mesh")
    return V, F


def write_mesh(path, vertices, faces):
    """Write a triangle mesh (OBJ/PLY by suffix) through a temporary file and a rename."""
    import os

    import trimesh
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.stem + ".tmp" + path.suffix)
    trimesh.Trimesh(np.asarray(vertices, float), np.asarray(faces), process=False).export(tmp)
    os.replace(tmp, path)
    return path
