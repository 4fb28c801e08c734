"""Read and clean a target face mesh (the actor's neutral scan) before the morph.

Cleaning follows paper 001 sec. 4: merge duplicated vertices, drop degenerate (tiny) and
repeated triangles and unreferenced vertices, make the winding consistent and the normals
point out of the head. Holes (eyes, mouth, neck, a partial scan's edge) are kept: the morph
works on open surfaces. The unit is found from the size: a head or face is 0.12-0.6 m across.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import numpy as np

from ..errors import MeshError
from ..mesh.triangles import edge_components, face_normals, triangle_areas

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
HEAD_SIZE_M = (0.12, 0.6)        # bounding-box diagonal of a face or head, metres
MIN_TRIANGLES = 500
MIN_AREA_M2 = 1e-9              # paper 001 sec. 4: smaller triangles are dropped


@dataclass
class Target:
    """A cleaned target mesh in metres (its own orientation).

    vertices (n,3) m; faces (f,3); unit: the file unit found or given; scale: metres per file
    unit; source_ids (n,) the file vertex each cleaned vertex came from; notes: what cleaning did.
    """
    vertices: np.ndarray
    faces: np.ndarray
    unit: str
    scale: float
    source_ids: np.ndarray
    name: str = "target"
    notes: list = field(default_factory=list)


def drop_faces(target, drop, note):
    """The Target without the triangles ``drop`` (f,) bool and the vertices only they used;
    ``note`` is added to its notes."""
    F = target.faces[~np.asarray(drop, bool)]
    used, inv = np.unique(F, return_inverse=True)
    return Target(target.vertices[used], inv.reshape(-1, 3), target.unit, target.scale,
                  target.source_ids[used], target.name, target.notes + [note])


def detect_unit(V, name="target"):
    """(unit name, metres per unit) that makes the mesh's diagonal a plausible head size."""
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    for unit, s in UNITS.items():
        if HEAD_SIZE_M[0] <= diag * s <= HEAD_SIZE_M[1]:
            return unit, s
    raise MeshError(f"{name}: its bounding box is {diag:.4g} units across, which is no head size in "
                    f"metres, centimetres or millimetres ({HEAD_SIZE_M[0]}-{HEAD_SIZE_M[1]} m); "
                    "pass the unit explicitly (--unit) or rescale the file")


def clean(V, F, name="target", unit=None, shapes=None):
    """Clean a raw mesh (file units) into a Target in metres. Raises MeshError naming ``name``.

    shapes (K,n,3) file units, optional: the actor's blendshape offsets. Vertices that
    coincide in the neutral but part in a shape (the two lips of a closed lip slit, when
    jawOpen opens it) are not merged."""
    import trimesh

    V, F = np.asarray(V, float), np.asarray(F, np.int64)
    notes = []
    if F.ndim != 2 or F.shape[1] != 3 or (len(F) and (F.min() < 0 or F.max() >= len(V))):
        raise MeshError(f"{name}: faces must be triangles indexing its {len(V)} vertices")
    if not np.isfinite(V).all():
        raise MeshError(f"{name}: {int((~np.isfinite(V)).any(1).sum())} vertices are NaN or infinite")
    if unit is None:
        unit, scale = detect_unit(V, name)
    else:
        if unit not in UNITS:
            raise MeshError(f"{name}: unknown unit '{unit}'; use one of {', '.join(UNITS)}")
        scale = UNITS[unit]
    V = V * scale
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    # duplicated vertices (within 1e-7 of the size, in the neutral and every shape): merge
    P = V if shapes is None else np.concatenate([V[None], V + np.asarray(shapes) * scale]).transpose(1, 0, 2)
    key = np.round(P.reshape(len(V), -1) / (diag * 1e-7)).astype(np.int64)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    if len(first) < len(V):
        notes.append(f"merged {len(V) - len(first)} duplicated vertices")
    src = first
    V, F = V[first], inv.ravel()[F]
    # degenerate, collapsed and repeated triangles
    area = triangle_areas(V, F)
    bad = (area < MIN_AREA_M2) | (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])
    _, uniq = np.unique(np.sort(F, axis=1), axis=0, return_index=True)
    rep = np.ones(len(F), bool)
    rep[uniq] = False
    if bad.any() or rep.any():
        notes.append(f"dropped {int(bad.sum())} degenerate and {int((rep & ~bad).sum())} repeated triangles")
    F = F[~bad & ~rep]
    if len(F) < MIN_TRIANGLES:
        raise MeshError(f"{name}: only {len(F)} usable triangles; a face scan needs at least {MIN_TRIANGLES}")
    # keep the largest connected piece (stray bits of hair, eyeballs, scanning debris)
    comp = edge_components(F[:, [0, 1, 1, 2]], len(V))
    tri_comp = comp[F[:, 0]]
    big = np.bincount(tri_comp).argmax()
    if (tri_comp != big).any():
        notes.append(f"dropped {int((tri_comp != big).sum())} triangles in pieces apart from the face")
        F = F[tri_comp == big]
    used, inv = np.unique(F, return_inverse=True)
    V, F, src = V[used], inv.reshape(-1, 3), src[used]
    mesh = trimesh.Trimesh(V, F, process=False)
    flipped_before = F.copy()
    trimesh.repair.fix_winding(mesh)
    F = np.asarray(mesh.faces, np.int64)
    if (F != flipped_before).any():
        notes.append(f"made the winding consistent ({int((F != flipped_before).any(1).sum())} triangles flipped)")
    # normals out of the head: area-weighted normals point away from the centroid
    fn = face_normals(V, F)
    c = V[F].mean(1)
    if np.einsum("ij,ij->", fn, c - np.average(c, axis=0, weights=np.linalg.norm(fn, axis=1))) < 0:
        F = F[:, [0, 2, 1]]
        notes.append("flipped all normals to point out of the head")
    return Target(V, F, unit, scale, src, name, notes)
