"""Triangle-mesh helpers shared by the simulation (contacts) and the renderer (shading)."""
from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components


def face_normals(X, faces):
    """Unnormalised face normals (F,3) of triangles ``faces`` (F,3) at positions X: the
    cross product of two edges, twice the triangle's area long."""
    X, faces = np.asarray(X, float), np.asarray(faces)
    return np.cross(X[faces[:, 1]] - X[faces[:, 0]], X[faces[:, 2]] - X[faces[:, 0]])


def triangle_areas(X, faces):
    """Areas (F,) of triangles ``faces`` at positions X (units of X squared)."""
    return 0.5 * np.linalg.norm(face_normals(X, faces), axis=1)


def vertex_normals(X, faces, n_vertices=None):
    """Area-weighted unit vertex normals (N,3) of triangles ``faces`` (F,3) at positions X;
    N = n_vertices, default len(X)."""
    X, faces = np.asarray(X, float), np.asarray(faces)
    fn = face_normals(X, faces)
    vn = np.zeros((len(X) if n_vertices is None else n_vertices, 3))
    for k in range(3):
        np.add.at(vn, faces[:, k], fn)
    return vn / np.maximum(np.linalg.norm(vn, axis=1, keepdims=True), 1e-30)


def unique_edges(F):
    """Unique undirected edges (E,2) of triangles F (F,3) and, per triangle, its 3 edge ids
    (F,3) in the order (v0v1, v1v2, v2v0)."""
    F = np.asarray(F, np.int64)
    e = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    e.sort(axis=1)
    edges, inv = np.unique(e, axis=0, return_inverse=True)
    return edges, inv.reshape(3, len(F)).T


def umbrella(X, faces):
    """Distance (V,) from each vertex of X (V,3) to the mean of its edge neighbours in
    triangles ``faces`` (F,3), units of X: a crease or spike shows as a large value."""
    X = np.asarray(X, float)
    E, _ = unique_edges(faces)
    n = len(X)
    A = coo_matrix((np.ones(2 * len(E)), (np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]])), shape=(n, n)).tocsr()
    deg = np.maximum(np.asarray(A.sum(1)).ravel(), 1)[:, None]
    return np.linalg.norm(A @ X / deg - X, axis=1)


def edge_components(edges, n):
    """Connected-component label (n,) of each of n nodes joined by the edges (E,2)."""
    e = np.asarray(edges, np.int64).reshape(-1, 2)
    g = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(n, n))
    return connected_components(g, directed=False)[1]


def boundary_edges(faces):
    """Edges (B,2) used by a single triangle of ``faces`` (F,3): the open boundaries."""
    edges, tri_edges = unique_edges(faces)
    return edges[np.bincount(tri_edges.ravel(), minlength=len(edges)) == 1]


def boundary_vertices(faces, n):
    """Boolean (n,) mask of the vertices on open boundary edges of ``faces`` (F,3)."""
    mask = np.zeros(n, bool)
    mask[boundary_edges(faces).ravel()] = True
    return mask


def boundary_loops(faces):
    """Open boundaries of a triangle mesh: a list of vertex-id arrays, one per connected
    component of its boundary edges (holes such as open eyes or mouth)."""
    b = boundary_edges(faces)
    if len(b) == 0:
        return []
    ids, local = np.unique(b, return_inverse=True)
    lab = edge_components(local, len(ids))
    return [ids[lab == i] for i in range(lab.max() + 1)]


def group_offsets(counts):
    """Position (sum(counts),) of each item within its group, for groups of ``counts`` (G,)
    items laid end to end: [0..counts[0]-1, 0..counts[1]-1, ...]."""
    counts = np.asarray(counts, np.int64)
    return np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)


PAIRS = 2_000_000     # centroid-triangle pairs per batch (covered_from_front)


def covered_from_front(X, faces, eps=1e-6):
    """Boolean (F,) of triangles whose centroid is hidden along +z: a ray from it towards +z
    hits another triangle more than ``eps`` (m) in front. X (N,3) m, faces (F,3).

    The triangles are binned by their xy bounding boxes on a grid of about two median edge
    lengths; each centroid is tested against the triangles of its cell (2D barycentric
    inside test, then the depth of the plane there)."""
    X, faces = np.asarray(X, float), np.asarray(faces, np.int64)
    P = X[faces]                                            # (F,3,3)
    c = P.mean(1)
    h = 2.0 * float(np.median(np.linalg.norm(P[:, 0] - P[:, 1], axis=1)))
    lo, hi = np.floor(P[..., :2].min(1) / h).astype(np.int64), np.floor(P[..., :2].max(1) / h).astype(np.int64)
    base = lo.min(0)
    lo, hi = lo - base, hi - base
    ny = int(hi[:, 1].max()) + 1
    span = hi - lo + 1
    # every triangle in each cell its box overlaps
    count = span[:, 0] * span[:, 1]
    tri = np.repeat(np.arange(len(faces)), count)
    k = group_offsets(count)
    cell = (lo[tri, 0] + k // span[tri, 1]) * ny + lo[tri, 1] + k % span[tri, 1]
    order = np.argsort(cell, kind="stable")
    cell, tri = cell[order], tri[order]
    q = (np.floor(c[:, :2] / h).astype(np.int64) - base)
    qcell = q[:, 0] * ny + q[:, 1]
    start, stop = np.searchsorted(cell, qcell, "left"), np.searchsorted(cell, qcell, "right")
    out = np.zeros(len(faces), bool)
    # in batches of about PAIRS centroid-triangle pairs: a dense scan seen edge-on (the sides
    # of a head) stacks hundreds of triangles in a cell
    ends = np.cumsum(stop - start)
    cuts = np.searchsorted(ends, np.arange(PAIRS, ends[-1] + PAIRS, PAIRS), "right")
    for i, j in zip(np.r_[0, cuts[:-1]], cuts):
        ids = np.arange(i, j)
        n = stop[ids] - start[ids]
        pid = np.repeat(ids, n)
        cand = tri[np.repeat(start[ids], n) + group_offsets(n)]
        keep = cand != pid
        pid, cand = pid[keep], cand[keep]
        a, b, d = P[cand, 0], P[cand, 1], P[cand, 2]
        p = c[pid]
        e1, e2, r = b[:, :2] - a[:, :2], d[:, :2] - a[:, :2], p[:, :2] - a[:, :2]
        det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        ok = np.abs(det) > 1e-30
        det = np.where(ok, det, 1.0)
        u = (r[:, 0] * e2[:, 1] - r[:, 1] * e2[:, 0]) / det
        v = (e1[:, 0] * r[:, 1] - e1[:, 1] * r[:, 0]) / det
        inside = ok & (u >= 0) & (v >= 0) & (u + v <= 1)
        z = a[:, 2] + u * (b[:, 2] - a[:, 2]) + v * (d[:, 2] - a[:, 2])
        out[pid[inside & (z > p[:, 2] + eps)]] = True
    return out
