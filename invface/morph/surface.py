"""Surface morph of the template skin onto the target (paper 001 sec. 8, 8.1).

1. Poisson morph: three Poisson equations (one per displacement component) on the template
   surface, discretised by the finite-volume Laplacian with control areas of one third of
   the incident triangles and length-weighted fluxes F_ij = L_ij (u_j - u_i) / |x_j - x_i|,
   L_ij the dual edge (edge midpoint to the centroids of the two triangles). Dirichlet values
   are the curve displacements: every template vertex within half an edge of a template
   curve moves with the curve point at its normalised arc length on the target curve.
   (The paper puts Dirichlet conditions where mesh edges cross the curves, second-order
   after Gibou et al.; here they sit on the nearest vertices, first order, which at the
   template's 1-2 mm edges is below the snapping error.) The matrix is factorised once.
2. Snap: the target is projected onto the smooth morphed template (closest points); each
   morphed template vertex is then located in that projected copy of the target, and the
   same barycentric weights on the real target give its snapped position (Fig. 10c-d).
   Target triangles that face away from the template where they project (nostril walls and
   other cavities, which the paper's shrink-wrapped targets do not have) and those in the
   ear boxes (sec. 9.1) are not snapped onto; template vertices inside an ear box do not
   snap. The template's eye and lip slits, mapped onto a scan's open eyes and parted lips
   (openings.py), are Dirichlet data of step 1 and keep their rim positions; where the scan's
   eyes or lips are closed, the slit's two sides are held together on the scan (seams).
3. Inverted triangles (normal against the target's interpolated normal) are grown into a
   region (two rings), relaxed with zero-length springs holding the region's boundary, and
   resnapped; repeated a few times. Folds left after that, with a ring around them, are not
   snapped (the fill of step 4 takes them).
4. Partial targets (sec. 8.1): template vertices with no target under them (closest target
   point on the target's boundary, or farther than a tolerance) are not snapped; a second
   Poisson solve with the snapped vertices as Dirichlet data fills them in smoothly.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import splu
from scipy.spatial import cKDTree

from ..mesh.closest import barycentric_points, closest_points
from ..mesh.sections import arc_length, point_to_polyline
from ..mesh.tets import graph_laplacian, harmonic
from ..mesh.triangles import boundary_vertices, face_normals, triangle_areas, unique_edges, vertex_normals

SNAP_DISTANCE = 0.01          # m: farther template vertices are "off the scan" (sec. 8.1)
CARRY_BAND = 0.03             # m: off-scan vertices farther than this from the scan follow the carried template


def fv_laplacian(V, F):
    """The finite-volume Laplacian (n,n) (symmetric, positive semidefinite, flux form) and
    the control areas (n,) (one third of the incident triangle areas)."""
    V, F = np.asarray(V, float), np.asarray(F, np.int64)
    edges, tri_edges = unique_edges(F)
    cen = V[F].mean(1)
    L = np.zeros(len(edges))
    for k in range(3):
        e = tri_edges[:, k]
        mid = 0.5 * (V[F[:, k]] + V[F[:, (k + 1) % 3]])
        np.add.at(L, e, np.linalg.norm(cen - mid, axis=1))
    w = L / np.maximum(np.linalg.norm(V[edges[:, 0]] - V[edges[:, 1]], axis=1), 1e-30)
    n = len(V)
    i, j = edges[:, 0], edges[:, 1]
    A = sp.coo_matrix((np.concatenate([-w, -w, w, w]), (np.concatenate([i, j, i, j]),
                                                        np.concatenate([j, i, i, j]))), shape=(n, n)).tocsr()
    area = triangle_areas(V, F)
    ctrl = np.zeros(n)
    for k in range(3):
        np.add.at(ctrl, F[:, k], area / 3)
    return A, ctrl


class SurfacePoisson:
    """Dirichlet solves u (n,3) with A u = 0 on the free vertices; the factorisation is kept
    per Dirichlet set (the paper: everything but the values is precomputed)."""

    def __init__(self, V, F):
        self.A, _ = fv_laplacian(V, F)
        self._cache = {}

    def solve(self, fixed, values):
        fixed = np.asarray(fixed)
        key = fixed.tobytes()
        n = self.A.shape[0]
        if key not in self._cache:
            free = np.setdiff1d(np.arange(n), fixed)
            self._cache = {key: (free, splu(self.A[free][:, free].tocsc()), self.A[free][:, fixed])}
        free, lu, Afd = self._cache[key]
        u = np.zeros((n, 3))
        u[fixed] = values
        u[free] = lu.solve(-(Afd @ values))
        return u


def curve_dirichlet(V, curves_t, curves_g, tol):
    """Template vertex ids (c,) near the template curves and their displacements (c,3).

    curves_t / curves_g: {key: (S,3)} matched template / target polylines (equal S); a vertex
    within ``tol`` of a template curve moves by the target-minus-template curve displacement
    at its normalised arc length; vertices near several curves average them.
    """
    acc = np.zeros((len(V), 3))
    cnt = np.zeros(len(V))
    tree = cKDTree(V)
    for key, Ct in curves_t.items():
        Cg = curves_g[key]
        cand = np.unique(np.concatenate(tree.query_ball_point(Ct, tol * 2))).astype(np.int64)
        if len(cand) == 0:
            continue
        s, d = point_to_polyline(V[cand], Ct)
        ok = d <= tol
        cand, s = cand[ok], s[ok]
        u = s / max(arc_length(Ct)[-1], 1e-12) * (len(Ct) - 1)
        k = np.clip(np.floor(u).astype(int), 0, len(Ct) - 2)
        f = (u - k)[:, None]
        disp = (1 - f) * (Cg[k] - Ct[k]) + f * (Cg[k + 1] - Ct[k + 1])
        np.add.at(acc, cand, disp)
        np.add.at(cnt, cand, 1)
    ids = np.flatnonzero(cnt)
    return ids, acc[ids] / cnt[ids, None]


def snap(Vm, Ft, Vg, Fg, normals=None, max_distance=SNAP_DISTANCE):
    """Snap the morphed template (Vm (n,3), Ft) onto the target (Vg, Fg) via the target
    projected onto the template (Fig. 10c-d). Returns snapped positions (n,3) and a mask (n,)
    of vertices that found the target (False: off a partial scan, sec. 8.1), and each
    vertex's target triangle (n,) and barycentric weights (n,3)."""
    # 1. the target onto the morphed template
    tri, w, dist = closest_points(Vg, Vm, Ft)
    Vproj = barycentric_points(Vm, Ft, tri, w)
    # target triangles facing away from the template where they project (the walls of
    # nostrils and other cavities, which the paper's shrink-wrapped target does not have)
    # are not snapped onto
    Nt = vertex_normals(Vm, Ft) if normals is None else normals
    facing = np.einsum("ij,ij->i", vertex_normals(Vg, Fg), barycentric_points(Nt, Ft, tri, w)) > 0
    keep = np.flatnonzero(facing[Fg].all(1))
    Fg = Fg[keep]
    # 2. each template vertex located in the projected target, mapped to the real target
    tri2, w2, d2 = closest_points(Vm, Vproj, Fg)
    snapped = barycentric_points(Vg, Fg, tri2, w2)
    on_edge = boundary_vertices(Fg, len(Vg))[Fg[tri2]]
    support = w2 > 1e-6
    on_border = (on_edge & support).sum(1)
    # on a target boundary edge, or at a boundary vertex (past a corner of the border, where
    # every template vertex beyond it would otherwise snap onto that one vertex)
    at_border = (on_border >= 2) | ((support.sum(1) == 1) & (on_border == 1))
    # a target triangle whose vertices projected far (behind, across a hole) is unreliable
    far = dist[Fg[tri2]].max(1) > max_distance
    ok = ~at_border & ~far & (d2 < max_distance) & (np.linalg.norm(snapped - Vm, axis=1) < 2 * max_distance)
    return snapped, ok, keep[tri2], w2


