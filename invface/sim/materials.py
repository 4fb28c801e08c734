"""Flesh and muscle constitutive model (paper 000 Sec. 4; Teran et al. 2003/2005).

Energy density per unit rest volume, as a function of the deformation gradient F:

    Psi(F) = mu10 (I1 - 3) + mu01 (I2 - 3) - (2 mu10 + 4 mu01)(J - 1)     isotropic Mooney-Rivlin
           + kappa/2 (J - 1)^2                                             quasi-incompressibility
           + sigma_max [ psi_p(lam) + a psi_a(lam) ],  lam = |F d|           fibre (Eq. 4)

with I1 = tr C, I2 = (I1^2 - tr C^2)/2, C = F^T F, J = det F, d the unit fibre direction in the
rest configuration and a in [0, 1] the muscle activation. The passive fibre stress is Blemker's
exponential (zero in compression), the active one the Gaussian force-length curve
f_a(lam) = exp(-((lam-1)/w)^2); psi_p, psi_a are their integrals from lam = 1, so the fibre
stress is sigma_max (f_p + a f_a) and the force is linear in a as Eq. 4 states.

The Mooney-Rivlin invariants are used unsplit (not J^-2/3-scaled) and the linear J term cancels
the rest stress: every term is a polynomial in F (the fibre term in |F d|), so energy, stress
and stiffness are defined and smooth through element inversion and degeneracy (J <= 0). This
is the robustness that Irving/Teran's diagonalised stress extrapolation provides, obtained from
the energy itself (as in Smith et al. 2018, "Stable Neo-Hookean flesh"), which keeps force =
-grad energy exact so the Newton line search can use the energy. The definiteness fix of
Teran et al. is the per-element projection of dP/dF onto its non-negative eigenspace
(``project_psd``), used when the exact Newton matrix is not positive definite.

All kernels take whole arrays: F (T,3,3) and return (T,), (T,3,3), (T,9,9) in SI units (Pa).
Index convention for 9-vectors: F[i, j] -> 3 i + j.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np
from scipy.special import erf

_EPS = np.zeros((3, 3, 3))
_EPS[0, 1, 2] = _EPS[1, 2, 0] = _EPS[2, 0, 1] = 1.0
_EPS[0, 2, 1] = _EPS[2, 1, 0] = _EPS[1, 0, 2] = -1.0
_I3 = np.eye(3)


@dataclass(frozen=True)
class Material:
    """Material constants (Pa, dimensionless fibre shape parameters).

    Defaults: soft facial tissue (shear modulus 2 (mu10 + mu01) = 5 kPa, bulk 50x that:
    Poisson ratio ~0.49), muscle peak isometric stress 40 kPa, Blemker passive curve
    (P1 = 0.05, P2 = 6.6), active force-length width 0.5 (force halves at 42 % strain).
    """
    mu10: float = 2000.0
    mu01: float = 500.0
    kappa: float = 250000.0
    sigma_max: float = 40000.0
    passive_p1: float = 0.05
    passive_p2: float = 6.6
    active_width: float = 0.5

    def as_dict(self):
        return asdict(self)


def invariants(F):
    """I1, I2, J (each (T,)) of F (T,3,3)."""
    C = np.einsum("tki,tkj->tij", F, F)
    I1 = np.einsum("tii->t", C)
    I2 = 0.5 * (I1 ** 2 - np.einsum("tij,tji->t", C, C))
    return I1, I2, np.linalg.det(F)


def cofactor(F):
    """Cofactor matrix dJ/dF (T,3,3): its columns are c1 x c2, c2 x c0, c0 x c1 for F's columns c."""
    c = np.transpose(F, (0, 2, 1))
    return np.stack([np.cross(c[:, 1], c[:, 2]), np.cross(c[:, 2], c[:, 0]),
                     np.cross(c[:, 0], c[:, 1])], axis=2)


# non-zero Levi-Civita entries (i, a, m, sign): d2 J / dF_ij dF_ab = eps_iam eps_jbn F_mn
_LC = [(i, a, m, _EPS[i, a, m]) for i in range(3) for a in range(3) for m in range(3) if _EPS[i, a, m]]


def _skew(v):
    """Cross-product matrices [v]x (T,3,3) of vectors v (T,3)."""
    z = np.zeros(len(v))
    return np.stack([np.stack([z, -v[:, 2], v[:, 1]], 1), np.stack([v[:, 2], z, -v[:, 0]], 1),
                     np.stack([-v[:, 1], v[:, 0], z], 1)], 1)


