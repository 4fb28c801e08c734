"""Read and clean a target face mesh (the actor's neutral scan) before the morph.

Cleaning follows paper 001 sec. 4: merge duplicated vertices, drop degenerate (tiny) and
repeated triangles and unreferenced vertices, make the winding consistent and the normals
point out of the head. Holes (eyes, mouth, neck, a partial scan's edge) are kept: the morph
works on open surfaces. Without a unit given, the scan is put in provisional metres by its box
(``provisional_scales``); the model builder then decides the unit from the face
(``morph.units``). ``detect_unit`` (the box alone) serves fit-scan, whose scans are faces.
"""
from __future__ import annotations

from dataclasses import dataclass, field
import numpy as np

from ..errors import MeshError
from ..mesh.triangles import edge_components, face_normals, triangle_areas, umbrella, unique_edges

UNITS = {"m": 1.0, "cm": 0.01, "mm": 0.001}
HEAD_SIZE_M = (0.12, 0.6)        # bounding-box diagonal of a face or head, metres
BOX_RANGE_M = (0.12, 1.5)        # ... of a face, a head or a bust (a provisional unit)
NO_UNIT_DIAGS_M = (0.3, 0.6)     # a scan no unit fits is tried at these diagonals (a head, a bust)
MIN_TRIANGLES = 500
MIN_AREA_M2 = 1e-9              # paper 001 sec. 4: smaller triangles are dropped
MIN_PIECE_FRACTION = 0.02      # pieces under this share of the largest one's area are dropped
                               # (a face apart from a torso ten times its area stays)
SPIKE_RATIO = 10.0              # a vertex this many local edge lengths off its neighbours' mean


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


def inward_pieces(V, F, convex=0.2):
    """Boolean (f,) of the triangles (F (f,3) on V (n,3), each piece consistently wound) in
    pieces whose normals point inwards. A piece's area-weighted normals are compared with the
    directions from its own centroid when it is clearly curved around it (a head, a bust, a
    crown: the normalised sum beyond ``convex``), else from the whole scan's (a flat stray
    patch). (One test over the whole scan turned a head inwards when a crown larger than the
    head sat on it: their common centroid lay in the crown.)"""
    fn = face_normals(V, F)
    c = V[F].mean(1)
    a = np.linalg.norm(fn, axis=1)
    comp = edge_components(F[:, [0, 1, 1, 2]], len(V))[F[:, 0]]
    k = comp.max() + 1

    def outward(centre):                     # (k,) normalised sum of n . (c - centre) per piece
        d = c - centre
        return (np.bincount(comp, np.einsum("ij,ij->i", fn, d), k)
                / np.maximum(np.bincount(comp, a * np.linalg.norm(d, axis=1), k), 1e-30))

    own = np.stack([np.bincount(comp, a * c[:, j], k) for j in range(3)], 1)
    mine = outward((own / np.maximum(np.bincount(comp, a, k), 1e-30)[:, None])[comp])
    whole = outward(np.average(c, axis=0, weights=a))
    return np.where(np.abs(mine) > convex, mine, whole)[comp] < 0


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


def provisional_scales(V):
    """Candidate (unit, metres per file unit) for a mesh V (n,3) in file units, most likely
    first: each unit that makes its box's diagonal a head or bust size, then 'none', the
    scales that make the diagonal a head's or a bust's (NO_UNIT_DIAGS_M)."""
    diag = float(np.linalg.norm(V.max(0) - V.min(0)))
    if not diag > 0:
        raise MeshError("all its vertices coincide")
    out = [(u, s) for u, s in UNITS.items() if BOX_RANGE_M[0] <= diag * s <= BOX_RANGE_M[1]]
    return out + [("none", d / diag) for d in NO_UNIT_DIAGS_M]