def inverted_triangles(Vs, Ft, Vg, Fg):
    """Boolean (f,) of snapped template triangles whose normal opposes the target's normal
    at their centroid (the paper's level-set normal test)."""
    fn = face_normals(Vs, Ft)
    tri, w, _ = closest_points(Vs[Ft].mean(1), Vg, Fg)
    gn = barycentric_points(vertex_normals(Vg, Fg), Fg, tri, w)
    return np.einsum("ij,ij->i", fn, gn) < 0


def _rings(F, ids, n, rings):
    """Boolean (n,) mask of vertices ``ids`` grown by ``rings`` triangle rings."""
    mask = np.zeros(n, bool)
    mask[ids] = True
    for _ in range(rings):
        mask[F[mask[F].any(1)].ravel()] = True
    return mask


def relax_region(Vs, Ft, bad_tris, rings=2, held=()):
    """Relax the vertices around ``bad_tris`` with zero-length springs (a uniform-weight
    harmonic solve) holding the region's boundary and the vertices ``held``; returns new
    positions (n,3) and the region mask (n,)."""
    n = len(Vs)
    region = _rings(Ft, np.unique(Ft[bad_tris]), n, rings)
    Lu = graph_laplacian(unique_edges(Ft)[0], n)
    # the region's outer ring is held: free = region minus vertices touching the outside
    touching = np.asarray(Lu @ (~region).astype(float)).ravel() < 0
    free = np.setdiff1d(np.flatnonzero(region & ~touching), held)
    if len(free) == 0:
        return Vs.copy(), region
    fixed = np.setdiff1d(np.arange(n), free)
    return harmonic(Lu, fixed, Vs[fixed]), region