def isotropic(F, m: Material, order=2):
    """Mooney-Rivlin + quasi-incompressibility: psi (T,), P (T,3,3), dP/dF (T,9,9) or None."""
    I1, I2, J = invariants(F)
    c = 2 * m.mu10 + 4 * m.mu01
    psi = m.mu10 * (I1 - 3) + m.mu01 * (I2 - 3) - c * (J - 1) + 0.5 * m.kappa * (J - 1) ** 2
    if order == 0:
        return psi, None, None
    Ft = np.transpose(F, (0, 2, 1))
    C = Ft @ F
    cof = cofactor(F)
    sJ = m.kappa * (J - 1) - c
    P = 2 * m.mu10 * F + m.mu01 * (2 * I1[:, None, None] * F - 2 * (F @ C)) + sJ[:, None, None] * cof
    if order == 1:
        return psi, P, None
    T = len(F)
    B = F @ Ft
    # d2 I2 / dF_ij dF_ab = 2 [2 F_ij F_ab + I1 d_ia d_jb - d_ia C_bj - F_ib F_aj - B_ia d_jb]
    H = 2 * m.mu01 * (2 * F[:, :, :, None, None] * F[:, None, None, :, :]
                      - F[:, :, None, None, :] * Ft[:, None, :, :, None])
    H += m.kappa * cof[:, :, :, None, None] * cof[:, None, None, :, :]
    D = 2 * m.mu01 * (I1[:, None, None] * _I3 - C) + 2 * m.mu10 * _I3
    for i in range(3):
        H[:, i, :, i, :] += D
        H[:, :, i, :, i] -= 2 * m.mu01 * B
    # eps_jbn v_n = -[v]x_jb, so the (i, a) block of the J Hessian is -eps_iak [F_k.]x
    for i, a, k, si in _LC:
        H[:, i, :, a, :] -= si * sJ[:, None, None] * _skew(F[:, k, :])
    return psi, P, H.reshape(T, 9, 9)


def fibre_curves(lam, a, m: Material):
    """Fibre energy per unit volume and its first two derivatives in lam (each like lam)."""
    w, p1, p2, s = m.active_width, m.passive_p1, m.passive_p2, m.sigma_max
    u = lam - 1.0
    g = np.exp(-(u / w) ** 2)
    psi_a = 0.5 * np.sqrt(np.pi) * w * erf(u / w)
    da, dda = g, -2 * u / w ** 2 * g
    e = np.exp(p2 * np.maximum(u, 0.0))
    stretched = u > 0
    psi_p = np.where(stretched, p1 * ((e - 1) / p2 - u), 0.0)
    dp = np.where(stretched, p1 * (e - 1), 0.0)
    ddp = np.where(stretched, p1 * p2 * e, 0.0)
    return s * (psi_p + a * psi_a), s * (dp + a * da), s * (ddp + a * dda)


def fibre(F, d, a, m: Material, order=2):
    """Anisotropic fibre term for fibres d (T,3) (unit, rest frame) at activations a (T,).

    Returns psi (T,), P (T,3,3), dP/dF (T,9,9) (None when not asked for).
    """
    Fd = np.einsum("tij,tj->ti", F, d)
    lam = np.maximum(np.linalg.norm(Fd, axis=1), 1e-12)
    psi, dpsi, ddpsi = fibre_curves(lam, a, m)
    if order == 0:
        return psi, None, None
    g = np.einsum("ti,tj->tij", Fd, d) / lam[:, None, None]       # d lam / dF
    P = dpsi[:, None, None] * g
    if order == 1:
        return psi, P, None
    T = len(F)
    g9 = g.reshape(T, 9)
    # d2 lam / dF2 = (d_ia d_j d_b - g_ij g_ab) / lam
    Hl = (np.einsum("ia,tj,tb->tijab", _I3, d, d).reshape(T, 9, 9)
          - np.einsum("ti,tj->tij", g9, g9)) / lam[:, None, None]
    H = ddpsi[:, None, None] * np.einsum("ti,tj->tij", g9, g9) + dpsi[:, None, None] * Hl
    return psi, P, H


def project_psd(H, floor=0.0):
    """Clamp the eigenvalues of symmetric blocks H (T,n,n) to >= floor (definiteness fix)."""
    w, Q = np.linalg.eigh(H)
    if np.all(w >= floor):
        return H
    return np.einsum("tij,tj,tkj->tik", Q, np.maximum(w, floor), Q)
