"""Carry per-vertex offsets (blendshapes) between two faces of the same topology.

The template and an actor morphed from it share their vertices, and both lie in the model
frame (+Y up, face along +Z), aligned by the morph. An offset sculpted on one is carried to
the same vertex of the other as it is, scaled by the ratio of the two faces' sizes. It is
not turned into a local frame: the morph slides vertices in the tangent plane and its
snapped normals are noisy, so per-vertex rotations (of the one-ring, or of the normal)
scatter the offsets' directions between neighbours and crease the carried shape.
"""
from __future__ import annotations

import numpy as np


def spread(X, ids):
    """RMS distance (m) of the vertices ``ids`` of X (V,3) from their centroid."""
    P = X[ids]
    return float(np.sqrt(((P - P.mean(0)) ** 2).sum(1).mean()))


def carry_offsets(deltas, source, target, face):
    """Offsets ``deltas`` (K,V,3) m on the face ``source`` (V,3) carried onto ``target`` (V,3)
    of the same topology, scaled by the ratio of the two faces' spreads over the vertex ids
    ``face``. Returns ((K,V,3) m, the scale)."""
    s = spread(target, face) / spread(source, face)
    return s * np.asarray(deltas, float), s