@dataclass
class SurfaceMorph:
    """Result of the surface morph: positions (n,3) of the template skin on the target,
    the Poisson-only positions (n,3), the snapped mask (n,), inverted triangles left (int),
    relaxation rounds run (int), the curve-vertex count (int), and each vertex's target
    triangle (n,) and barycentric weights (n,3) (meaningful where snapped)."""
    positions: np.ndarray
    poisson: np.ndarray
    snapped: np.ndarray
    inverted: int
    relax_rounds: int
    dirichlet_vertices: int
    target_triangles: np.ndarray
    target_weights: np.ndarray


def in_boxes(P, boxes):
    """Boolean (n,) of points P (n,3) inside any of the boxes (k,2,3) (min, max corners)."""
    P = np.asarray(P)
    inside = np.zeros(len(P), bool)
    for lo, hi in boxes:
        inside |= ((P >= lo) & (P <= hi)).all(1)
    return inside


def morph_surface(Vt, Ft, Vg, Fg, curves_t, curves_g, rims=None, no_snap=(), seams=None, carried=None,
                  relax_rounds=4, progress=None):
    """Morph the template skin (Vt (n,3), Ft) onto the aligned target (Vg, Fg) using matched
    curve pairs (``curves_t`` on the template, ``curves_g`` on the target) and, optionally,
    ``rims`` = (template vertex ids (k,), their positions (k,3) on the target's eye and lip
    openings) from openings.map_openings: Dirichlet data of the Poisson morph that the snap
    keeps; curve vertices within two rings of them are left to the rims. ``no_snap``: boxes
    (k,2,3) (the scan's ears, sec. 9.1) where no target triangle is snapped onto and no
    template vertex snaps; the Poisson fill closes them. ``seams`` (P,2): template vertex
    pairs held together (closed slits, openings.closed_seams): each pair goes to the target
    point nearest its Poisson-morphed midpoint, as a rim would. ``carried`` (n,3): the
    template skin carried onto the target by the face's similarity; template vertices off the
    target and more than ``CARRY_BAND`` from any snapped one (the back of a partial scan, a
    scalp under hair) are held there in the fill, which blends the band between. Returns
    SurfaceMorph."""
    say = progress or (lambda m: None)
    edge = float(np.median(np.linalg.norm(Vt[Ft[:, 0]] - Vt[Ft[:, 1]], axis=1)))
    ids, disp = curve_dirichlet(Vt, curves_t, curves_g, tol=0.6 * edge)
    rid, rpos = rims if rims is not None else (np.zeros(0, np.int64), np.zeros((0, 3)))
    rtri, rw = np.zeros(0, np.int64), np.zeros((0, 3))
    if len(rid):
        keep = ~_rings(Ft, rid, len(Vt), 2)[ids]
        ids, disp = np.concatenate([ids[keep], rid]), np.concatenate([disp[keep], rpos - Vt[rid]])
        rtri, rw, _ = closest_points(rpos, Vg, Fg)
    say(f"surface Poisson: {len(ids)} curve and rim vertices as Dirichlet data")
    solver = SurfacePoisson(Vt, Ft)
    Vm = Vt + solver.solve(ids, disp)
    if seams is not None and len(seams):
        ids, disp, (rid, rpos, rtri, rw) = _hold_seams(Vt, Vm, Vg, Fg, seams, ids, disp, (rid, rpos, rtri, rw))
        say(f"{len(seams)} closed-slit vertex pairs held together on the target")
        Vm = Vt + solver.solve(ids, disp)

    Nt = vertex_normals(Vt, Ft)
    boxes = np.reshape(no_snap, (-1, 2, 3))
    usable = np.flatnonzero(~in_boxes(Vg[Fg].mean(1), boxes))

    def snap_keeping_rims(V):
        Vs, ok, tri, w = snap(V, Ft, Vg, Fg[usable], normals=Nt)
        tri = usable[tri]
        ok &= ~in_boxes(V, boxes)
        Vs[rid], ok[rid], tri[rid], w[rid] = rpos, True, rtri, rw
        return Vs, ok, tri, w

    say("snapping onto the target")
    Vs, ok, tri, w = snap_keeping_rims(Vm)
    rounds = 0
    bad = inverted_triangles(np.where(ok[:, None], Vs, Vm), Ft, Vg, Fg) & ok[Ft].all(1)
    while bad.any() and rounds < relax_rounds:
        rounds += 1
        say(f"relaxing {int(bad.sum())} inverted triangles (round {rounds})")
        relaxed, region = relax_region(np.where(ok[:, None], Vs, Vm), Ft, bad, held=rid)
        Vs2, ok2, tri2, w2 = snap_keeping_rims(relaxed)
        Vs = np.where(region[:, None], Vs2, Vs)
        ok = np.where(region, ok2, ok)
        tri = np.where(region, tri2, tri)
        w = np.where(region[:, None], w2, w)
        bad = inverted_triangles(np.where(ok[:, None], Vs, Vm), Ft, Vg, Fg) & ok[Ft].all(1)
    if bad.any():
        # folds the relaxation could not undo (a template ala snapped into a scan's nostril):
        # their vertices, and a ring around them, are left to the Poisson fill
        fold = _rings(Ft, np.unique(Ft[bad]), len(Vt), 1) & ~np.isin(np.arange(len(Vt)), rid)
        ok &= ~fold
        say(f"{int(bad.sum())} triangles still folded: {int(fold.sum())} vertices around them left to the fill")
    if not ok.all():
        Vs = _fill(Vt, Vs, ok, solver, carried, say)
    return SurfaceMorph(Vs, Vm, ok, int(bad.sum()), rounds, len(ids), tri, w)


