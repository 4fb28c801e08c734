"""Vectorised tetrahedral-mesh geometry: volumes, quality, boundary, embedding, Laplacian.

Conventions: ``X`` (N,3) float64 vertex positions in metres, ``tets`` (T,4) int vertex ids,
positively oriented when det[x1-x0, x2-x0, x3-x0] > 0.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

# The face opposite vertex k, ordered so its normal points out of a positive tet.
_FACES = np.array([[1, 2, 3], [0, 3, 2], [0, 1, 3], [0, 2, 1]])
TET_EDGES = ([0, 0, 0, 1, 1, 2], [1, 2, 3, 2, 3, 3])     # a tet's six edges: (first ends, second ends)


def signed_volumes(X, tets):
    """Signed volumes (T,) in m^3."""
    p = X[tets]
    return np.einsum("ij,ij->i", np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), p[:, 3] - p[:, 0]) / 6.0


def orient(X, tets):
    """Swap two vertices of every negatively oriented tet so all volumes are positive."""
    tets = tets.copy()
    neg = signed_volumes(X, tets) < 0
    tets[neg, 2], tets[neg, 3] = tets[neg, 3].copy(), tets[neg, 2].copy()
    return tets


def dihedral_angles(X, tets):
    """The six interior dihedral angles (T,6) in radians of each tet."""
    p = X[tets]
    n = []
    for f in _FACES:
        a, b, c = p[:, f[0]], p[:, f[1]], p[:, f[2]]
        nn = np.cross(b - a, c - a)
        n.append(nn / np.maximum(np.linalg.norm(nn, axis=1, keepdims=True), 1e-300))
    out = []
    for k in range(4):
        for m in range(k + 1, 4):
            cosang = np.clip(-np.einsum("ij,ij->i", n[k], n[m]), -1, 1)
            out.append(np.arccos(cosang))
    return np.stack(out, 1)


def radius_ratio(X, tets):
    """Normalised radius ratio 3 r_in / r_circ (T,): 1 for a regular tet, 0 when degenerate."""
    p = X[tets]
    d1, d2, d3 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]
    vol6 = np.einsum("ij,ij->i", np.cross(d1, d2), d3)
    area = 0.0
    for f in _FACES:
        area = area + 0.5 * np.linalg.norm(np.cross(p[:, f[1]] - p[:, f[0]], p[:, f[2]] - p[:, f[0]]), axis=1)
    r_in = 0.5 * np.abs(vol6) / np.maximum(area, 1e-300)
    num = (np.sum(d1 * d1, 1)[:, None] * np.cross(d2, d3) + np.sum(d2 * d2, 1)[:, None] * np.cross(d3, d1)
           + np.sum(d3 * d3, 1)[:, None] * np.cross(d1, d2))
    r_c = np.linalg.norm(num, axis=1) / np.maximum(np.abs(2 * vol6), 1e-300)
    rr = 3.0 * r_in / np.maximum(r_c, 1e-300)
    # it is at most 1; above (0/0 when two corners coincide: 3.8e281 once) the tet is degenerate
    return np.where(rr <= 1.0 + 1e-9, rr, 0.0)


def quality_summary(X, tets):
    """Dict of mesh quality figures: counts, volume range, min dihedral (deg), radius ratio."""
    vol = signed_volumes(X, tets)
    dih = np.degrees(dihedral_angles(X, tets))
    rr = radius_ratio(X, tets)
    return {
        "tets": int(len(tets)),
        "vertices": int(len(X)),
        "volume_m3": float(vol.sum()),
        "min_volume_m3": float(vol.min()),
        "inverted": int((vol <= 0).sum()),
        "min_dihedral_deg": float(dih.min()),
        "max_dihedral_deg": float(dih.max()),
        "min_radius_ratio": float(rr.min()),
        "mean_radius_ratio": float(rr.mean()),
    }


def face_use(tets):
    """All tet faces (4T,3), outward for positive tets, and how many tets share each (4T,)."""
    faces = tets[:, _FACES].reshape(-1, 3)
    _, inv, counts = np.unique(np.sort(faces, axis=1), axis=0, return_inverse=True, return_counts=True)
    return faces, counts[inv.ravel()]


def boundary_faces(tets):
    """Outward-oriented triangles (B,3) that belong to exactly one tet, and their tet ids (B,)."""
    faces, use = face_use(tets)
    owner = np.repeat(np.arange(len(tets)), 4)
    once = use == 1
    return faces[once], owner[once]


def barycentric(X, tets, tet_ids, points):
    """Barycentric coordinates (P,4) of ``points`` (P,3) in tets ``tet_ids`` (P,)."""
    p = X[tets[tet_ids]]
    D = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]], axis=2)
    lam = np.linalg.solve(D, (points - p[:, 0])[..., None])[..., 0]
    return np.concatenate([1 - lam.sum(1, keepdims=True), lam], axis=1)


def mean_edge_length(X, tets):
    """Mean length (m) of the six edges of every tet (edges shared by tets count per tet)."""
    e = X[tets[:, TET_EDGES[0]]] - X[tets[:, TET_EDGES[1]]]
    return float(np.linalg.norm(e, axis=2).mean())


def node_spacing(X, tets):
    """Mean length (N,) m of the tet edges at each node (X (N,3), tets (T,4))."""
    e = np.stack([tets[:, TET_EDGES[0]], tets[:, TET_EDGES[1]]], -1).reshape(-1, 2)
    length = np.linalg.norm(X[e[:, 0]] - X[e[:, 1]], axis=1)
    count = np.bincount(e.ravel(), minlength=len(X))
    return np.bincount(e.ravel(), np.repeat(length, 2), minlength=len(X)) / np.maximum(count, 1)


def shape_gradients(X, tets):
    """Gradients of the 4 linear shape functions per tet (T,4,3) and rest volumes (T,)."""
    p = X[tets]
    Dm = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], p[:, 3] - p[:, 0]], axis=2)
    Dinv = np.linalg.inv(Dm)                      # rows: grad of lambda_1..3
    g = np.concatenate([-Dinv.sum(1, keepdims=True), Dinv], axis=1)
    return g, np.linalg.det(Dm) / 6.0


def laplacian(X, tets):
    """Cotangent (linear FEM) stiffness Laplacian L (N,N), symmetric positive semidefinite.

    L = sum_t V_t G_t^T G_t, the discrete -div grad; L @ u = 0 is the harmonic condition.
    """
    g, vol = shape_gradients(X, tets)
    K = np.einsum("t,tai,tbi->tab", np.abs(vol), g, g)
    rows = np.repeat(tets, 4, axis=1).ravel()
    cols = np.tile(tets, (1, 4)).ravel()
    n = len(X)
    return sp.csr_matrix((K.ravel(), (rows, cols)), shape=(n, n))


def graph_laplacian(edges, n):
    """Uniform-weight graph Laplacian (n,n) of undirected edges (E,2) (repeats count once):
    degree on the diagonal, -1 per neighbour; the stiffness of zero-length unit springs."""
    e = np.asarray(edges)
    W = sp.coo_matrix((np.ones(2 * len(e)), (np.concatenate([e[:, 0], e[:, 1]]),
                                             np.concatenate([e[:, 1], e[:, 0]]))), shape=(n, n)).tocsr()
    W.data[:] = 1.0
    return (sp.diags(np.asarray(W.sum(1)).ravel()) - W).tocsr()


def harmonic(L, fixed, values):
    """Solve L u = 0 with u[fixed] = values (Dirichlet), natural (Neumann) elsewhere.

    L: (N,N) sparse; fixed: (C,) ids; values: (C,) or (C,k). Returns u (N,) or (N,k).
    """
    from scipy.sparse.linalg import splu

    n = L.shape[0]
    free = np.setdiff1d(np.arange(n), fixed)
    values = np.asarray(values, float)
    u = np.zeros((n,) + values.shape[1:])
    u[fixed] = values
    A = L[free][:, free].tocsc()
    rhs = -(L[free][:, fixed] @ values)
    sol = splu(A).solve(np.asarray(rhs).reshape(len(free), -1))
    u[free] = sol.reshape((len(free),) + values.shape[1:])
    return u


def locate(X, tets, points, k=32):
    """Tet containing each point, or the best extrapolating one nearby.

    Candidates are the k tets with the nearest centroids; the winner has the largest minimum
    barycentric weight (inside: >= 0). Returns tet ids (P,) and barycentric weights (P,4).
    """
    from scipy.spatial import cKDTree

    points = np.asarray(points, float).reshape(-1, 3)
    k = min(k, len(tets))
    _, cand = cKDTree(X[tets].mean(1)).query(points, k=k)
    cand = cand.reshape(len(points), k)
    bary = barycentric(X, tets, cand.ravel(), np.repeat(points, k, axis=0)).reshape(len(points), k, 4)
    best = np.argmax(bary.min(2), axis=1)
    rows = np.arange(len(points))
    return cand[rows, best], bary[rows, best]


def tet_incidence(tets, n_nodes):
    """Sparse CSR (T, N) tet-node incidence: M[t, n] = 1 where node n is a corner of tet t."""
    return sp.csr_matrix((np.ones(tets.size), (np.repeat(np.arange(len(tets)), 4), tets.ravel())),
                         shape=(len(tets), n_nodes))


def tet_adjacency(tets, n_vertices):
    """Sparse (N,N) matrix, nonzero where two vertices share a tet."""
    M = tet_incidence(tets, n_vertices)
    return (M.T @ M).tocsr()


def tets_within_rings(tets, n_nodes, start, rings):
    """The tets within ``rings`` vertex-rings of each point's tet ``start`` (P,): sparse C (P, T)
    with C[p, t] != 0 for those tets, and the tet-node incidence M (T, N) (so C @ M marks
    their nodes). Both CSR, duplicates summed."""
    T, P = len(tets), len(start)
    M = tet_incidence(tets, n_nodes)
    C = sp.csr_matrix((np.ones(P), (np.arange(P), start)), shape=(P, T))
    for _ in range(rings):
        C = ((C @ M) @ M.T).tocsr()
    C.sum_duplicates()
    return C, M


def locate_near(X, tets, points, start, rings=1):
    """Like ``locate``, but each point's candidates are the tets within ``rings`` vertex-rings
    of its tet ``start`` (P,) in the same mesh: a point keeps to its own side of a slit (lips,
    eyelids) that closes up in space. Returns tet ids (P,) and barycentric weights (P,4)."""
    points = np.asarray(points, float).reshape(-1, 3)
    C, _ = tets_within_rings(tets, len(X), start, rings)
    pid = np.repeat(np.arange(len(points)), np.diff(C.indptr))
    cand = C.indices
    score = np.empty(len(cand))
    for s in range(0, len(cand), 1 << 20):          # chunks bound the 3x3 solves' memory
        sl = slice(s, s + (1 << 20))
        score[sl] = barycentric(X, tets, cand[sl], points[pid[sl]]).min(1)
    # per point, the candidate with the largest minimum weight
    order = np.lexsort((-score, pid))
    first = order[np.r_[0, np.flatnonzero(np.diff(pid[order])) + 1]]
    t = cand[first]
    return t, barycentric(X, tets, t, points)
