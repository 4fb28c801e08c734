"""Volume morph of the template's anatomy (paper 001 sec. 8-9).

The surface displacements of the morphed skin are the Dirichlet data of three volumetric
Poisson equations (one per component) on the template's flesh tet mesh (linear-FEM Laplacian),
the same operator as paper 000 Eq. 11: the tet vertices on the skin move with the skin (through
the same skin-to-boundary correspondence), every other flesh vertex, the bone attachments
included, gets the harmonic extension. Deviation: the paper solves on a background grid
covering all of space; the template's bones are the inner boundary of its flesh, so the
flesh mesh carries them (bone vertices, muscle centre-lines and the jaw pivot are moved by
the displacement of the tet they lie in, or the nearest one, linearly extrapolated).
Where the skin moves inward by more than the tissue is thick, the inner surface is pushed
back first (collision processing, only the inner displacements change, then the field is
solved again with both surfaces as Dirichlet data, as the paper does).
Fibres follow the deformation gradient of their tet. Tets that invert or fall below the
template's quality bound are relaxed (sec. 9: mass-spring relaxation of interior nodes or
remeshing; here the non-skin vertices of the bad tets' neighbourhood minimise a regularised
mean-ratio distortion against the template's own tets, mesh.untangle, which untangles
inverted tets and restores the template's shape quality without remeshing), with the skin
held until the last round.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import MeshError
from ..mesh.closest import barycentric_points, closest_points
from ..mesh.tets import (barycentric, boundary_faces, harmonic, laplacian, locate,
                         radius_ratio, shape_gradients, signed_volumes)
from ..mesh.triangles import vertex_normals
from ..mesh.untangle import untangle
from ..sim.poisson import outer_boundary

MIN_DEPTH_FRACTION = 0.7     # inner surfaces keep at least this much of the template's tissue depth
DEGENERATE = 1e-3            # radius ratio below which a morphed tet is unusable (builds: >= 0.009)


@dataclass
class VolumeMorph:
    """Morphed rest positions X (N,3), the count of inner-surface vertices pushed back by
    collision processing, and relaxation statistics."""
    X: np.ndarray
    pushed: int
    relaxed_vertices: int
    relax_rounds: int


def _depth(points, V, F):
    """Signed depth (P,) of points below the skin (V, F): positive inside."""
    tri, w, d = closest_points(points, V, F)
    q = barycentric_points(V, F, tri, w)
    n = barycentric_points(vertex_normals(V, F), F, tri, w)
    return np.where(np.einsum("ij,ij->i", points - q, n) > 0, -d, d), n


def volume_displacement(model, surface_displacement, keep_depth=MIN_DEPTH_FRACTION):
    """dX (N,3): harmonic extension of the skin displacement (V,3) into the flesh, and the
    skin-boundary tet vertex ids (B,).

    Collision processing (sec. 8): inner-surface vertices (bone, mucosa) that end up closer
    to the morphed skin than ``keep_depth`` of their template depth are pushed back inward
    along the skin normal, and the field is solved again with both the skin and the
    corrected inner surface as Dirichlet data. Returns dX, ids and the count pushed.
    """
    ids, S = outer_boundary(model, apart=False)
    X0, tets = model.rest_positions, model.tets
    L = laplacian(X0, tets).tocsr()
    dX = harmonic(L, ids, S @ surface_displacement)
    faces, _ = boundary_faces(tets)
    inner = np.setdiff1d(np.unique(faces), ids)
    skin1 = model.neutral + surface_displacement
    d0, _ = _depth(X0[inner], model.neutral, model.triangles)
    X1 = X0 + dX
    d1, n1 = _depth(X1[inner], skin1, model.triangles)
    want = keep_depth * np.maximum(d0, 0)
    low = d1 < want
    if low.any():
        X1[inner[low]] -= (want[low] - d1[low])[:, None] * n1[low]
        fixed = np.concatenate([ids, inner])
        dX = harmonic(L, fixed, (X1 - X0)[fixed])
    return dX, ids, int(low.sum())


def _bad_tets(X, tets, min_radius_ratio):
    return (signed_volumes(X, tets) <= 0) | (radius_ratio(X, tets) < min_radius_ratio)


def relax_tets(X, X0, tets, held, min_radius_ratio, rounds=6, rings=2, release=2):
    """Untangle and re-shape the tets around bad ones (inverted or below the radius-ratio
    bound): the non-held vertices within ``rings`` (growing each round) of a bad tet minimise
    the regularised mean-ratio distortion against the template's rest tets X0 (mesh.untangle);
    in the last ``release`` rounds the held (skin, bone) vertices of tets still bad are
    released as well (a fold the surface morph left in the skin has no good tets under it).
    Returns X (N,3), vertices moved (int), rounds run (int)."""
    N = len(X)
    moved = np.zeros(N, bool)
    for r in range(rounds):
        bad = _bad_tets(X, tets, min_radius_ratio)
        if not bad.any():
            return X, int(moved.sum()), r
        region = np.zeros(N, bool)
        region[np.unique(tets[bad])] = True
        for _ in range(rings + r):
            region[np.unique(tets[region[tets].any(1)])] = True
        if r >= rounds - release:     # last resort: release the skin/bone vertices of bad tets too
            held = held.copy()
            held[np.unique(tets[bad])] = False
        free = np.flatnonzero(region & ~held)
        X = untangle(X, X0, tets, free)
        moved[free] = True
    return X, int(moved.sum()), rounds


def carry_points(X0, X1, tets, points):
    """Points (P,3) in the rest mesh X0 moved by the piecewise-linear map X0 -> X1 of the tet
    they lie in (or the best nearby one, extrapolated)."""
    points = np.asarray(points, float).reshape(-1, 3)
    t, w = locate(X0, tets, points)
    return np.einsum("pk,pkj->pj", w, X1[tets[t]])


def carry_similar(X0, X1, points, radius=0.02):
    """Points (P,3) of one rigid part (an eyeball, a dental arch) moved by the similarity
    (rotation, uniform scale, translation) that best maps the flesh around them, X0 -> X1
    (N,3), weighted by a Gaussian of each flesh point's distance to the part (points farther
    than ``radius`` m are left out). Keeps the part's shape, where the volume map's tets
    extrapolated into the head's inside would shear it."""
    from scipy.spatial import cKDTree
    points = np.asarray(points, float).reshape(-1, 3)
    d, _ = cKDTree(points).query(X0, distance_upper_bound=radius)
    near = np.isfinite(d)
    if near.sum() < 4:
        return points.copy()
    w = np.exp(-(d[near] / (0.5 * radius)) ** 2)
    A, B = X0[near], X1[near]
    ma, mb = w @ A / w.sum(), w @ B / w.sum()
    a, b = A - ma, B - mb
    U, S, Vt = np.linalg.svd((w[:, None] * b).T @ a)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    R = U @ D @ Vt
    s = np.trace(np.diag(S) @ D) / float(w @ np.sum(a * a, axis=1))
    return (points - ma) @ (s * R).T + mb


