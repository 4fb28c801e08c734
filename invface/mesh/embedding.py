"""Embeddings of a surface in a tet mesh: sparse maps W (V, N) with surface = W @ X.

The barycentric embedding puts each surface vertex in one tet: the surface is piecewise
linear in space, and where the tets are much larger than the surface's triangles (a morphed
actor's lips: 8 mm tets under 1 mm triangles) every tet face the surface crosses shows as a
crease, and a vertex near a tet corner follows that corner alone: a strongly deformed pose
(jawOpen) tears the lip line into spikes.

The moving-least-squares embedding (linear basis, compact quartic kernel) blends the nodes
near each vertex instead. Its weights sum to 1 and reproduce every affine map of the nodes
exactly, so the rest surface and any rigid or affine motion come out as with barycentric
weights, and the deformed surface is smooth across tet faces. Each vertex blends only nodes of
the tets within ``rings`` vertex-rings of its own tet, so the two sides of a slit (lips,
eyelids) stay apart although they are close in space. The approximant flattens peaks of the
nodes' displacement (it is not interpolating); one step of nodal correction brings them back.

Morphed models use it (meta["skin_embedding"] = MLS); the template keeps barycentric weights,
since its render skin subdivides its tets' own boundary faces.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from ..errors import InvfaceError
from .tets import node_spacing, tets_within_rings

_MAX_COND = 1e6        # a point whose moment matrix is worse than this, or whose weights' absolute
_MAX_LEBESGUE = 5.0    # sum exceeds this (a few nodes far to one side), keeps its barycentric row
MLS = {"method": "moving_least_squares", "rings": 2, "radius": 1.5, "correct": True}   # morphed models' default


def skin_embedding_method(meta):
    """The embedding parameters in a model's meta["skin_embedding"] (None: barycentric),
    checked; raises InvfaceError for an unknown method or parameters."""
    spec = meta.get("skin_embedding")
    if spec is None:
        return None
    if not isinstance(spec, dict) or spec.get("method") != MLS["method"] or set(spec) != set(MLS):
        raise InvfaceError(f"meta.skin_embedding must be {MLS} (other rings/radius/correct allowed), got {spec}")
    if not (isinstance(spec["rings"], int) and 1 <= spec["rings"] <= 4 and 0.5 <= float(spec["radius"]) <= 4):
        raise InvfaceError(f"meta.skin_embedding: rings must be 1..4 and radius 0.5..4, got {spec}")
    return spec


def embedding_matrix(X, tets, points, tet_ids, weights, spec=None):
    """Sparse W (P, N) embedding ``points`` (P,3) in the tet mesh (X (N,3), tets (T,4)) as
    ``spec`` says (see skin_embedding_method): None: barycentric (tet_ids (P,), weights (P,4)),
    else moving_least_squares with its rings, radius and correct."""
    if spec is None:
        return barycentric_matrix(tets, tet_ids, weights, len(X))
    return moving_least_squares(X, tets, points, tet_ids, weights, int(spec["rings"]), float(spec["radius"]),
                                bool(spec["correct"]))


def barycentric_matrix(tets, tet_ids, weights, n_nodes):
    """Sparse W (V, N) of a barycentric embedding: vertex v = sum_k weights[v,k] X[tets[tet_ids[v],k]].

    tets (T,4) ints, tet_ids (V,) ints, weights (V,4), n_nodes N."""
    V = len(tet_ids)
    return sp.csr_matrix((np.asarray(weights, float).ravel(), (np.repeat(np.arange(V), 4), tets[tet_ids].ravel())),
                         shape=(V, n_nodes))


def moving_least_squares(X, tets, points, tet_ids, weights, rings=2, radius=1.5, correct=True):
    """Smooth embedding W (P, N) of ``points`` (P,3) m in the tet mesh (X (N,3) m, tets (T,4)).

    tet_ids (P,), weights (P,4): each point's barycentric embedding (its own tet, from
    ``tets.locate_near``). A point's nodes are those of the tets within ``rings`` vertex-rings
    of its tet; node i reaches h_i = ``radius`` times the mean length of its edges. Per point p
    the weights are phi_i = k_i q_i^T A^-1 e_1 with the linear basis q_i = (1, X_i - p) (scaled),
    A = sum_i k_i q_i q_i^T and the C1 kernel k_i = (1 - |X_i - p|^2 / h_i^2)^2: rows sum to 1
    and W @ (X G^T + c) = points G^T + c for any affine map. The weights are smooth in p
    wherever every node that reaches p is among its candidates (2 rings at radius 1.5). A point
    whose nodes do not span 3D well (moment matrix condition > 1e6, or sum_i |phi_i| > 5: a few
    nodes, all to one side) keeps its barycentric row.

    The approximant is not interpolating: a peak of the nodes' displacement comes out as a local
    average. With ``correct``, one step of nodal correction is applied: W' = W (2 I - A), A (N, N)
    the same weights at the nodes themselves, i.e. the MLS of u + (u - A u). It keeps the rows'
    sum and the affine maps exact, for about 3.5x the weights per point. In the unit test (a
    sheet in a 4x4x4 box): creases at tet faces 12x smaller than barycentric ones, and a bump
    one cell wide followed within 1.1x barycentric's error (1.6x uncorrected). Returns CSR (P, N).
    """
    W = _mls(X, tets, points, tet_ids, weights, rings, radius)
    if correct:
        N = len(X)
        node_tet = np.zeros(N, np.int64)
        node_tet[tets.ravel()] = np.repeat(np.arange(len(tets)), 4)
        A = _mls(X, tets, X, node_tet, (tets[node_tet] == np.arange(N)[:, None]).astype(float), rings, radius)
        W = (2.0 * W - W @ A).tocsr()
        W.eliminate_zeros()
    return W


def _mls(X, tets, points, tet_ids, weights, rings, radius):
    """moving_least_squares without the nodal correction."""
    points = np.asarray(points, float).reshape(-1, 3)
    N, P = len(X), len(points)
    C, M = tets_within_rings(tets, N, tet_ids, rings)
    nodes = (C @ M).tocsr()
    nodes.sum_duplicates()
    pid = np.repeat(np.arange(P), np.diff(nodes.indptr))
    node = nodes.indices
    h = radius * node_spacing(X, tets)                 # (N,): each node's kernel radius, smooth in space
    s = h[tets[tet_ids]].mean(1)                       # (P,): the basis' scale (conditioning only)
    d = X[node] - points[pid]
    q = np.c_[np.ones(len(node)), d / s[pid, None]]    # centred linear basis
    k = np.clip(1.0 - (d ** 2).sum(1) / h[node] ** 2, 0.0, None) ** 2
    A = np.empty((P, 4, 4))
    for a in range(4):
        for b in range(a, 4):
            A[:, a, b] = A[:, b, a] = np.bincount(pid, k * q[:, a] * q[:, b], minlength=P)
    ok = np.linalg.cond(A) < _MAX_COND
    A[~ok] = np.eye(4)
    c = np.linalg.solve(A, np.broadcast_to(np.eye(4)[:, :1], (P, 4, 1)))[..., 0]         # A^-1 e_1
    phi = k * np.einsum("ik,ik->i", q, c[pid])
    ok &= np.bincount(pid, np.abs(phi), minlength=P) <= _MAX_LEBESGUE
    keep = ok[pid] & (phi != 0)
    W = sp.csr_matrix((phi[keep], (pid[keep], node[keep])), shape=(P, N))
    if not ok.all():
        W = W + sp.diags((~ok).astype(float)) @ barycentric_matrix(tets, tet_ids, weights, N)
    return W.tocsr()
