"""Coarse (simulation) and fine (render) skin grids of the template, with mouth and eye slits.

The lips and eyelids are separated along a grid row: the vertices strictly between the
corners are duplicated and the cells below the row use the duplicates, so the lips (and the
lids) can part while the surface stays one connected mesh.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import grid
from .shape import EYE_INNER, EYE_OUTER, MOUTH_CORNER, skin_field


@dataclass
class Slit:
    """A cut along grid row ``row`` between corner columns ``i0`` < ``i1`` (both kept whole)."""
    name: str
    row: int
    i0: int
    i1: int

    def interior(self):
        return np.arange(self.i0 + 1, self.i1)

    def scaled(self, f):
        return Slit(self.name, self.row * f, self.i0 * f, self.i1 * f)


@dataclass
class SkinGrid:
    """A triangulated grid skin. Vertices = grid vertices (ni*nj, row-major in (i, j)) then
    the slit duplicates (lower side) in slit order."""
    alpha: np.ndarray      # (ni, nj) radians
    beta: np.ndarray       # (ni, nj)
    r: np.ndarray          # (ni, nj) metres from grid.CENTER
    slits: list
    triangles: np.ndarray  # (F,3)
    tri_cells: np.ndarray  # (F,2) lower-left cell (i, j) of each triangle
    dup_grid: np.ndarray   # (D,2) grid (i, j) of each duplicated vertex
    dup_slit: list         # slit name of each duplicate

    @property
    def shape(self):
        return self.alpha.shape

    def grid_index(self):
        ni, nj = self.shape
        return np.arange(ni * nj).reshape(ni, nj)

    def vertex_grid(self):
        """(V,2) grid (i, j) of every vertex, duplicates included."""
        ni, nj = self.shape
        i, j = np.meshgrid(np.arange(ni), np.arange(nj), indexing="ij")
        return np.concatenate([np.stack([i.ravel(), j.ravel()], 1), self.dup_grid])

    def positions(self, r=None):
        """(V,3) points at radius r (ni, nj) along each vertex's ray (default: the skin)."""
        r = self.r if r is None else r
        p = grid.CENTER + r[..., None] * grid.directions(self.alpha, self.beta)
        g = self.vertex_grid()
        return p[g[:, 0], g[:, 1]]

    def slit_vertices(self, name, side):
        """Vertex ids along a slit from corner i0 to corner i1; side 'upper' or 'lower'."""
        s = next(s for s in self.slits if s.name == name)
        idx = self.grid_index()
        ids = [idx[s.i0, s.row]]
        inner = idx[s.interior(), s.row]
        if side == "lower":
            nv = self.shape[0] * self.shape[1]
            dup = np.nonzero(np.array(self.dup_slit) == name)[0] + nv
            inner = dup
        return np.concatenate([ids, inner, [idx[s.i1, s.row]]])


def _apply_slits(ni, nj, slits):
    idx = np.arange(ni * nj).reshape(ni, nj)
    cells, tris = grid.quad_triangles(ni, nj, idx)
    dup_grid, dup_slit = [], []
    lower_tri = np.zeros(len(tris), bool)
    nv = ni * nj
    for s in slits:
        interior = s.interior()
        new = nv + len(dup_grid) + np.arange(len(interior))
        remap_s = np.arange(ni * nj + len(dup_grid) + len(interior))
        remap_s[idx[interior, s.row]] = new
        below = (cells[:, 1] == s.row - 1) & (cells[:, 0] >= s.i0) & (cells[:, 0] < s.i1)
        tris[below] = remap_s[tris[below]]
        lower_tri |= below
        dup_grid += [(i, s.row) for i in interior]
        dup_slit += [s.name] * len(interior)
    return tris, cells, np.array(dup_grid, int).reshape(-1, 2), dup_slit


