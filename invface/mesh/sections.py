"""Plane sections of triangle meshes as ordered polylines, and arc-length parametrisation."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .triangles import unique_edges


@dataclass
class Section:
    """One connected chain of a plane section: points (n,3) (a closed loop repeats its first
    point at the end)."""
    points: np.ndarray
    closed: bool

    @property
    def length(self):
        return float(arc_length(self.points)[-1])


def arc_length(P):
    """Cumulative arc length (n,) of polyline P (n,3), starting at 0."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])


def resample(P, s_new, s=None):
    """Points of polyline P (n,d) at arc lengths s_new (m,) (s: P's own arc lengths)."""
    s = arc_length(P) if s is None else s
    return np.stack([np.interp(s_new, s, P[:, k]) for k in range(P.shape[1])], 1)


def resample_even(P, n):
    """n points equally spaced by arc length along polyline P (m,d), both ends kept."""
    s = arc_length(P)
    return resample(P, np.linspace(0, s[-1], n), s)


def plane_sections(V, F, origin, normal):
    """All connected chains where the plane (origin, normal) cuts the mesh (V (n,3), F (f,3)).

    Each crossed edge gives one point; two crossed edges of a triangle are joined. Returns a
    list of Section, longest first. Vertices exactly on the plane are nudged to one side.
    """
    V, F = np.asarray(V, float), np.asarray(F, np.int64)
    normal = np.asarray(normal, float) / np.linalg.norm(normal)
    d = (V - origin) @ normal
    d = np.where(d == 0, 1e-12, d)
    side = d[F] > 0
    F = F[side.any(1) & ~side.all(1)]             # only the triangles the plane cuts
    if len(F) == 0:
        return []
    edges, tri_edges = unique_edges(F)
    da, db = d[edges[:, 0]], d[edges[:, 1]]
    crossed = (da * db) < 0
    cross_ids = np.flatnonzero(crossed)
    if len(cross_ids) == 0:
        return []
    node = -np.ones(len(edges), np.int64)
    node[cross_ids] = np.arange(len(cross_ids))
    t = da[cross_ids] / (da[cross_ids] - db[cross_ids])
    e = edges[cross_ids]
    pts = V[e[:, 0]] + t[:, None] * (V[e[:, 1]] - V[e[:, 0]])
    tn = node[tri_edges]                                   # (F,3) node per triangle edge or -1
    hit = (tn >= 0).sum(1) == 2
    pair = np.sort(tn[hit], axis=1)[:, 1:]                 # the two non-negative entries
    chains = [Section(pts[np.r_[c, c[:1]] if closed else c], closed)
              for c, closed in walk_chains(pair, len(cross_ids))]
    chains.sort(key=lambda c: -c.length)
    return chains


def walk_chains(pairs, n):
    """The ordered chains through n nodes joined by the pairs (E,2): a list of (node ids (k,),
    closed). Open chains come first, each walked from an end (a degree-1 node); what remains
    is walked as closed loops (the first node is not repeated). At a node of degree 3 or more
    the walk takes the first unvisited neighbour."""
    adj = [[] for _ in range(n)]
    for a, b in pairs:
        adj[a].append(b)
        adj[b].append(a)
    seen = np.zeros(n, bool)
    chains = []
    starts = [i for i in range(n) if len(adj[i]) == 1] + list(range(n))
    for s in starts:
        if seen[s]:
            continue
        chain, prev, cur = [s], -1, s
        seen[s] = True
        while True:
            nxt = [k for k in adj[cur] if k != prev and not seen[k]]
            if not nxt:
                break
            prev, cur = cur, nxt[0]
            seen[cur] = True
            chain.append(cur)
        chains.append((np.array(chain), len(chain) > 2 and chain[0] in adj[chain[-1]]))
    return chains


def point_to_polyline(points, P):
    """Closest points on polyline P (n,3) to points (m,3): (arc length (m,), distance (m,))."""
    points = np.asarray(points, float).reshape(-1, 3)
    a, b = P[:-1], P[1:]
    ab = b - a
    L2 = np.maximum((ab ** 2).sum(1), 1e-30)
    u = np.clip(np.einsum("mkj,kj->mk", points[:, None, :] - a[None], ab) / L2, 0, 1)
    q = a[None] + u[..., None] * ab[None]
    dist = np.linalg.norm(q - points[:, None, :], axis=2)
    k = np.argmin(dist, axis=1)
    s = arc_length(P)
    rows = np.arange(len(points))
    return s[k] + u[rows, k] * np.sqrt(L2[k]), dist[rows, k]
