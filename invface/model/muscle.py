"""A muscle of the flesh: its tets, fibres, centre line and activation-length curve."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Muscle:
    """One muscle embedded in the flesh mesh.

    tets: (n,) flesh tet ids; fibers: (n,3) unit fibre directions; centerline: (P,3) m,
    from origin (on bone) to insertion (skin/lips), closed rings repeat their first point;
    activation_curve: (Q,2) piecewise-linear map from normalised centre-line length L/L0
    to activation in [0, 1] (paper 000 Eq. 9); side: 'L', 'R' or 'M' (midline).
    """
    name: str
    tets: np.ndarray
    fibers: np.ndarray
    centerline: np.ndarray
    activation_curve: np.ndarray
    side: str = "M"

    @property
    def rest_length(self) -> float:
        """Rest length L0 (m) of the centre-line polyline (Eq. 9 at rest)."""
        return float(np.linalg.norm(np.diff(self.centerline, axis=0), axis=1).sum())

    def activation(self, length):
        """Activation a(L) from the activation-length curve; length in metres."""
        c = self.activation_curve
        return np.interp(np.asarray(length) / self.rest_length, c[:, 0], c[:, 1])