def carry_bone(X0, X1, tets, points, near=0.003, far=0.015):
    """Bone surface points (P,3) moved with the flesh X0 -> X1 (N,3): those within ``near`` m
    of a flesh vertex by the tet map (carry_points) with the flesh they hold, those beyond
    ``far`` (the back of the cranium, the ramus, far outside the face's flesh, where the tets'
    map extrapolated would shear them) by the similarity of the flesh (carry_similar),
    blended linearly in between."""
    from scipy.spatial import cKDTree
    points = np.asarray(points, float).reshape(-1, 3)
    d, _ = cKDTree(X0).query(points)
    w = np.clip((far - d) / (far - near), 0.0, 1.0)[:, None]
    out = carry_similar(X0, X1, points, radius=far) * (1 - w)
    if np.any(w > 0):
        inside = w[:, 0] > 0
        out[inside] += w[inside] * carry_points(X0, X1, tets, points[inside])
    return out


def carry_fibers(X0, X1, tets, tet_ids, fibers):
    """Unit fibres (n,3) of tets ``tet_ids`` pushed forward by each tet's deformation gradient."""
    g, _ = shape_gradients(X0, tets[tet_ids])
    Fd = np.einsum("tai,taj->tij", X1[tets[tet_ids]], g)          # F = sum_a x_a grad(N_a)^T
    f = np.einsum("tij,tj->ti", Fd, fibers)
    return f / np.linalg.norm(f, axis=1, keepdims=True)


def morph_volume(model, surface_displacement, min_radius_ratio, progress=None):
    """Morph the flesh of ``model`` by the skin displacement (V,3). Raises MeshError when tets
    stay inverted or flattened (radius ratio under DEGENERATE) after relaxation: a tet of
    volume 1e-25 m^3 passed a plain sign test and then broke point location and the solver."""
    say = progress or (lambda m: None)
    dX, ids, pushed = volume_displacement(model, surface_displacement)
    if pushed:
        say(f"collision processing: {pushed} inner-surface vertices pushed back under the skin")
    X = model.rest_positions + dX
    held = np.zeros(len(X), bool)
    held[ids] = True
    n_bad = int(_bad_tets(X, model.tets, min_radius_ratio).sum())
    moved, rounds = 0, 0
    if n_bad:
        say(f"relaxing {n_bad} inverted or low-quality tets")
        X, moved, rounds = relax_tets(X, model.rest_positions, model.tets, held, min_radius_ratio)
    bad = _bad_tets(X, model.tets, DEGENERATE)
    if bad.any():           # a last, wider pass: four rings around them, everything released
        say(f"{int(bad.sum())} tets still flat: relaxing a wider region")
        X, more, r2 = relax_tets(X, model.rest_positions, model.tets, held, min_radius_ratio, rounds=4, rings=4,
                                 release=4)
        moved, rounds = moved + more, rounds + r2
        bad = _bad_tets(X, model.tets, DEGENERATE)
    if bad.any():
        c = model.rest_positions[model.tets[bad]].mean(1)
        names = list(model.landmarks)
        L = model.neutral[[model.landmarks[k] for k in names]]
        near = sorted({names[i] for i in np.argmin(np.linalg.norm(c[:, None] - L[None], axis=2), axis=1)})
        raise MeshError(f"the morphed flesh has {int(bad.sum())} inverted or flattened tets (radius ratio "
                        f"under {DEGENERATE}) after relaxation, nearest the template's {', '.join(near)}: the "
                        "target is too far from the template's proportions there (check the landmarks in the "
                        "--preview sheet)")
    return VolumeMorph(X, pushed, moved, rounds)


def inside_fraction(X, tets, points, tol=-0.05):
    """Fraction of points (P,3) inside the tet mesh (smallest barycentric weight >= tol)."""
    t, _ = locate(X, tets, points)
    w = barycentric(X, tets, t, points)
    return float((w.min(1) >= tol).mean())
