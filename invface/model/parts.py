"""The head's rigid inner parts: eyeballs, teeth, tongue and the mouth cavity's lining.

They are not simulated: each vertex follows the cranium (jaw weight 0), the jaw (1) or a
blend of the two (the lining stretches between the palate and the floor of the mouth), by the
same linear blend skinning as the rig (``rig.skin``). They are rendered with their own fixed
albedo, which lives in the calibration's gauge (the skin's mean albedo is ``SKIN_ALBEDO``), so
a calibrated light shows them as bright relative to the skin as a real mouth and eye are.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .rig import skin


@dataclass
class InnerParts:
    """Meshes of the parts, concatenated: vertices (P,3) m in the model frame at rest,
    triangles (Fp,3) outward-facing (the lining faces the cavity), albedo (P,3) linear RGB,
    jaw_weights (P,) in [0, 1], names (n,) and offsets (n+1,): part i owns the vertices
    offsets[i]:offsets[i+1]."""
    vertices: np.ndarray
    triangles: np.ndarray
    albedo: np.ndarray
    jaw_weights: np.ndarray
    names: list
    offsets: np.ndarray

    def posed(self, jaw_matrix) -> np.ndarray:
        """Vertex positions (P,3) m with the jaw at ``jaw_matrix`` (4,4), before the head pose."""
        return skin(self.vertices, self.jaw_weights, np.asarray(jaw_matrix, float))

    def part(self, name) -> slice:
        """The vertex range of part ``name``."""
        i = list(self.names).index(name)
        return slice(int(self.offsets[i]), int(self.offsets[i + 1]))

    def mesh(self, name):
        """(vertices (n,3), triangles (f,3)) of part ``name`` alone, at rest."""
        sl = self.part(name)
        T = self.triangles[(self.triangles >= sl.start).all(1) & (self.triangles < sl.stop).all(1)]
        return self.vertices[sl], T - sl.start

    def with_vertices(self, vertices) -> "InnerParts":
        """The same parts with other rest positions (P,3) (a morphed actor's)."""
        return InnerParts(np.asarray(vertices, float), self.triangles, self.albedo, self.jaw_weights,
                          list(self.names), self.offsets)

    def validate(self):
        """Raise ValueError naming the bad field."""
        P = len(self.vertices)
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3 or not np.all(np.isfinite(self.vertices)):
            raise ValueError("vertices are not (P,3) finite")
        if self.triangles.ndim != 2 or self.triangles.shape[1] != 3 or (
                len(self.triangles) and (self.triangles.min() < 0 or self.triangles.max() >= P)):
            raise ValueError(f"triangles are not (F,3) indices below {P}")
        if self.albedo.shape != (P, 3) or not np.all((self.albedo >= 0) & (self.albedo <= 1)):
            raise ValueError("albedo is not (P,3) in [0, 1]")
        if self.jaw_weights.shape != (P,) or not np.all((self.jaw_weights >= 0) & (self.jaw_weights <= 1)):
            raise ValueError("jaw weights are not (P,) in [0, 1]")
        if len(self.offsets) != len(self.names) + 1 or self.offsets[0] != 0 or self.offsets[-1] != P \
                or np.any(np.diff(self.offsets) < 0):
            raise ValueError(f"offsets do not split the {P} vertices into {len(self.names)} parts")


def concatenate(parts):
    """One InnerParts from a list of (name, vertices (n,3), triangles (f,3), albedo (n,3),
    jaw weights (n,))."""
    verts, tris, alb, jw, names, offsets = [], [], [], [], [], [0]
    for name, v, f, a, w in parts:
        tris.append(np.asarray(f, np.int64) + offsets[-1])
        verts.append(np.asarray(v, float))
        alb.append(np.broadcast_to(np.asarray(a, float), (len(v), 3)))
        jw.append(np.broadcast_to(np.asarray(w, float), (len(v),)))
        names.append(name)
        offsets.append(offsets[-1] + len(v))
    return InnerParts(np.concatenate(verts), np.concatenate(tris), np.clip(np.concatenate(alb), 0, 1),
                      np.clip(np.concatenate(jw), 0, 1), names, np.array(offsets, np.int64))