def _slit_line(p0, p1, n, sag=0.0):
    """n points from p0 to p1 (x, y only), the middle lowered by ``sag`` metres."""
    s = np.linspace(0, 1, n)
    xy = (1 - s)[:, None] * p0[:2] + s[:, None] * p1[:2]
    xy[:, 1] -= sag * np.sin(np.pi * s)
    return xy


def _angles_of(xy):
    """(n,2) ray angles of the skin points seen from the front at xy (n,2)."""
    p = grid.point_at(skin_field, xy[:, 0], xy[:, 1])
    d = (p - grid.CENTER) / np.linalg.norm(p - grid.CENTER, axis=-1, keepdims=True)
    return np.stack(grid.angles(d), -1)


def _sizing(p):
    """Target edge-length factor: ~2x denser around eyes, nose and mouth than at the rim."""
    c = np.array([0.0, 0.0, 0.11])
    d2 = ((p[..., 0] / 0.05) ** 2 + ((p[..., 1] - c[1]) / 0.06) ** 2 + ((p[..., 2] - c[2]) / 0.06) ** 2)
    return 1.0 - 0.55 * np.exp(-d2)


def build_grids(n_alpha, n_beta, factor, relax_iters=120):
    """Coarse and fine SkinGrids. n_alpha must be odd (a centre column on the midline)."""
    if n_alpha % 2 == 0:
        n_alpha += 1
    a = np.linspace(*grid.ALPHA_RANGE, n_alpha)
    b = np.linspace(*grid.BETA_RANGE, n_beta)
    alpha, beta = np.meshgrid(a, b, indexing="ij")
    ic = n_alpha // 2
    fixed = np.zeros(alpha.shape, bool)
    fixed[0, :] = fixed[-1, :] = fixed[:, 0] = fixed[:, -1] = True
    slits = []

    def place(name, p_in, p_out, sag, symmetric_pair):
        # the row whose initial beta is nearest the feature, columns nearest its corners
        ang = _angles_of(np.array([p_in[:2], p_out[:2]]))
        row = int(np.argmin(np.abs(b - ang.mean(0)[1])))
        cols = [int(np.argmin(np.abs(a - x))) for x in ang[:, 0]]
        i0, i1 = min(cols), max(cols)
        if i1 - i0 < 2:
            i1 = i0 + 2
        line = _angles_of(_slit_line(p_in if cols[0] <= cols[1] else p_out,
                                     p_out if cols[0] <= cols[1] else p_in, i1 - i0 + 1, sag))
        alpha[i0:i1 + 1, row] = line[:, 0]
        beta[i0:i1 + 1, row] = line[:, 1]
        fixed[i0:i1 + 1, row] = True
        slits.append(Slit(name, row, i0, i1))
        if symmetric_pair:
            m0, m1 = n_alpha - 1 - i1, n_alpha - 1 - i0
            alpha[m0:m1 + 1, row] = -line[::-1, 0]
            beta[m0:m1 + 1, row] = line[::-1, 1]
            fixed[m0:m1 + 1, row] = True
            slits.append(Slit(symmetric_pair, row, m0, m1))

    mouth_r = MOUTH_CORNER * np.array([-1, 1, 1])
    place("mouth", mouth_r, MOUTH_CORNER, 0.0, None)
    place("eye_L", EYE_INNER, EYE_OUTER, 0.0012, "eye_R")
    assert slits[0].i0 < ic < slits[0].i1
    alpha, beta = grid.relax(skin_field, alpha, beta, fixed, _sizing, iters=relax_iters)

    grids = []
    for f, sl in ((1, slits), (factor, [s.scaled(factor) for s in slits])):
        A, B = grid.subdivide(alpha, beta, f) if f > 1 else (alpha, beta)
        r = grid.raycast(skin_field, A, B)
        tris, cells, dup_grid, dup_slit = _apply_slits(A.shape[0], A.shape[1], sl)
        grids.append(SkinGrid(A, B, r, sl, tris, cells, dup_grid, dup_slit))
    return grids[0], grids[1]