def _hold_seams(Vt, Vm, Vg, Fg, seams, ids, disp, rims):
    """Closed slits (``seams`` (P, 2) template vertex pairs): both sides on the target point
    nearest their Poisson-morphed midpoint (``Vm``), added to the Dirichlet data (ids,
    displacements) in place of any curve data they had, and to the rims (ids, positions,
    target triangles, barycentrics) the snap keeps. Returns (ids, disp, rims)."""
    rid, rpos, rtri, rw = rims
    stri, sw, _ = closest_points(0.5 * (Vm[seams[:, 0]] + Vm[seams[:, 1]]), Vg, Fg)
    spos = barycentric_points(Vg, Fg, stri, sw)
    sid = seams.T.ravel()
    rims = (np.concatenate([rid, sid]), np.concatenate([rpos, spos, spos]),
            np.concatenate([rtri, stri, stri]), np.concatenate([rw, sw, sw]))
    keep = ~np.isin(ids, sid)
    ids, disp = np.concatenate([ids[keep], sid]), np.concatenate([disp[keep], np.concatenate([spos, spos]) - Vt[sid]])
    return ids, disp, rims


def _fill(Vt, Vs, ok, solver, carried, say):
    """The skin with the template vertices off the target (``~ok``) filled by a Poisson solve
    held at the snapped ones (``Vs``); with ``carried``, those more than ``CARRY_BAND`` from any
    snapped vertex are held at the template carried by the face's similarity."""
    say(f"{int((~ok).sum())} template vertices off the target: filled by a second Poisson solve")
    D, held = np.where(ok[:, None], Vs - Vt, 0.0), ok.copy()
    if carried is not None:
        far = ~ok
        far[far] = cKDTree(Vt[ok]).query(Vt[far])[0] > CARRY_BAND
        D[far], held[far] = carried[far] - Vt[far], True
        say(f"{int(far.sum())} of them follow the template carried by the face's similarity")
    fixed = np.flatnonzero(held)
    return Vt + solver.solve(fixed, D[fixed])