def spike_vertices(V, F, ratio=SPIKE_RATIO, rounds=3):
    """Vertices (n,) bool that stick out of the surface as spikes: farther than ``ratio``
    times the local edge length from the mean of their edge neighbours. The local edge
    length of a vertex is the mean over its neighbours of their shortest edge, which a spike's
    own long edges do not enter. Repeated ``rounds`` times with the spikes' triangles left
    out (a spike of several vertices loses its tip first). Scale-free: V in any unit."""
    out = np.zeros(len(V), bool)
    for _ in range(rounds):
        Fk = F[~out[F].any(1)]
        E, _ = unique_edges(Fk)
        if not len(E):
            break
        L = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
        shortest = np.full(len(V), np.inf)
        np.minimum.at(shortest, E[:, 0], L)
        np.minimum.at(shortest, E[:, 1], L)
        near = np.zeros(len(V))
        deg = np.zeros(len(V))
        np.add.at(near, E.ravel(), shortest[E[:, ::-1]].ravel())
        np.add.at(deg, E.ravel(), 1.0)
        used = deg > 0
        new = used & (umbrella(V, Fk) > ratio * near / np.maximum(deg, 1)) & ~out
        if not new.any():
            break
        out |= new
    return out


def clean(V, F, name="target", unit=None, shapes=None):
    """Clean a raw mesh (file units) into a Target in metres (provisional ones, the box's
    guess, when ``unit`` is None). Raises MeshError naming ``name``.

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
    diag = float(np.linalg.norm(V.max(0) - V.min(0))) if len(V) else 0.0
    if not diag > 0:
        raise MeshError(f"{name}: all its vertices coincide")
    # duplicated vertices (within 1e-7 of the size, in the neutral and every shape): merge
    P = V if shapes is None else np.concatenate([V[None], V + np.asarray(shapes)]).transpose(1, 0, 2)
    key = np.round(P.reshape(len(V), -1) / (diag * 1e-7)).astype(np.int64)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    if len(first) < len(V):
        notes.append(f"merged {len(V) - len(first)} duplicated vertices")
    src = first
    V, F = V[first], inv.ravel()[F]
    # degenerate (under MIN_AREA_M2 at a 0.3 m head), collapsed and repeated triangles
    area = triangle_areas(V, F)
    bad = (area < MIN_AREA_M2 * (diag / 0.3) ** 2) | (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])
    _, uniq = np.unique(np.sort(F, axis=1), axis=0, return_index=True)
    rep = np.ones(len(F), bool)
    rep[uniq] = False
    if bad.any() or rep.any():
        notes.append(f"dropped {int(bad.sum())} degenerate and {int((rep & ~bad).sum())} repeated triangles")
    F = F[~bad & ~rep]
    if len(F) < MIN_TRIANGLES:
        raise MeshError(f"{name}: only {len(F)} usable triangles; a face scan needs at least {MIN_TRIANGLES}")
    spikes = spike_vertices(V, F)
    if spikes.any():
        F = F[~spikes[F].any(1)]
        notes.append(f"removed {int(spikes.sum())} spike vertices (far off their neighbours' surface)")
    # small pieces apart (stray bits of hair, eyeballs, scanning debris) go; large ones stay
    # until the face is found (crop.py keeps the head's): the largest may be a bust's stand
    comp = edge_components(F[:, [0, 1, 1, 2]], len(V))
    tri_comp = comp[F[:, 0]]
    piece_area = np.bincount(tri_comp, weights=triangle_areas(V, F))
    small = piece_area[tri_comp] < MIN_PIECE_FRACTION * piece_area.max()
    if small.any():
        notes.append(f"dropped {int(small.sum())} triangles in small pieces apart from the rest")
        F = F[~small]
    used, inv = np.unique(F, return_inverse=True)
    V, F, src = V[used], inv.reshape(-1, 3), src[used]
    if unit is None:
        try:
            unit, scale = provisional_scales(V)[0]
        except MeshError as e:
            raise MeshError(f"{name}: {e}") from None
    else:
        if unit not in UNITS:
            raise MeshError(f"{name}: unknown unit '{unit}'; use one of {', '.join(UNITS)}")
        scale = UNITS[unit]
    V = V * scale
    mesh = trimesh.Trimesh(V, F, process=False)
    flipped_before = F.copy()
    trimesh.repair.fix_winding(mesh)
    F = np.asarray(mesh.faces, np.int64)
    if (F != flipped_before).any():
        notes.append(f"made the winding consistent ({int((F != flipped_before).any(1).sum())} triangles flipped)")
    flip = inward_pieces(V, F)
    if flip.all():
        notes.append("flipped all normals to point out of the head")
    elif flip.any():
        notes.append(f"flipped the normals of {int(flip.sum())} of {len(F)} triangles (pieces facing inwards)")
    F = np.where(flip[:, None], F[:, [0, 2, 1]], F)
    return Target(V, F, unit, scale, src, name, notes)
