"""Blendshape-driven volume displacements: the precomputed Poisson solves of paper 000 Eq. 10-11.

For every blendshape k the pre-skinning surface displacement B e_k is carried onto the outer
boundary of the rest tet mesh (Dirichlet data) and diffused into the volume by the
volumetric Laplacian of the rest mesh (linear-FEM cotangent weights), with natural (Neumann)
conditions on the inner boundary (bone attachments, mucosa, cut faces):

    A^U(X0) dX_k = A^C(X0) B e_k                                              (Eq. 11)

A^U is factorised once and all 3K right-hand sides are solved together. By linearity the
displacement of any combination sum_k b_k B e_k is sum_k b_k dX_k (Eq. 10).

The outer boundary is the set of boundary tet vertices, not attached to bone, that lie on the
render surface (within a quarter of the mean tet edge); the linear correspondence from the
surface to them is the barycentric weight of each one's closest point on the render mesh.
Where the mouth is closed at rest both lips' surfaces meet at the slit, and a lip's contact face
lies on the other lip's render surface. So a vertex counts as on the surface only if it is also
within reach with the jaw opened (``SEPARATING_OPENING``, where the lips are apart), and it takes
the triangle nearest there. Taking the nearest at rest gave the lower lip's slit and contact-face
vertices the upper lip's displacement: on the default head the field at the inner lower lip
missed lowerLipDepress by 4.8 of its 6.0 mm, and upperLipRaise moved it 3.9 mm
(``bench/tracks.py``).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu

from ..errors import InvfaceError
from ..mesh.closest import candidate_points
from ..mesh.tets import boundary_faces, laplacian, mean_edge_length
from ..model.rig import skin


# jaw opening (rad about the hinge) at which a lip vertex's own surface is told from the other
# lip's (``outer_boundary``)
SEPARATING_OPENING = 0.3


def outer_boundary(model, apart=True):
    """Outer-boundary tet vertices (B,) and the sparse correspondence S (B, V) with
    dX[ids] = S @ dx for a surface displacement dx (V, ...). apart: tell the closed lips apart
    (see the module's note), for displacements that part them (the blendshapes); without it a
    vertex takes the nearest triangle at rest, which keeps the lips' contact faces together, as
    a neutral-to-neutral morph (``morph.volume``) wants."""
    X0, tets = model.rest_positions, model.tets
    faces, _ = boundary_faces(tets)
    cand = np.unique(faces)
    bone = np.zeros(len(X0), bool)
    bone[model.fixed_cranium] = True
    bone[model.fixed_jaw] = True
    cand = cand[~bone[cand]]
    tol = 0.25 * mean_edge_length(X0, tets)
    tri, w, d = candidate_points(X0[cand], model.neutral, model.triangles)
    if apart:
        # the candidates within reach at rest, ranked by their distance with the jaw opened; a
        # vertex is on the surface when the best of them is within reach there too
        M = model.jaw_matrix(np.array([SEPARATING_OPENING, 0, 0, 0, 0, 0]))
        Vo = skin(model.neutral, model.jaw_weights, M)
        Xo = skin(X0[cand], model.volume_jaw_weights[cand], M)
        qo = np.einsum("pkj,pkji->pki", w, Vo[model.triangles[tri]])
        d = np.where(d <= tol, np.linalg.norm(qo - Xo[:, None], axis=2), np.inf)
    best = np.argmin(d, axis=1)
    rows = np.arange(len(cand))
    on = d[rows, best] <= tol
    if not on.any():
        raise InvfaceError("no tet-mesh boundary vertex lies on the render surface: the model's "
                           "embedding is broken (rebuild the model)")
    ids, tri, w = cand[on], tri[rows, best][on], w[rows, best][on]
    S = sp.csr_matrix((w.ravel(), (np.repeat(np.arange(len(ids)), 3), model.triangles[tri].ravel())),
                      shape=(len(ids), len(model.neutral)))
    return ids, S


class PoissonTransfer:
    """The factorised Dirichlet/Neumann volumetric Laplacian of a FaceModel's rest mesh."""

    def __init__(self, model):
        self.ids, self.S = outer_boundary(model)
        N = len(model.rest_positions)
        L = laplacian(model.rest_positions, model.tets).tocsr()
        self.free = np.setdiff1d(np.arange(N), self.ids)
        self.N = N
        self.L_fd = L[self.free][:, self.ids]
        self._lu = splu(L[self.free][:, self.free].tocsc())

    def solve(self, surface_deltas):
        """Volume displacements (K,N,3) for surface displacements (K,V,3) (Eq. 11)."""
        D = np.asarray(surface_deltas, float)
        K, V = D.shape[:2]
        flat = np.moveaxis(D, 0, 1).reshape(V, 3 * K)              # columns: (k, xyz)
        bc = self.S @ flat
        out = np.zeros((self.N, 3 * K))
        out[self.ids] = bc
        if K:
            out[self.free] = self._lu.solve(-(self.L_fd @ bc))
        return np.moveaxis(out.reshape(self.N, K, 3), 1, 0)


def track_displacements(model):
    """dX_k (K,N,3) of a FaceModel's blendshapes (pre-skinning deltas), Eq. 10-11."""
    return PoissonTransfer(model).solve(model.blendshapes)
