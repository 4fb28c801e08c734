"""Eye and mouth openings: the template's lid and lip slits mapped onto a scan's rims.

The template's eyes and mouth are closed slits: each is a boundary loop of the skin whose
two halves (upper and lower lid, upper and lower lip) meet at the corners. A scan with open
eyes or parted lips has a wider hole there. Snapping the slit vertex by vertex onto such a
hole tears the lids and lips apart unevenly (both halves find the nearer rim). Instead each
half of the template's slit is mapped onto the matching half of the scan's rim, corner to
corner by normalised arc length; these are Dirichlet data of the surface morph and the
positions the snap keeps (paper 001 sec. 8: curves drive the morph; the rims are the
scan's hard eye and lip curves).

Before that, a scan whose lips roll into the mouth and lids into the sockets (production
heads) has those inner surfaces left out (``inner_surfaces``), so its rims are the lip and
lid lines, not holes at the back of the inner lips.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ..mesh.sections import arc_length, resample, walk_chains
from ..mesh.triangles import (boundary_edges, boundary_loops, boundary_vertices, covered_from_front,
                              edge_components, unique_edges)

# the openings and the landmarks at their ends
OPENINGS = {"eye_L": ("eye_inner_L", "eye_outer_L"), "eye_R": ("eye_inner_R", "eye_outer_R"),
            "mouth": ("mouth_corner_L", "mouth_corner_R")}
# the feature curves that run across each opening: its rims replace them once it is mapped
ACROSS = {"eye_L": (("eye_inner_L", "eye_outer_L"),), "eye_R": (("eye_inner_R", "eye_outer_R"),),
          "mouth": (("mouth_corner_L", "stomion"), ("stomion", "mouth_corner_R"))}
CORNER_TOL = 0.003      # m: a loop belongs to an opening when it passes this close to both corners
OPENING_REACH = 0.035   # m: a scan's hole is an eye or mouth opening when it comes this close
                        #    to the template's (the scan is aligned to the template)
MAX_INNER_FRACTION = 0.25   # more hidden skin than this behind the openings: not left out


def opening_centres(TL):
    """(k,3) midpoints of the corners of each opening in OPENINGS, from landmarks TL."""
    return np.array([0.5 * (np.asarray(TL[a]) + np.asarray(TL[b])) for a, b in OPENINGS.values()])


def inner_surfaces(V, F, centres, reach=OPENING_REACH):
    """Boolean (f,) of the scan's triangles behind its eye and mouth openings.

    Production heads (ICT-FaceKit, game rigs) model the lips rolling into the mouth and the
    lids into the sockets: the hole is at the back of the inner lip, behind a closed lip
    line, not at the lip line that the template's slit stands for. These inner surfaces are
    the triangles hidden from the front (+z, the aligned scan looks along +z) and connected,
    through hidden triangles, to a hole that comes within ``reach`` of one of the template's
    opening ``centres`` (k,3); the outermost boundary (the widest loop: neck or scan edge)
    is never one. What is left has its hole at the visible lip and lid line (paper 001
    sec. 7: the mouth occlusion curve). V (n,3) aligned scan, F (f,3)."""
    F = np.asarray(F, np.int64)
    loops = boundary_loops(F)
    out = np.zeros(len(F), bool)
    if len(loops) < 2:
        return out
    outer = max(range(len(loops)), key=lambda i: np.ptp(V[loops[i]], axis=0).sum())
    centres = np.reshape(centres, (-1, 3))
    rim = np.zeros(len(V), bool)
    for i, lp in enumerate(loops):
        if i != outer and (np.linalg.norm(V[lp][:, None] - centres[None], axis=2).min() < reach):
            rim[lp] = True
    if not rim.any():
        return out
    hidden = covered_from_front(V, F)
    edges, tri_edges = unique_edges(F)
    # hidden triangles joined through their shared edges (a graph of triangle and edge
    # nodes); the pieces that touch an opening's rim are the inner surfaces
    hid = np.flatnonzero(hidden)
    links = np.stack([np.repeat(hid, 3), len(F) + tri_edges[hid].ravel()], 1)
    lab = edge_components(links, len(F) + len(edges))[:len(F)]
    seed = hidden & rim[F].any(1)
    return hidden & np.isin(lab, lab[seed])


def ordered_loops(faces):
    """The open boundaries of a triangle mesh as ordered cycles: a list of vertex-id arrays
    (each loop once round, no repeat); boundaries that are not simple cycles are left out."""
    ids, local = np.unique(boundary_edges(faces), return_inverse=True)
    local = local.reshape(-1, 2)
    degree = np.bincount(local.ravel(), minlength=len(ids))
    return [ids[c] for c, closed in walk_chains(local, len(ids))
            if closed and len(c) >= 6 and (degree[c] == 2).all()]


def _side_height(V, F, half):
    """Mean height of the triangles touching the inner vertices of a loop half: the lid or
    lip the half borders (a closed slit's two halves lie on top of each other)."""
    touch = np.isin(F, half[1:-1]).any(1)
    return V[F[touch]].mean(axis=(0, 1))[1]


def split_loop(V, F, loop, a, b, tol=CORNER_TOL):
    """Split an ordered boundary loop (k,) of the mesh (V, F) at the vertices nearest the
    corner points a and b (3,) into its upper and lower halves, each running from a's vertex
    to b's vertex. Returns (upper ids, lower ids), or None when the loop misses a corner by
    more than tol."""
    da, db = (np.linalg.norm(V[loop] - p, axis=1) for p in (a, b))
    ia, ib = int(np.argmin(da)), int(np.argmin(db))
    if da[ia] > tol or db[ib] > tol or ia == ib:
        return None
    k = len(loop)
    one = loop[np.arange(ia, ia + (ib - ia) % k + 1) % k]
    two = loop[np.arange(ia, ia - (ia - ib) % k - 1, -1) % k]
    if min(len(one), len(two)) < 3:
        return None
    return (one, two) if _side_height(V, F, one) >= _side_height(V, F, two) else (two, one)


def map_openings(Vt, Ft, TL, Vg, Fg, L):
    """Template slit vertices and their places on the scan's rims.

    Vt (n,3), Ft: template skin; TL: template landmarks {name: (3,)}. Vg (m,3), Fg: the
    aligned scan; L: its landmarks. For every opening of OPENINGS that is a boundary loop on
    both meshes, each template half maps onto the scan half by normalised arc length.
    Returns (ids (k,) template vertex ids, positions (k,3) on the scan, names list)."""
    loops_t, loops_g = ordered_loops(Ft), ordered_loops(Fg)
    ids, pos, names = [], [], []
    for name, (a, b) in OPENINGS.items():
        halves_t = next((h for lp in loops_t if (h := split_loop(Vt, Ft, lp, TL[a], TL[b])) is not None), None)
        halves_g = next((h for lp in loops_g if (h := split_loop(Vg, Fg, lp, L[a], L[b])) is not None), None)
        if halves_t is None or halves_g is None:
            continue
        for ht, hg in zip(halves_t, halves_g):
            s, t = arc_length(Vt[ht]), arc_length(Vg[hg])
            ids.append(ht)
            pos.append(resample(Vg[hg], s / max(s[-1], 1e-12) * t[-1], t))
        names.append(name)
    if not ids:
        return np.zeros(0, np.int64), np.zeros((0, 3)), []
    ids, pos = np.concatenate(ids), np.concatenate(pos)
    ids, first = np.unique(ids, return_index=True)      # corners are in both halves
    return ids, pos[first], names


def lid_pairs(curves):
    """(P,2) template vertex ids of the two lids' facing points, corner to corner: the
    interiors of the eye curves (``eye_L_upper`` with ``eye_L_lower``, and R), which are the
    two sides of the lid slits; the template's eyes are open at rest, so these pairs do not
    coincide as the lips' do."""
    out = [np.zeros((0, 2), np.int64)]
    for s in ("L", "R"):
        up, lo = curves.get(f"eye_{s}_upper"), curves.get(f"eye_{s}_lower")
        if up is not None and lo is not None and len(up) == len(lo) > 2:
            out.append(np.stack([np.asarray(up)[1:-1], np.asarray(lo)[1:-1]], 1))
    return np.concatenate(out).astype(np.int64)


def closed_seams(Vt, Ft, TL, Vg, Fg, L, opened=(), tol=1e-7, reach=OPENING_REACH / 2, lids=None):
    """The template's slits as seams to close: pairs (P,2) of template vertex ids, the upper
    and the lower side of the same slit point (coincident in the template's neutral, as the
    lips are, or given in ``lids`` (P,2), the open eyes' ``lid_pairs``), of every opening of
    OPENINGS where the aligned scan (Vg, Fg; landmarks L) is closed: not in ``opened`` (those
    map onto a scan's rims) and with no hole of the scan within ``reach`` of the opening's
    centre (a hole whose rim could not be split at the corners is left to the
    vertex-by-vertex snap, as before). A bust's sculpted eyes are closed in this sense: the
    template's open lids are closed on them, and the carried eyeballs stay behind the skin.

    A scan whose eyes or lips are closed has no rim to map; snapped vertex by vertex, the two
    sides of the slit find different walls of the lip or lid line's groove and the slit tears
    open. ``surface.morph_surface`` holds each pair
    together on the scan instead."""
    b = np.flatnonzero(boundary_vertices(Ft, len(Vt)))
    pairs = np.array(sorted(cKDTree(Vt[b]).query_pairs(tol)), np.int64).reshape(-1, 2)
    pairs = b[pairs]
    if lids is not None and len(lids):
        pairs = np.concatenate([pairs, np.asarray(lids, np.int64).reshape(-1, 2)])
    if not len(pairs):
        return pairs
    centres = opening_centres(TL)
    names = list(OPENINGS)
    holes = [Vg[lp].mean(0) for lp in ordered_loops(Fg)]
    on_scan = opening_centres(L)
    closed = [n not in opened and not any(np.linalg.norm(h - c) < reach for h in holes)
              for n, c in zip(names, on_scan)]
    near = np.argmin(np.linalg.norm(Vt[pairs[:, 0]][:, None] - centres[None], axis=2), axis=1)
    return pairs[np.asarray(closed)[near]]
