"""Muscle tracks (paper 000 Eq. 5) and activation from centre-line length (Eq. 9).

A track is a zero-length spring from a flesh vertex interior to a muscle to its target
position: f = K_m (M_m - I_m X), energy 1/2 sum_v k_v |x_v - t_v|^2.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import InvfaceError


def activation_slopes(muscle, length):
    """One-sided slopes (da/dL on the shortening side, on the lengthening side) (1/m) of the
    activation-length curve at ``length``; they differ only on a break of the curve, such as
    the rest length where a muscle starts to contract (a stretch within 1e-9 of a break, the
    round-off of a rest length recomputed, counts as on it)."""
    c = muscle.activation_curve
    L0 = muscle.rest_length
    s = np.asarray(length, float) / L0
    near = np.abs(c[:, 0] - s[..., None]) < 1e-9
    s = np.where(near.any(-1), c[np.argmax(near, -1), 0], s)
    slopes = np.diff(c[:, 1]) / np.diff(c[:, 0])
    out = []
    for side, inside in (("left", (s > c[0, 0]) & (s <= c[-1, 0])), ("right", (s >= c[0, 0]) & (s < c[-1, 0]))):
        k = np.clip(np.searchsorted(c[:, 0], s, side=side) - 1, 0, len(slopes) - 1)
        out.append(np.where(inside, slopes[k], 0.0) / L0)
    return tuple(out)


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


@dataclass
class TrackState:
    """Eq. 7-9 evaluated for controls (b, j): track targets (n,3), centre-line points (P,3),
    lengths L (M,), activations a (M,), the one-sided slopes da/dL (M,2) (shortening side,
    lengthening side; see activation_slopes), plus the pre-skinning points."""
    targets: np.ndarray
    centerlines: np.ndarray
    lengths: np.ndarray
    activations: np.ndarray
    slopes: np.ndarray
    pre_targets: np.ndarray
    pre_centerlines: np.ndarray


class MuscleTracks:
    """Blendshape-driven muscle tracks (paper 000 Sec. 6, Eq. 7-9) of a FaceModel.

    track_displacements: dX_k (K,N,3) from the Poisson precompute (sim.poisson); free (N,)
    bool, the simulated vertices; stiffness: N/m per track vertex (a number, or one per
    muscle: a vertex in several muscles gets the largest).

    Every free vertex of a muscle's tets carries a zero-length track to
    M_m(b, j) = T^M(j)(M^0 + sum_k M^k b_k) (Eq. 7); the centre-line points, embedded
    barycentrically in the rest tets, follow C_m(b, j) = T^C(j)(C^0 + sum_k C^k b_k) (Eq. 8).
    T^M, T^C are linear blend skinning with the volumetric jaw weights.
    """

    def __init__(self, model, track_displacements, free, stiffness):
        from ..mesh.tets import locate

        X0, tets = model.rest_positions, model.tets
        dX = np.asarray(track_displacements, float)
        muscles = model.muscles
        M = len(muscles)
        k_m = np.broadcast_to(np.asarray(stiffness, float), (M,))
        k = np.zeros(len(X0))
        for i, m in enumerate(muscles):
            v = np.unique(tets[m.tets])
            k[v] = np.maximum(k[v], k_m[i])
        self.vertices = np.flatnonzero((k > 0) & free)
        self.stiffness = k[self.vertices]
        self.rest_targets = X0[self.vertices]
        self.target_deltas = np.ascontiguousarray(dX[:, self.vertices])   # (K,n,3) = M^k
        self.target_weights = model.volume_jaw_weights[self.vertices]
        self.muscles = muscles
        pts = np.concatenate([m.centerline for m in muscles])
        owner = np.repeat(np.arange(M), [len(m.centerline) for m in muscles])
        tet, bary = locate(X0, tets, pts)
        self.rest_centerlines = pts
        self.centerline_deltas = np.einsum("pk,Kpki->Kpi", bary, dX[:, tets[tet]])   # C^k
        self.centerline_weights = np.clip(np.einsum("pk,pk->p", bary, model.volume_jaw_weights[tets[tet]]), 0, 1)
        same = owner[1:] == owner[:-1]
        self.seg = np.flatnonzero(same)                                 # segment i: points i, i+1
        self.seg_owner = owner[:-1][same]
        self.owner = owner
        self.n_muscles = M

    def lengths(self, C):
        """Centre-line lengths (M,) (Eq. 9) and dL/dC (P,3) for points C (P,3)."""
        d = C[self.seg + 1] - C[self.seg]
        n = np.linalg.norm(d, axis=1)
        u = d / np.maximum(n, 1e-15)[:, None]
        dL = np.zeros_like(C)
        np.add.at(dL, self.seg, -u)
        np.add.at(dL, self.seg + 1, u)
        return np.bincount(self.seg_owner, n, minlength=self.n_muscles), dL

    def evaluate(self, b, jaw_matrix):
        """TrackState for blendshape weights b (K,) and the 4x4 jaw transform."""
        from ..model.rig import skin

        b = np.asarray(b, float)
        pre_t = self.rest_targets + np.tensordot(b, self.target_deltas, axes=(0, 0))
        pre_c = self.rest_centerlines + np.tensordot(b, self.centerline_deltas, axes=(0, 0))
        C = skin(pre_c, self.centerline_weights, jaw_matrix)
        L, _ = self.lengths(C)
        a = np.zeros(self.n_muscles)
        da = np.zeros((self.n_muscles, 2))
        for i, m in enumerate(self.muscles):
            a[i], da[i] = m.activation(L[i]), activation_slopes(m, L[i])
        return TrackState(skin(pre_t, self.target_weights, jaw_matrix), C, L, a, da, pre_t, pre_c)

    def springs(self, state):
        """The Tracks (Eq. 5) of a TrackState."""
        return Tracks(self.vertices, state.targets, self.stiffness)

    def activation_jacobian(self, state, jaw_matrix, dM):
        """da/dp (M, K+J) for p = (b, jaw), dM (J,4,4) the jaw-transform derivatives: the
        derivative in the direction of increasing p (where a muscle sits on a break of its
        activation curve, as every muscle at rest does, the slope on the side p moves it to:
        a weight at its lower bound 0 that shortens the muscle activates it)."""
        from ..model.rig import skin_derivatives

        dC = skin_derivatives(state.pre_centerlines, self.centerline_weights, jaw_matrix,
                              self.centerline_deltas, dM)                     # (P_, P, 3)
        _, dL = self.lengths(state.centerlines)
        per_point = np.einsum("qpi,pi->qp", dC, dL)                          # (K+J, P)
        dLdp = np.stack([np.bincount(self.owner, row, minlength=self.n_muscles) for row in per_point], 1)
        return np.where(dLdp < 0, state.slopes[:, :1], state.slopes[:, 1:]) * dLdp

    def target_derivatives(self, state, jaw_matrix, dM):
        """d targets / dp (K+J, n, 3)."""
        from ..model.rig import skin_derivatives

        return skin_derivatives(state.pre_targets, self.target_weights, jaw_matrix, self.target_deltas, dM)

    def target_vjp(self, state, jaw_matrix, dM, g):
        """g . d targets / dp (K+J,) for g (n, 3), without forming the derivatives."""
        from ..model.rig import skin_vjp

        return skin_vjp(state.pre_targets, self.target_weights, jaw_matrix, self.target_deltas, dM, g)
