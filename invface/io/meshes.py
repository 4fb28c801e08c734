"""Triangle meshes in and out: OBJ/PLY/STL/OFF through trimesh (PLY triangle strips through
``plystrips``), and the binary PLY with vertex colours that Mitsuba reads. Errors name the file."""
from __future__ import annotations

import warnings
from pathlib import Path

import numpy as np

from ..errors import MeshError
from .atomic import atomic_open, atomic_path

MESH_EXTS = (".obj", ".ply", ".stl", ".off")


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
    points = len(V)
    if len(F) == 0 and path.suffix.lower() == ".ply":      # faces as triangle strips (scan archives)
        from .plystrips import read_tristrips, vertex_count
        V, F = read_tristrips(path) or (V, F)
        points = max(len(V), vertex_count(path))
    if len(V) == 0 or len(F) == 0:
        raise MeshError(f"{path}: the file holds no triangle mesh"
                        + (f" ({points} points and no faces: a point cloud; mesh it first, e.g. Poisson "
                           "surface reconstruction in MeshLab or Open3D)" if points else ""))
    return V, F


def write_mesh(path, vertices, faces):
    """Write a triangle mesh (vertices (n,3), faces (f,3)) as OBJ/PLY/STL/OFF by suffix,
    atomically; returns the Path."""
    import trimesh
    path = Path(path)
    if path.suffix.lower() not in MESH_EXTS:
        raise MeshError(f"{path}: unknown mesh format '{path.suffix}' (use {', '.join(MESH_EXTS)})")
    with atomic_path(path) as tmp:
        trimesh.Trimesh(np.asarray(vertices, float), np.asarray(faces), process=False).export(tmp)
    return path


def write_ply(path, vertices, faces, colors):
    """Binary PLY with float32 positions and float32 r, g, b (Mitsuba reads them as the
    ``vertex_color`` attribute; vertex order is kept, unlike OBJ); written atomically."""
    v = np.hstack([np.asarray(vertices, np.float32), np.asarray(colors, np.float32)])
    f = np.asarray(faces, np.int32)
    head = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(v)}\n"
            + "".join(f"property float {c}\n" for c in ("x", "y", "z", "r", "g", "b"))
            + f"element face {len(f)}\nproperty list uchar int vertex_indices\nend_header\n")
    rec = np.zeros(len(f), dtype=[("n", "u1"), ("i", "<i4", (3,))])
    rec["n"], rec["i"] = 3, f
    with atomic_open(path, "wb") as fh:
        fh.write(head.encode())
        fh.write(v.astype("<f4").tobytes())
        fh.write(rec.tobytes())
    return Path(path)
