"""A FaceModel with its flesh mesh refined 1:8 (``refine(model)``): the same face, rig and
anatomy simulated on eight times the tets (the paper-scale bench: the resolution-4
template's tets become about a million, the paper's scale)."""
from __future__ import annotations


import numpy as np

from ..mesh.refine import subdivide
from ..mesh.tets import barycentric
from ..model.facemodel import FaceModel, Muscle
from ..sim.poisson import track_displacements


def refine(model: FaceModel, levels=1, progress=None) -> FaceModel:
    """A copy of ``model`` whose flesh tets are each cut into 8, ``levels`` times.

    The new vertices are edge midpoints, so the rest state is the same (stress-free) state.
    A midpoint between two cranium-fixed (jaw-fixed) vertices is cranium- (jaw-) fixed;
    its volumetric jaw weight is the mean of its edge's. A muscle owns the children of its
    tets, with the parent's fibre direction. The render surface is re-embedded in the child
    tet that contains it (same barycentric point). The Poisson track displacements (Eq. 10-11)
    are solved again on the refined mesh. The render surface, rig, landmarks, curves, bones
    and inner parts are unchanged."""
    say = progress or (lambda msg: None)
    m = model
    for _ in range(levels):
        say(f"refining {len(m.tets):,} tets")
        N = len(m.rest_positions)
        X, tets, edges = subdivide(m.rest_positions, m.tets)

        def fixed(ids):
            on = np.zeros(N, bool)
            on[ids] = True
            return np.concatenate([ids, N + np.flatnonzero(on[edges].all(1))]).astype(np.int64)

        vw = np.concatenate([m.volume_jaw_weights, m.volume_jaw_weights[edges].mean(1)])
        children = lambda t: (8 * np.asarray(t, np.int64)[:, None] + np.arange(8)).reshape(-1)
        muscles = [Muscle(mu.name, children(mu.tets), np.repeat(mu.fibers, 8, axis=0), mu.centerline,
                          mu.activation_curve, mu.side) for mu in m.muscles]
        # the child of each surface vertex's tet that holds its point (largest smallest weight)
        P = np.einsum("vk,vkd->vd", m.embed_weights, m.rest_positions[m.tets[m.embed_tets]])
        cand = children(m.embed_tets).reshape(-1, 8)
        w = np.stack([barycentric(X, tets, cand[:, c], P) for c in range(8)], axis=1)   # (V,8,4)
        best = np.argmax(w.min(axis=2), axis=1)
        # the rest carried over as it is (a new model: no surface models or embedding cached)
        m = m.replace(rest_positions=X, tets=tets, fixed_cranium=fixed(m.fixed_cranium),
                      fixed_jaw=fixed(m.fixed_jaw), volume_jaw_weights=vw, muscles=muscles,
                      embed_tets=cand[np.arange(len(cand)), best], embed_weights=w[np.arange(len(cand)), best],
                      track_displacements=None, meta={**m.meta, "refined": int(m.meta.get("refined", 0)) + 1})
    if model.track_displacements is not None:
        say("muscle-track precompute on the refined mesh (Poisson solves, Eq. 10-11)")
        m.track_displacements = track_displacements(m)
    return m

