"""Collision penalty forces (paper 000 Eq. 3): flesh against flesh (lip on lip, lid on lid)
and flesh against bone (lips and cheeks against the teeth/jaw proxy).

Each contact is a vertex v and a plane (point p, unit normal n) on the other side; with the
penetration s = -n . (x_v - p) its penalty energy is k/2 s^2 (zero when separated), made C2
at first touch by a cubic over the first ``CONTACT_SMOOTHING`` metres of penetration:

    e(s) = 0 (s <= 0),  k s^3 / (6 d) (0 < s < d),  k/2 s^2 - k d/2 s + k d^2/6 (s >= d),

so the force -e'(s) n pushes v back along n, its Jacobian is continuous (Newton keeps its
quadratic convergence when a contact starts or stops touching) and the tangent/adjoint
derivatives are those of a smooth function. The plane is a Gaussian-weighted average of the nearby partner
vertices and their normals (the facing lip or lid, or the cranium/jaw mesh moved with the
jaw), so it moves continuously with X and contacts do not flicker between partners.

Contact detection (``detect``) runs once per Newton iteration and freezes the planes;
energy, gradient and Hessian (e''(s) n n^T per penetrating vertex) are exact for that frozen set,
which keeps the line search consistent, and at a converged state the frozen planes are the
current ones. Both sides of a flesh-flesh contact carry their own contact against the other
side's plane, so the forces are equal and opposite to first order. The plane's dependence on
X is left out of the Hessian (lagged contact geometry, the usual choice for penalty contact);
this is also the choice the tangent/adjoint solves inherit.

Flesh-flesh candidates are fixed at set-up: free boundary vertices within ``radius`` of each
other in the rest state whose normals face each other, that are on each other's outer side
and share no tet.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from ..mesh.tets import boundary_faces
from ..mesh.triangles import group_offsets, vertex_normals

CONTACT_SMOOTHING = 2e-5     # m: the cubic onset of the contact penalty


def penalty(gap, k, d=CONTACT_SMOOTHING):
    """C2 penalty of gaps (c,) with stiffness k (c,): energy e, de/dgap, d2e/dgap2 (each (c,))."""
    s = np.maximum(-gap, 0.0)
    cubic = s < d
    e = np.where(cubic, k * s ** 3 / (6 * d), k * (0.5 * s ** 2 - 0.5 * d * s + d * d / 6))
    de = -np.where(cubic, k * s ** 2 / (2 * d), k * (s - 0.5 * d))
    dde = np.where(cubic, k * s / d, k)
    return e, de, dde


@dataclass
class ContactSet:
    """Frozen contacts: vertices v (c,), unit normals n (c,3), stiffness k (c,) N/m, and the
    plane point p(X) = p0 + sum_j w_j x_{u_j}: static part p0 (c,3), partner vertices u
    (c,K) (-1 = none) with frozen weights w (c,K). Bone contacts have no partners.

    Planes on the jaw move rigidly with it: ``moves`` (c,) marks them and p_local, n_local
    (c,3) hold them in the jaw's rest frame, so ``posed`` re-places them for another jaw
    transform and ``jaw_derivative`` differentiates the forces with respect to it."""
    v: np.ndarray
    p0: np.ndarray
    n: np.ndarray
    k: np.ndarray
    u: np.ndarray
    w: np.ndarray
    moves: np.ndarray = None
    p_local: np.ndarray = None
    n_local: np.ndarray = None

    def __post_init__(self):
        if self.moves is None:
            self.moves = np.zeros(len(self.v), bool)
            self.p_local, self.n_local = self.p0.copy(), self.n.copy()

    def posed(self, M):
        """The same contacts with the jaw planes placed by the jaw transform M (4,4)."""
        p0, n = self.p0.copy(), self.n.copy()
        m = self.moves
        p0[m] = self.p_local[m] @ M[:3, :3].T + M[:3, 3]
        n[m] = self.n_local[m] @ M[:3, :3].T
        return ContactSet(self.v, p0, n, self.k, self.u, self.w, m, self.p_local, self.n_local)

    def jaw_derivative(self, X, dM, n_vertices):
        """d(energy gradient)/d(jaw parameter) (P,N,3) for jaw-transform derivatives dM (P,4,4).

        Only the penetrating jaw contacts contribute: with gap = n.(x - p0), the gradient
        e'(gap) n changes by e'' dgap n + e' dn, dn = dR n_local, dp0 = dR p_local + dt.
        """
        out = np.zeros((len(dM), n_vertices, 3))
        gap = self.gaps(X)
        m = self.moves & (gap < 0)
        if not m.any():
            return out
        x, n, p0 = X[self.v[m]], self.n[m], self.p0[m]
        _, de, dde = penalty(gap[m], self.k[m])
        for i, D in enumerate(dM):
            dn = self.n_local[m] @ D[:3, :3].T
            dp = self.p_local[m] @ D[:3, :3].T + D[:3, 3]
            dgap = np.einsum("ci,ci->c", dn, x - p0) - np.einsum("ci,ci->c", n, dp)
            np.add.at(out[i], self.v[m], (dde * dgap)[:, None] * n + de[:, None] * dn)
        return out

    def gaps(self, X):
        p = self.p0 + np.einsum("ck,cki->ci", self.w, X[np.maximum(self.u, 0)])
        return np.einsum("ci,ci->c", self.n, X[self.v] - p)

    def energy(self, X):
        return float(penalty(self.gaps(X), self.k)[0].sum())

    def gradient(self, X, n_vertices):
        """Energy gradient (N,3) (= minus the collision forces)."""
        f = penalty(self.gaps(X), self.k)[1][:, None] * self.n
        out = np.zeros((n_vertices, 3))
        np.add.at(out, self.v, f)
        m = self.u >= 0
        np.add.at(out, self.u[m], -(self.w[..., None] * f[:, None, :])[m])
        return out

    def blocks(self, X):
        """Hessian blocks [(pairs (P,2), B (P,3,3))] of the penetrating contacts:
        e''(s) n n^T (e_v - sum_j w_j e_uj)(e_v - sum_j w_j e_uj)^T."""
        gap = self.gaps(X)
        pen = gap < 0
        k = penalty(gap[pen], self.k[pen])[2]
        v, n, u, w = self.v[pen], self.n[pen], self.u[pen], self.w[pen]
        nn = k[:, None, None] * np.einsum("ci,cj->cij", n, n)
        ids = np.concatenate([v[:, None], u], axis=1)                 # (c, 1+K)
        coef = np.concatenate([np.ones((len(v), 1)), -w], axis=1)
        coef = np.where(ids >= 0, coef, 0.0)
        K1 = ids.shape[1]
        a, b = np.meshgrid(np.arange(K1), np.arange(K1), indexing="ij")
        pairs = np.stack([ids[:, a.ravel()], ids[:, b.ravel()]], axis=2)   # (c, K1^2, 2)
        cc = coef[:, a.ravel()] * coef[:, b.ravel()]
        m = (pairs[..., 0] >= 0) & (pairs[..., 1] >= 0) & (cc != 0)
        B = cc[..., None, None] * nn[:, None]
        return [(pairs[m], B[m])]

    @staticmethod
    def empty():
        z = np.zeros((0, 3))
        return ContactSet(np.zeros(0, np.int64), z, z, np.zeros(0), np.zeros((0, 1), np.int64), np.zeros((0, 1)))


def gaussian_weights(x, P, h):
    """Normalised Gaussian weights (c,k) of candidates P (c,k,3) (NaN = invalid) around x (c,3)."""
    d2 = np.sum((P - x[:, None]) ** 2, axis=2)
    w = np.exp(-(d2 - np.nanmin(d2, axis=1, keepdims=True)) / h ** 2)
    w = np.where(np.isfinite(w), w, 0.0)
    return w / w.sum(1, keepdims=True)


def weighted_planes(x, P, N, h):
    """Gaussian-weighted planes at points x (c,3) from candidates P, N (c,k,3), width h (m).

    Invalid candidates carry NaN positions. Returns p (c,3), n (c,3) unit, weights (c,k).
    """
    w = gaussian_weights(x, P, h)
    p = np.einsum("ck,cki->ci", w, np.nan_to_num(P))
    n = np.einsum("ck,cki->ci", w, np.nan_to_num(N))
    return p, n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30), w


class BoneSurface:
    """A bone triangle mesh (vertices (B,3), triangles (F,3)) in its rest frame, normals
    oriented towards the flesh, queried as a Gaussian-weighted plane of the k nearest vertices."""

    def __init__(self, vertices, triangles, flesh_points, k=8):
        self.V = np.asarray(vertices, float)
        tri = np.asarray(triangles, np.int64)
        self.N = vertex_normals(self.V, tri, len(self.V))
        self.h = 0.5 * float(np.linalg.norm(self.V[tri[:, 1]] - self.V[tri[:, 0]], axis=1).mean())
        self.tree, self.k = cKDTree(self.V), min(k, len(self.V))
        if len(flesh_points):
            p, n = self.planes(flesh_points)
            if np.median(np.einsum("ci,ci->c", n, flesh_points - p)) < 0:
                self.N = -self.N

    def planes(self, points, M=None):
        """Planes (p (c,3), n (c,3)) in world space for points (c,3); M (4,4) the bone's
        current rigid transform (None = rest)."""
        R, t = (np.eye(3), np.zeros(3)) if M is None else (M[:3, :3], M[:3, 3])
        local = (points - t) @ R
        _, i = self.tree.query(local, k=self.k)
        i = i.reshape(len(points), -1)
        p, n, _ = weighted_planes(local, self.V[i], self.N[i], self.h)
        return p @ R.T + t, n @ R.T


class Collisions:
    """Contact model of a FaceModel's flesh: lips/lids self-contact and flesh against bone.

    stiffness: penalty stiffness N/m per contact vertex; radius: candidate search radius (m).
    """

    def __init__(self, model, free_mask, stiffness, radius=0.004, bone_gap=0.0):
        X0, tets = model.rest_positions, model.tets
        N = len(X0)
        self.n_vertices, self.stiffness, self.bone_gap = N, float(stiffness), bone_gap
        self.faces, _ = boundary_faces(tets)
        bverts = np.unique(self.faces)
        nrm = vertex_normals(X0, self.faces, N)
        cand = bverts[free_mask[bverts]]

        # flesh-flesh candidates: free boundary vertices near at rest, facing, separated, no shared tet
        ij = cKDTree(X0[cand]).query_pairs(radius, output_type="ndarray")
        pairs = cand[np.concatenate([ij, ij[:, ::-1]])] if len(ij) else np.zeros((0, 2), np.int64)
        facing = np.einsum("pi,pi->p", nrm[pairs[:, 0]], nrm[pairs[:, 1]]) < -0.5
        # v must lie on the outer side of u's surface at rest (not behind it)
        outside = np.einsum("pi,pi->p", nrm[pairs[:, 1]], X0[pairs[:, 0]] - X0[pairs[:, 1]]) >= -1e-9
        pairs = pairs[facing & outside]
        if len(pairs):
            pairs = pairs[~_share_tet(tets, N, pairs)]
        # padded partner table: self_vertices (c,), partners (c, kmax) with -1 padding
        self.self_vertices, inv = np.unique(pairs[:, 0], return_inverse=True)
        slot = np.zeros(len(pairs), np.int64)
        order = np.argsort(inv, kind="stable")
        counts = np.bincount(inv, minlength=len(self.self_vertices))
        slot[order] = group_offsets(counts)
        self.partners = np.full((len(self.self_vertices), counts.max(initial=0)), -1, np.int64)
        self.partners[inv, slot] = pairs[:, 1]
        self.radius = radius

        # flesh-bone candidates: free boundary vertices facing a bone (not the skin side),
        # within ``radius`` of it and outside it at rest
        self.bones = []
        for mesh, moves in ((model.cranium_mesh, False), (model.jaw_mesh, True)):
            if mesh is None or len(mesh[0]) == 0:
                continue
            d, _ = cKDTree(mesh[0]).query(X0[cand], distance_upper_bound=radius)
            near = cand[np.isfinite(d)]
            if not len(near):
                continue
            bone = BoneSurface(mesh[0], mesh[1], X0[near])
            p, n = bone.planes(X0[near])
            ok = (np.einsum("ci,ci->c", n, nrm[near]) < 0) & (np.einsum("ci,ci->c", n, X0[near] - p) >= -1e-9)
            if ok.any():
                self.bones.append((bone, moves, near[ok]))
        # the weighted planes of curved surfaces may cut a rest vertex slightly: measure
        # gaps from the rest gap where that is negative, so the rest state is contact-free
        self.offset = 0.0
        self.offset = np.minimum(self.detect(X0).gaps(X0), 0.0)

    def coupled_pairs(self):
        """Vertex pairs (P,2) that flesh-flesh contacts may couple (for the sparsity pattern)."""
        ids = np.concatenate([self.self_vertices[:, None], self.partners], axis=1)
        K1 = ids.shape[1]
        a, b = np.meshgrid(np.arange(K1), np.arange(K1), indexing="ij")
        pairs = np.stack([ids[:, a.ravel()], ids[:, b.ravel()]], axis=2).reshape(-1, 2)
        return pairs[(pairs >= 0).all(1)]

    def detect(self, X, jaw_matrix=None):
        """Current contacts (ContactSet) at positions X (N,3); jaw_matrix (4,4) moves the jaw."""
        parts = []
        K = max(self.partners.shape[1], 1)
        if len(self.self_vertices):
            nrm = vertex_normals(X, self.faces, self.n_vertices)
            valid = self.partners >= 0
            P = np.where(valid[..., None], X[self.partners], np.nan)
            _, n, w = weighted_planes(X[self.self_vertices], P, nrm[self.partners], 0.5 * self.radius)
            parts.append((self.self_vertices, np.zeros_like(n), n, self.partners, w, False))
        for bone, moves, near in self.bones:
            p, n = bone.planes(X[near], jaw_matrix if moves else None)
            parts.append((near, p + self.bone_gap * n, n, np.full((len(near), K), -1), np.zeros((len(near), K)),
                          moves))
        if not parts:
            return ContactSet.empty()
        v, p0, n, u, w = (np.concatenate(z) for z in list(zip(*parts))[:5])
        moving = np.concatenate([np.full(len(z[0]), z[5]) for z in parts])
        p0 = p0 + np.reshape(self.offset, (-1, 1)) * n
        M = np.eye(4) if jaw_matrix is None else jaw_matrix
        p_local, n_local = p0.copy(), n.copy()
        p_local[moving] = (p0[moving] - M[:3, 3]) @ M[:3, :3]
        n_local[moving] = n[moving] @ M[:3, :3]
        return ContactSet(v, p0, n, np.full(len(v), self.stiffness), u, w, moving, p_local, n_local)


def _share_tet(tets, n_vertices, pairs):
    """Whether each vertex pair (P,2) shares a tet."""
    import scipy.sparse as sp

    rows = np.repeat(np.arange(len(tets)), 4)
    inc = sp.csr_matrix((np.ones(rows.size), (tets.reshape(-1), rows)), shape=(n_vertices, len(tets)))
    adj = (inc @ inc.T).tocsr()
    return np.asarray(adj[pairs[:, 0], pairs[:, 1]]).ravel() > 0
