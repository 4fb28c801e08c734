"""Triangle penalty contacts (paper 000 Eq. 3): flesh against flesh (lip on lip, lid on lid)
and flesh against bone (lips and cheeks against the teeth/jaw proxy).

A contact is a free boundary vertex x and a triangle (a, b, c) on the other side, paired once
at set-up: every facing triangle of the other lip or lid, or of the cranium or jaw mesh,
whose centroid lies within ``radius`` (1.5 tet edges, at least MIN_CONTACT_RADIUS) of the
vertex at rest. Its energy is

    E = w(r) e(gap),   gap = n . (x - a) - gap_rest,   r^2 = |x - centroid(a,b,c)|^2 - (n . (x - a))^2

with n the triangle's unit normal (so the plane moves and turns with the flesh or bone it
belongs to; jaw triangles move rigidly with the jaw transform), gap_rest the rest gap where
that is negative (the rest state is contact-free), e the C2 penalty of the penetration
(``base.penalty``), and w a C2 bump of r^2 (1 on the normal through the centroid, 0 from
``radius`` on): each triangle's plane stands for the facing surface only near that triangle,
and a vertex's triangles hand over to each other smoothly as it slides. One plane per vertex
extended without a gate makes false contacts (a lip dragged below the upper teeth's edge by
an open jaw lies far "behind" its planes). The gate measures r in the triangle's plane, not
in space: a gate of the 3D distance fades the contact as the vertex goes deeper, and lets a
lip pressed hard behind the teeth through.

The total contact energy is therefore a C2 function of the flesh positions and the jaw
parameters alone; its gradient and full Hessian (including the turning of the planes and
the gate) go into the Newton matrix and the tangent/adjoint solves, so the equilibrium is a
function of the controls, not of the path of the solve, and its derivatives are the
derivatives of that function (planes re-found during a solve would make it depend on the
path).

The lids slide on the eyeballs through a separate, exact sphere contact (``eyeballs``): a lid
crosses the whole eyeball when the eye closes, farther than a triangle's gate reaches.

Limits: a vertex that slides more than about ``radius`` from where it was at rest leaves its
triangles; a lip dragged past the edge of a bone mesh has no contact there.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ...mesh.tets import boundary_faces, tet_adjacency
from ...mesh.triangles import face_normals, group_offsets, vertex_normals
from .base import ContactModel, penalty, psd

MIN_CONTACT_RADIUS = 0.006   # m: the narrowest pairing radius and gate the simulator uses: a gate
#                              that narrows with a refined mesh hands a sliding lip from plane to
#                              plane abruptly (bench/history has the measurements)


def _skew(v):
    """Cross-product matrices (c,3,3): _skew(v) @ w = v x w."""
    z = np.zeros(len(v))
    return np.stack([np.stack([z, -v[:, 2], v[:, 1]], 1),
                     np.stack([v[:, 2], z, -v[:, 0]], 1),
                     np.stack([-v[:, 1], v[:, 0], z], 1)], 1)


# (e1, e2, d) = A q for q = (x, a, b, c): e1 = b - a, e2 = c - a, d = x - a
_A = np.kron(np.array([[0, -1, 1, 0], [0, -1, 0, 1], [1, -1, 0, 0]], float), np.eye(3))


def plane_gap(x, a, b, c, order=2):
    """Signed distances (c,) of points x from the planes of triangles (a, b, c) (each (c,3)),
    positive on the side of (b - a) x (c - a); with order >= 1 also the gradient (c,12) and
    with order 2 the Hessian (c,12,12) with respect to q = (x, a, b, c)."""
    e1, e2, d = b - a, c - a, x - a
    n = np.cross(e1, e2)
    L = np.linalg.norm(n, axis=1)
    nh = n / L[:, None]
    s = np.einsum("ci,ci->c", n, d)
    gap = s / L
    if order == 0:
        return gap
    z = np.zeros_like(n)
    ds = np.concatenate([np.cross(e2, d), np.cross(d, e1), n], 1)           # in (e1, e2, d)
    dL = np.concatenate([np.cross(e2, nh), np.cross(nh, e1), z], 1)
    dg = ds / L[:, None] - (s / L ** 2)[:, None] * dL
    if order == 1:
        return gap, dg @ _A
    Sd, S1, S2, Sn = _skew(d), _skew(e1), _skew(e2), _skew(nh)
    Z = np.zeros_like(Sd)
    Hs = np.concatenate([np.concatenate([Z, -Sd, S2], 2),
                         np.concatenate([Sd, Z, -S1], 2),
                         np.concatenate([-S2, S1, Z], 2)], 1)
    dn = np.concatenate([-S2, S1, Z], 2)                                      # (c,3,9)
    N2 = np.concatenate([np.concatenate([Z, -Sn, Z], 2),
                         np.concatenate([Sn, Z, Z], 2),
                         np.concatenate([Z, Z, Z], 2)], 1)
    outer = lambda u, v: np.einsum("ci,cj->cij", u, v)
    HL = (np.einsum("cki,ckj->cij", dn, dn) - outer(dL, dL)) / L[:, None, None] + N2
    Hg = (Hs / L[:, None, None] - (outer(ds, dL) + outer(dL, ds)) / (L ** 2)[:, None, None]
          + (2 * s / L ** 3)[:, None, None] * outer(dL, dL) - (s / L ** 2)[:, None, None] * HL)
    return gap, dg @ _A, _A.T @ Hg @ _A


def _smoothstep(u):
    """C2 smoothstep S(u) = 10u^3 - 15u^4 + 6u^5 on [0, 1] (clipped) and its two derivatives."""
    u = np.clip(u, 0.0, 1.0)
    return u ** 3 * (10 - 15 * u + 6 * u * u), 30 * u * u * (u - 1) ** 2, 60 * u * (2 * u - 1) * (u - 1)


_C = np.array([1.0, -1 / 3, -1 / 3, -1 / 3])      # x - centroid(a, b, c) = sum_k _C[k] q_k


def contact_energy(q, rest_gap, reach, k, order=2):
    """Energy of contacts q = (x, a, b, c) (c,12): the penalty of the gap of x from the
    plane of (a, b, c) less its rest gap ``rest_gap`` (c,), times a gate w of the in-plane
    distance r of x from the triangle's centroid (its distance from the normal line through
    the centroid), 1 within reach[:, 0] and falling smoothly (C2 in r^2) to 0 at reach[:, 1]
    (both (c,)): the plane of one triangle stands for the facing surface only near it, and a
    vertex pushed deep behind it is held as firmly as one just touching it. Stiffness k
    (N/m). Returns e (c,), and with order >= 1 the gradient (c,12), with order 2 the Hessian
    (c,12,12)."""
    x, a, b, c = (q[:, 3 * i:3 * i + 3] for i in range(4))
    out = plane_gap(x, a, b, c, order)
    g = out if order == 0 else out[0]
    e, de, dde = penalty(g - rest_gap, k)
    dv = x - (a + b + c) / 3
    rho = np.einsum("ci,ci->c", dv, dv) - g * g                 # squared in-plane distance
    span = reach[:, 1] ** 2 - reach[:, 0] ** 2
    S, dS, ddS = _smoothstep((rho - reach[:, 0] ** 2) / span)
    w, dw, ddw = 1 - S, -dS / span, -ddS / span ** 2
    if order == 0:
        return w * e
    dg = out[1]
    drho = 2 * (_C[None, :, None] * dv[:, None, :]).reshape(-1, 12) - 2 * g[:, None] * dg
    grad = (dw * e)[:, None] * drho + (w * de)[:, None] * dg
    if order == 1:
        return w * e, grad
    outer = lambda u, v: np.einsum("ci,cj->cij", u, v)
    Hg = out[2]
    Hrho = 2 * np.kron(np.outer(_C, _C), np.eye(3))[None] - 2 * outer(dg, dg) - 2 * g[:, None, None] * Hg
    H = ((ddw * e)[:, None, None] * outer(drho, drho) + (dw * e)[:, None, None] * Hrho
         + (dw * de)[:, None, None] * (outer(drho, dg) + outer(dg, drho))
         + (w * dde)[:, None, None] * outer(dg, dg) + (w * de)[:, None, None] * Hg)
    return w * e, grad, H


def _pairs(points, normals, Q, tri, radius, facing, exclude=None):
    """(point, triangle) pairs of points (P,3) with unit normals (P,3) and the triangles of
    (Q, tri) whose centroid lies within ``radius``, whose unit normal n has n . normal <
    ``facing`` and that have the point on their outer side; exclude(point ids, triangle ids)
    -> bool masks pairs out. Returns (point ids, triangle ids)."""
    if not len(points) or not len(tri):
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    fn = face_normals(Q, tri)
    fn /= np.linalg.norm(fn, axis=1, keepdims=True)
    near = cKDTree(Q[tri].mean(1)).query_ball_point(points, radius)
    i = np.repeat(np.arange(len(points)), [len(f) for f in near])
    f = np.fromiter((j for fs in near for j in fs), np.int64, count=len(i))
    keep = (np.einsum("ci,ci->c", normals[i], fn[f]) < facing) \
        & (np.einsum("ci,ci->c", fn[f], points[i] - Q[tri[f, 0]]) >= -1e-9)
    if exclude is not None and keep.any():
        keep[keep] = ~exclude(i[keep], f[keep])
    return i[keep], f[keep]


BONE_PAIRS_PER_VERTEX = 4     # a fine skull mesh (2 mm triangles) would pair ~25 per vertex


def _nearest_per_point(points, centroids, i, f, k):
    """Of the pairs (point ids i, triangle ids f), the k per point with the nearest centroid."""
    d = np.linalg.norm(points[i] - centroids[f], axis=1)
    order = np.lexsort((d, i))
    i, f = i[order], f[order]
    keep = group_offsets(np.bincount(i)) < k          # rank within each point's pairs
    return i[keep], f[keep]


def _bone_meshes(model):
    """[((V (n,3), F (f,3)), moves with the jaw?)]: the cranium with the upper teeth and the
    mandible with the lower teeth (where the model has inner parts), each as one mesh."""
    out = []
    for mesh, teeth, moves in ((model.cranium_mesh, "upper_teeth", False), (model.jaw_mesh, "lower_teeth", True)):
        pieces = [] if mesh is None or len(mesh[0]) == 0 else [(np.asarray(mesh[0], float), np.asarray(mesh[1], np.int64))]
        if model.parts is not None and teeth in model.parts.names:
            pieces.append(model.parts.mesh(teeth))
        if pieces:
            off = np.cumsum([0] + [len(v) for v, _ in pieces[:-1]])
            out.append(((np.concatenate([v for v, _ in pieces]),
                         np.concatenate([f + o for (_, f), o in zip(pieces, off)])), moves))
    return out


class TriangleContacts(ContactModel):
    """Penalty contacts of a FaceModel's flesh on triangles: lips/lids on each other and flesh
    against bone and teeth.

    free_mask (N,): the simulated vertices; stiffness: penalty stiffness N/m per contact;
    radius (m): the pairing distance at rest and the width of each contact's gate; adjacency
    (N,N) sparse: the tet mesh's vertex connectivity (``mesh.tets.tet_adjacency``), which keeps
    a vertex from pairing with a triangle of its own tets.

    Contacts are fixed at set-up: ``v`` (c,) free boundary vertices, ``tri`` (c,3) triangles
    as ids into the point array Q = (flesh vertices (N), cranium mesh vertices, jaw mesh
    vertices, each with its teeth) (``points``), the jaw's moved rigidly by the jaw
    transform. A flesh vertex is paired with every free boundary triangle whose centroid is
    within ``radius`` at rest, that faces it (normals opposed), has it on its outer side and
    shares no tet with it (the other lip or lid), and with the BONE_PAIRS_PER_VERTEX nearest
    bone (or teeth) triangles within ``radius`` facing it within 60 degrees.
    """

    def __init__(self, model, free_mask, stiffness, radius=0.004, adjacency=None):
        X0, tets = np.asarray(model.rest_positions, float), model.tets
        N = len(X0)
        self.n_vertices, self.stiffness, self.radius = N, float(stiffness), radius
        faces, _ = boundary_faces(tets)
        nrm = vertex_normals(X0, faces, N)
        bverts = np.unique(faces)
        #: the free boundary vertices (sorted ids): the vertices that can touch anything
        self.candidates = cand = bverts[free_mask[bverts]]

        # flesh on flesh
        tri = faces[free_mask[faces].all(1)]
        adj = tet_adjacency(tets, N) if adjacency is None else adjacency
        share = lambda i, f: np.any([np.asarray(adj[cand[i], tri[f, k]]).ravel() > 0 for k in range(3)], 0)
        i, f = _pairs(X0[cand], nrm[cand], X0, tri, radius, -0.5, share)
        vs, tris = [cand[i]], [tri[f]]

        # flesh on bone
        self.bone_vertices, offset, self.jaw_range, self.jaw_rest = [], N, (N, N), np.zeros((0, 3))
        for (V, T), moves in _bone_meshes(model):
            i, f = _pairs(X0[cand], nrm[cand], V, T, radius, 1.0)        # any orientation first
            if len(i) and np.median(np.einsum("ci,ci->c", face_normals(V, T[f]), X0[cand[i]] - V[T[f, 0]])) < 0:
                T = T[:, ::-1]                                          # normals towards the flesh
            i, f = _pairs(X0[cand], nrm[cand], V, T, radius, -0.5)
            i, f = _nearest_per_point(X0[cand], V[T].mean(1), i, f, BONE_PAIRS_PER_VERTEX)
            vs.append(cand[i])
            tris.append(T[f] + offset)
            self.bone_vertices.append(V)
            if moves:
                self.jaw_range, self.jaw_rest = (offset, offset + len(V)), V
            offset += len(V)
        self.v, self.tri = np.concatenate(vs), np.concatenate(tris)
        self.flesh = (self.tri < N).all(1)
        self.rest_gap = np.zeros(len(self.v))
        Q0 = self.points(X0, np.eye(4))
        q0 = self._q(Q0)
        self.rest_gap = np.minimum(plane_gap(*(q0[:, 3 * i:3 * i + 3] for i in range(4)), order=0), 0.0)
        self.reach = np.tile([0.0, radius], (len(self.v), 1))

    def __len__(self):
        return len(self.v)

    def points(self, X, M):
        """The point array Q (N + bone vertices, 3): flesh positions X (N,3), cranium mesh
        vertices, jaw mesh vertices moved by the jaw transform M (4,4)."""
        parts = [np.asarray(X, float)] + list(self.bone_vertices)
        Q = np.concatenate(parts) if len(parts) > 1 else parts[0].copy()
        j0, j1 = self.jaw_range
        Q[j0:j1] = Q[j0:j1] @ M[:3, :3].T + M[:3, 3]
        return Q

    def _q(self, Q, m=slice(None)):
        return np.concatenate([Q[self.v[m]], Q[self.tri[m]].reshape(-1, 9)], 1)

    def coupled_pairs(self):
        """Flesh vertex pairs (P,2) that contacts couple (for the sparsity pattern)."""
        ids = np.concatenate([self.v[:, None], self.tri], 1)[self.flesh]
        a, b = np.meshgrid(np.arange(4), np.arange(4), indexing="ij")
        return np.stack([ids[:, a.ravel()], ids[:, b.ravel()]], 2).reshape(-1, 2)

    def gaps(self, X, M):
        """Gaps (c,) (m) of the contacts at positions X (N,3) and jaw transform M (4,4), less
        their rest gaps; negative = penetrating (whether or not the gate lets them act)."""
        q = self._q(self.points(X, M))
        return plane_gap(*(q[:, 3 * i:3 * i + 3] for i in range(4)), order=0) - self.rest_gap

    def acting(self, X, M):
        """Which contacts act (c,) bool at positions X (N,3), jaw transform M (4,4):
        penetrating and inside their gate."""
        return self._acting(self.points(X, M))

    def _acting(self, Q):
        q = self._q(Q)
        gap = plane_gap(*(q[:, 3 * i:3 * i + 3] for i in range(4)), order=0) - self.rest_gap
        dv = q[:, :3] - Q[self.tri].mean(1)
        rho = np.einsum("ci,ci->c", dv, dv) - (gap + self.rest_gap) ** 2
        return (gap < 0) & (rho < self.reach[:, 1] ** 2)

    def kinds(self):
        """Masks (c,) of the flesh-flesh, flesh-cranium and flesh-jaw contacts (a dict)."""
        jaw = (self.tri >= self.jaw_range[0]).all(1) & (self.tri < self.jaw_range[1]).all(1)
        return {"flesh": self.flesh, "cranium": ~self.flesh & ~jaw, "jaw": jaw}

    def _active(self, X, M, order):
        """The contacts that act: (mask (c,), their contact_energy terms)."""
        Q = self.points(X, M)
        m = self._acting(Q)
        return m, contact_energy(self._q(Q, m), self.rest_gap[m], self.reach[m], self.stiffness, order)

    def energy(self, X, M):
        """Collision energy (J) at positions X (N,3), jaw transform M (4,4)."""
        return float(self._active(X, M, 0)[1].sum())

    def gradient(self, X, M):
        """Energy gradient (N,3) (= minus the collision forces)."""
        m, (_, grad) = self._active(X, M, 1)
        ids = np.concatenate([self.v[m, None], self.tri[m]], 1).reshape(-1)
        grad = grad.reshape(-1, 3)
        flesh = ids < self.n_vertices
        out = np.zeros((self.n_vertices, 3))
        np.add.at(out, ids[flesh], grad[flesh])
        return out

    def blocks(self, X, M, project=False):
        """Hessian blocks [(pairs (P,2), B (P,3,3))] of the acting contacts over their flesh
        vertices (each contact's 12x12 Hessian projected to PSD when ``project``)."""
        return self._blocks(X, M, psd if project else (lambda H: H))

    def acting_vertices(self, X, M):
        """The flesh vertices (sorted ids) of the contacts acting at positions X (N,3), jaw
        transform M (4,4): each acting contact's vertex and its triangle's flesh vertices."""
        m = self.acting(X, M)
        ids = np.concatenate([self.v[m], self.tri[m].ravel()])
        return np.unique(ids[ids < self.n_vertices])

    def projection_blocks(self, X, M):
        """The blocks, as ``blocks``, that projecting each acting contact's Hessian to PSD adds
        to its exact Hessian (each PSD): project_psd(H) - H."""
        return self._blocks(X, M, lambda H: psd(H) - H)

    def _blocks(self, X, M, fix):
        """``blocks`` with each contact's Hessian H (c,n,n) replaced by fix(H)."""
        m, (_, _, H) = self._active(X, M, 2)
        H = fix(H)
        ids = np.concatenate([self.v[m, None], self.tri[m]], 1)
        a, b = np.meshgrid(np.arange(4), np.arange(4), indexing="ij")
        pairs = np.stack([ids[:, a.ravel()], ids[:, b.ravel()]], 2).reshape(-1, 2)
        B = H.reshape(-1, 4, 3, 4, 3).transpose(0, 1, 3, 2, 4).reshape(-1, 3, 3)
        keep = (pairs < self.n_vertices).all(1)
        return [(pairs[keep], B[keep])]

    def jaw_derivative(self, X, M, dM):
        """d(energy gradient)/d(jaw parameter) (P,N,3) for jaw-transform derivatives dM (P,4,4):
        the acting contacts on jaw triangles, H[x, (a,b,c)] d(a,b,c)/dj."""
        out = np.zeros((len(dM), self.n_vertices, 3))
        m, (_, _, H) = self._active(X, M, 2)
        j0 = self.jaw_range[0]
        on_jaw = self.kinds()["jaw"][m]
        if not on_jaw.any():
            return out
        H = H[on_jaw]
        v, tri = self.v[m][on_jaw], self.tri[m][on_jaw]
        rest = self.jaw_rest[tri - j0]                                       # (c,3,3) jaw frame
        for i, D in enumerate(dM):
            dq = (rest @ D[:3, :3].T + D[:3, 3]).reshape(-1, 9)
            np.add.at(out[i], v, np.einsum("cij,cj->ci", H[:, :3, 3:], dq))
        return out
