"""Layered-shell tetrahedral flesh between the template's skin and bone.

Every coarse skin triangle is extruded along its vertices' rays down to the bone in ``L``
layers; each prism is split into 3 tets by the global vertex-order rule (each quad side is
cut by the diagonal from its lowest-numbered vertex), which makes neighbouring prisms
conforming. The result is deterministic, keeps the coarse skin exactly and takes
milliseconds. Vertex id = layer * Ns + skin vertex id (layer 0 = skin, layer L = inner).
"""
from __future__ import annotations

import numpy as np

from ..mesh.tets import barycentric


def layer_radii(r_skin, r_inner, n_layers):
    """(L+1, ...) radii from skin (layer 0) to the inner surface (layer L), uniform in depth."""
    t = np.linspace(0.0, 1.0, n_layers + 1).reshape((-1,) + (1,) * np.ndim(r_skin))
    return r_skin[None] * (1 - t) + r_inner[None] * t


def prism_tets(triangles, n_skin, n_layers):
    """Tets (3*F*L, 4) of the extruded triangles, positively oriented later by the caller."""
    tri = np.sort(triangles, axis=1)   # the vertex-order rule needs a < b < c
    a, b, c = tri[:, 0], tri[:, 1], tri[:, 2]
    out = []
    for k in range(n_layers):
        o, o2 = k * n_skin, (k + 1) * n_skin
        out += [np.stack([a + o, b + o, c + o, c + o2], 1),
                np.stack([a + o, b + o, b + o2, c + o2], 1),
                np.stack([a + o, a + o2, b + o2, c + o2], 1)]
    return np.concatenate(out)


def embed_fine(coarse, fine, factor, X, tets, n_layers, Vf):
    """Barycentric embedding of the fine skin's vertices Vf (Vf,3) (the grid's positions as
    the build moved them: the lids opened) in the coarse tet mesh.

    Fine vertex (I, J) lies near coarse cell (I // f, J // f). The candidates are the tets of
    every layer under that cell and its 8 neighbours, never across a slit (a lip vertex is
    embedded in its own lip); the tet with the largest minimum barycentric weight wins, so
    a vertex inside the mesh gets weights in [0, 1] and one outside the coarse skin the
    mildest extrapolation. Returns (tet id (Vf,), weights (Vf,4)).
    """
    ni, nj = coarse.shape
    fg = fine.vertex_grid()
    n_grid_f = fine.shape[0] * fine.shape[1]
    dup_name = np.array([""] * n_grid_f + list(fine.dup_slit), dtype=object)
    ci = np.minimum(fg[:, 0] // factor, ni - 2)
    cj = np.minimum(fg[:, 1] // factor, nj - 2)
    n_tri = len(coarse.triangles)
    key = coarse.tri_cells[:, 0] * nj + coarse.tri_cells[:, 1]
    order = np.argsort(key, kind="stable")
    best_t = np.zeros(len(fg), np.int64)
    best_w = np.zeros((len(fg), 4))
    best_score = np.full(len(fg), -np.inf)
    for di in (-1, 0, 1):
        for dj in (-1, 0, 1):
            ci2 = np.clip(ci + di, 0, ni - 2)
            cj2 = np.clip(cj + dj, 0, nj - 2)
            allowed = np.ones(len(fg), bool)
            for s in coarse.slits:
                near = (ci2 >= s.i0) & (ci2 < s.i1)
                lower = (fg[:, 1] < s.row * factor) | (dup_name == s.name)
                across = np.where(lower, cj2 >= s.row, cj2 <= s.row - 1)
                allowed &= ~(near & across)
            first = np.searchsorted(key[order], ci2 * nj + cj2)
            for t in range(2):
                tri_id = order[np.minimum(first + t, n_tri - 1)]
                for layer in range(n_layers):
                    for m in range(3):
                        cand = (3 * layer + m) * n_tri + tri_id   # layout of prism_tets
                        w = barycentric(X, tets, cand, Vf)
                        score = np.where(allowed, w.min(1), -np.inf)
                        better = score > best_score
                        best_score = np.where(better, score, best_score)
                        best_t = np.where(better, cand, best_t)
                        best_w = np.where(better[:, None], w, best_w)
    return best_t, best_w
