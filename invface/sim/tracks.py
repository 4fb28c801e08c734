"""Muscle tracks (paper 000 Eq. 5) and activation from centre-line length (Eq. 9).

A track is a zero-length spring from a flesh vertex interior to a muscle to its target
position: f = K_m (M_m - I_m X), energy 1/2 sum_v k_v |x_v - t_v|^2.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InvfaceError


def centerline_length(C):
    """Polyline length L (Eq. 9) of centre-lines C (..., P, 3) in metres, and dL/dC (..., P, 3)."""
    C = np.asarray(C, float)
    seg = np.diff(C, axis=-2)
    n = np.linalg.norm(seg, axis=-1, keepdims=True)
    u = seg / np.maximum(n, 1e-15)
    dL = np.zeros_like(C)
    dL[..., :-1, :] -= u
    dL[..., 1:, :] += u
    return n[..., 0].sum(-1), dL


def activation_from_length(muscle, length):
    """Activation a_m(L) and its slope da/dL (1/m) from the muscle's activation-length curve."""
    c = muscle.activation_curve
    L0 = muscle.rest_length
    s = np.asarray(length, float) / L0
    a = np.interp(s, c[:, 0], c[:, 1])
    slopes = np.diff(c[:, 1]) / np.diff(c[:, 0])
    k = np.clip(np.searchsorted(c[:, 0], s, side="right") - 1, 0, len(slopes) - 1)
    inside = (s > c[0, 0]) & (s < c[-1, 0])
    return a, np.where(inside, slopes[k], 0.0) / L0


@dataclass
class Tracks:
    """Zero-length springs: vertices (n,) flesh ids, targets (n,3) m, stiffness (n,) N/m."""
    vertices: np.ndarray
    targets: np.ndarray
    stiffness: np.ndarray

    def __post_init__(self):
        self.vertices = np.asarray(self.vertices, np.int64)
        self.targets = np.asarray(self.targets, float).reshape(-1, 3)
        self.stiffness = np.broadcast_to(np.asarray(self.stiffness, float), self.vertices.shape).copy()
        if not (len(self.vertices) == len(self.targets)):
            raise InvfaceError(f"tracks: {len(self.vertices)} vertices but {len(self.targets)} targets")
        if not np.all(np.isfinite(self.targets)) or not np.all(np.isfinite(self.stiffness)):
            raise InvfaceError("tracks: targets and stiffness must be finite")
        if np.any(self.stiffness < 0):
            raise InvfaceError("tracks: stiffness must be >= 0")

    def energy(self, X):
        d = X[self.vertices] - self.targets
        return 0.5 * float(np.einsum("v,vi,vi->", self.stiffness, d, d))

    def gradient(self, X):
        """Per-track gradient (n,3) (= minus the Eq. 5 force)."""
        return self.stiffness[:, None] * (X[self.vertices] - self.targets)

    def blocks(self):
        """Diagonal Hessian blocks: (pairs (n,2), B (n,3,3))."""
        return (np.stack([self.vertices, self.vertices], 1),
                self.stiffness[:, None, None] * np.eye(3))
