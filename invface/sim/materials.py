"""Flesh and muscle constitutive model (paper 000 Sec. 4; Teran et al. 2003/2005).

Energy density per unit rest volume, as a function of the deformation gradient F:

    Psi(F) = mu10 (I1 - 3) + mu01 (I2 - 3) - (2 mu10 + 4 mu01)(J - 1)     isotropic Mooney-Rivlin
           + kappa/2 (J - 1)^2 + k_b b(J)                                  quasi-incompressibility
           + sigma_max [ psi_p(lam) + a psi_a(lam) ],  lam = |F d|           fibre (Eq. 4)

with I1 = tr C, I2 = (I1^2 - tr C^2)/2, C = F^T F, J = det F, d the unit fibre direction in the
rest configuration and a in [0, 1] the muscle activation. The passive fibre stress is Blemker's
exponential (zero in compression), the active one the Gaussian force-length curve
f_a(lam) = exp(-((lam-1)/w)^2); psi_p, psi_a are their integrals from lam = 1, so the fibre
stress is sigma_max (f_p + a f_a) and the force is linear in a as Eq. 4 states.

The Mooney-Rivlin invariants are used unsplit (not J^-2/3-scaled) and the linear J term cancels
the rest stress: every term but the barrier is a polynomial in F (the fibre term in |F d|), so
stress and stiffness are smooth through strong compression, and force = -grad energy exactly,
so the Newton line search can use the energy. The polynomial volume term alone is finite
through inversion (as in Smith et al. 2018, "Stable Neo-Hookean flesh"), and on the default
head a 0.45 rad jaw opening then drove Newton into a state where one lip tet had flattened
(J = 7e-9) and no step could lower the energy without inverting it. The barrier b(J) (zero
for J >= ``barrier_start``, infinite at J = 0) makes every energy minimum inversion-free:
the energy of an inverted element is +inf, which the line search rejects. The definiteness fix of
Teran et al. (2005) clamps the negative eigenvalues of dP/dF to zero; it is used when the exact
Newton matrix is not positive definite. Each term is clamped through its closed-form
eigensystem (``iso_projected``, ``fibre_projected``; no 9x9 eigensolver), and the sum of the
clamped terms is positive semi-definite.

The per-element kernels are numba functions (``iso_element``, ``fibre_element`` and their
projected forms) that the fused FVM kernel in ``fem.py`` calls for every tet in parallel;
``isotropic`` and ``fibre`` apply them to whole arrays: F (T,3,3) -> (T,), (T,3,3), (T,9,9) in
SI units (Pa). Index convention for 9-vectors: F[i, j] -> 3 i + j. ``project_psd`` clamps
general symmetric blocks with an eigensolver (the contacts' 12x12 Hessians).
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass

import numba as nb
import numpy as np

JIT = dict(cache=True, nogil=True, fastmath=False)


@dataclass(frozen=True)
class Material:
    """Material constants (Pa, dimensionless fibre shape parameters).

    Defaults: soft facial tissue (shear modulus 2 (mu10 + mu01) = 5 kPa, bulk 50x that:
    Poisson ratio ~0.49), muscle peak isometric stress 40 kPa, Blemker passive curve
    (P1 = 0.05, P2 = 6.6), active force-length width 0.5 (force halves at 42 % strain),
    volume barrier from J = 0.2 with the bulk modulus as its stiffness (``volume_barrier``).
    """
    mu10: float = 2000.0
    mu01: float = 500.0
    kappa: float = 250000.0
    sigma_max: float = 40000.0
    passive_p1: float = 0.05
    passive_p2: float = 6.6
    active_width: float = 0.5
    barrier_start: float = 0.2
    barrier_stiffness: float = 250000.0

    def as_dict(self):
        return asdict(self)

    @property
    def shear_modulus(self):
        """Small-strain shear modulus 2 (mu10 + mu01) (Pa)."""
        return 2 * (self.mu10 + self.mu01)

    def params(self):
        """The constants as the float64 array (7,) the kernels take, in field order."""
        return np.array([self.mu10, self.mu01, self.kappa, self.sigma_max,
                         self.passive_p1, self.passive_p2, self.active_width,
                         self.barrier_start, self.barrier_stiffness])


@nb.njit(**JIT)
def volume_barrier(J, J0, k):
    """Inversion barrier k b(J), b = -(J - J0)^2 log(J / J0) for 0 < J < J0, else 0 (the
    C2 barrier of IPC, Li et al. 2020, applied to the volume ratio): its value and first two
    derivatives in J. It leaves every state with J >= J0 unchanged and makes the energy grow
    without bound as a tet flattens, so an energy minimum has no inverted tet."""
    if J >= J0:
        return 0.0, 0.0, 0.0
    u, lg = J - J0, math.log(J / J0)
    return (-k * u * u * lg, -k * (2 * u * lg + u * u / J),
            -k * (2 * lg + 4 * u / J - u * u / (J * J)))


@nb.njit(**JIT)
def _eps(i, j, k):
    """Levi-Civita symbol."""
    return (i - j) * (j - k) * (k - i) / 2


@nb.njit(**JIT)
def _mul(A, B, ta, tb):
    """3x3 product op(A) op(B), op the transpose where ta / tb (no BLAS call per element)."""
    out = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            acc = 0.0
            for k in range(3):
                acc += (A[k, i] if ta else A[i, k]) * (B[j, k] if tb else B[k, j])
            out[i, j] = acc
    return out


@nb.njit(**JIT)
def iso_element(F, prm, order, P, H):
    """Mooney-Rivlin + quasi-incompressibility of one element. F (3,3); prm Material.params().

    Returns psi; adds the stress to P (3,3) when order >= 1 and dP/dF to H (9,9) when order 2.
    """
    mu10, mu01, kappa = prm[0], prm[1], prm[2]
    C = _mul(F, F, True, False)
    I1 = C[0, 0] + C[1, 1] + C[2, 2]
    I2 = 0.5 * (I1 * I1 - np.sum(C * C))
    cof = np.empty((3, 3))
    for j in range(3):                     # columns of cof: c1 x c2, c2 x c0, c0 x c1
        j1, j2 = (j + 1) % 3, (j + 2) % 3
        cof[0, j] = F[1, j1] * F[2, j2] - F[2, j1] * F[1, j2]
        cof[1, j] = F[2, j1] * F[0, j2] - F[0, j1] * F[2, j2]
        cof[2, j] = F[0, j1] * F[1, j2] - F[1, j1] * F[0, j2]
    J = F[0, 0] * cof[0, 0] + F[1, 0] * cof[1, 0] + F[2, 0] * cof[2, 0]
    if J <= 0.0:
        return np.inf                      # outside the barrier's domain (see volume_barrier)
    c = 2 * mu10 + 4 * mu01
    b0, b1, b2 = volume_barrier(J, prm[7], prm[8])
    psi = mu10 * (I1 - 3) + mu01 * (I2 - 3) - c * (J - 1) + 0.5 * kappa * (J - 1) ** 2 + b0
    if order == 0:
        return psi
    sJ = kappa * (J - 1) - c + b1
    sJJ = kappa + b2
    FC = _mul(F, C, False, False)
    for i in range(3):
        for j in range(3):
            P[i, j] += 2 * mu10 * F[i, j] + mu01 * (2 * I1 * F[i, j] - 2 * FC[i, j]) + sJ * cof[i, j]
    if order == 1:
        return psi
    B = _mul(F, F, False, True)
    # d2 I2 / dF_ij dF_ab = 2 [2 F_ij F_ab + I1 d_ia d_jb - d_ia C_bj - F_ib F_aj - B_ia d_jb];
    # d2 J / dF_ij dF_ab = eps_iak eps_jbn F_kn
    for i in range(3):
        for j in range(3):
            for a in range(3):
                for b in range(3):
                    h = 2 * mu01 * (2 * F[i, j] * F[a, b] - F[i, b] * F[a, j]) + sJJ * cof[i, j] * cof[a, b]
                    if i == a:
                        h += 2 * mu01 * (I1 * (j == b) - C[j, b]) + 2 * mu10 * (j == b)
                    if j == b:
                        h -= 2 * mu01 * B[i, a]
                    if i != a and j != b:
                        k, n = 3 - i - a, 3 - j - b
                        h += sJ * _eps(i, a, k) * _eps(j, b, n) * F[k, n]
                    H[3 * i + j, 3 * a + b] += h
    return psi


@nb.njit(**JIT)
def fibre_curves(lam, a, prm):
    """Fibre energy per unit volume and its first two derivatives in the stretch lam."""
    s, p1, p2, w = prm[3], prm[4], prm[5], prm[6]
    u = lam - 1.0
    g = math.exp(-(u / w) ** 2)
    psi = a * 0.5 * math.sqrt(math.pi) * w * math.erf(u / w)
    d1, d2 = a * g, -a * 2 * u / w ** 2 * g
    if u > 0:
        e = math.exp(p2 * u)
        psi += p1 * ((e - 1) / p2 - u)
        d1 += p1 * (e - 1)
        d2 += p1 * p2 * e
    return s * psi, s * d1, s * d2


@nb.njit(**JIT)
def _fibre_stretch(F, d):
    """The fibre's stretch lam = |F d| (floored at 1e-12) and d lam / dF (9,) = (F d) d^T / lam."""
    Fd = np.array([F[0, 0] * d[0] + F[0, 1] * d[1] + F[0, 2] * d[2], F[1, 0] * d[0] + F[1, 1] * d[1] + F[1, 2] * d[2],
                   F[2, 0] * d[0] + F[2, 1] * d[1] + F[2, 2] * d[2]])
    lam = max(math.sqrt(Fd[0] ** 2 + Fd[1] ** 2 + Fd[2] ** 2), 1e-12)
    g = np.empty(9)
    for i in range(3):
        for j in range(3):
            g[3 * i + j] = Fd[i] * d[j] / lam
    return lam, g


@nb.njit(**JIT)
def fibre_element(F, d, a, prm, order, P, H):
    """Fibre term of one element for the unit rest fibre d (3,) at activation a (Eq. 4).

    Returns psi; adds the stress to P and dP/dF to H as ``iso_element``.
    """
    lam, g = _fibre_stretch(F, d)
    psi, dpsi, ddpsi = fibre_curves(lam, a, prm)
    if order == 0:
        return psi
    for i in range(3):
        for j in range(3):
            P[i, j] += dpsi * g[3 * i + j]
    if order == 1:
        return psi
    _fibre_hessian(g, d, lam, ddpsi, dpsi, H)
    return psi


@nb.njit(**JIT)
def _fibre_hessian(g, d, lam, c_g, c_t, H):
    """Adds c_g g g^T + c_t d2 lam / dF2 to H (9,9): the fibre term's dP/dF is this with
    c_g = psi'' and c_t = psi'. d2 lam / dF2 = (d_ia d_j d_b - g_ij g_ab) / lam, so g (unit) is an
    eigenvector with eigenvalue c_g, the two directions u d^T with u orthogonal to F d have
    c_t / lam, and the other six 0."""
    for i in range(3):
        for j in range(3):
            for a_ in range(3):
                for b in range(3):
                    p, q = 3 * i + j, 3 * a_ + b
                    hl = ((i == a_) * d[j] * d[b] - g[p] * g[q]) / lam
                    H[p, q] += c_g * g[p] * g[q] + c_t * hl


@nb.njit(**JIT)
def fibre_projected(F, d, a, prm, H):
    """Adds the fibre term's dP/dF with its negative eigenvalues clamped to 0 to H (9,9), from
    the eigensystem in ``_fibre_hessian``: psi'' -> max(psi'', 0), psi' / lam -> max(psi', 0) / lam."""
    lam, g = _fibre_stretch(F, d)
    _, dpsi, ddpsi = fibre_curves(lam, a, prm)
    _fibre_hessian(g, d, lam, max(ddpsi, 0.0), max(dpsi, 0.0), H)


@nb.njit(**JIT)
def sym3_eigen(A, V):
    """Eigen-decomposition of a symmetric 3x3 matrix by cyclic Jacobi rotations: on return A is
    diagonal (the eigenvalues) and V (3,3) holds the unit eigenvectors as columns (a product of
    rotations). No LAPACK call and no allocation: numba's 3x3 LAPACK calls cost more than the
    rest of the element kernel."""
    for i in range(3):
        for j in range(3):
            V[i, j] = 1.0 if i == j else 0.0
    for _ in range(50):
        off = A[0, 1] ** 2 + A[0, 2] ** 2 + A[1, 2] ** 2
        if off <= 1e-32 * (A[0, 0] ** 2 + A[1, 1] ** 2 + A[2, 2] ** 2 + off) or off == 0.0:
            return
        for p, q in ((0, 1), (0, 2), (1, 2)):
            if A[p, q] == 0.0:
                continue
            theta = (A[q, q] - A[p, p]) / (2 * A[p, q])
            t = (1.0 if theta >= 0 else -1.0) / (abs(theta) + math.sqrt(theta * theta + 1))
            c = 1 / math.sqrt(t * t + 1)
            sn = t * c
            for k in range(3):                  # A <- A R, then A <- R^T A, V <- V R
                akp, akq = A[k, p], A[k, q]
                A[k, p], A[k, q] = c * akp - sn * akq, sn * akp + c * akq
            for k in range(3):
                apk, aqk = A[p, k], A[q, k]
                A[p, k], A[q, k] = c * apk - sn * aqk, sn * apk + c * aqk
            for k in range(3):
                vkp, vkq = V[k, p], V[k, q]
                V[k, p], V[k, q] = c * vkp - sn * vkq, sn * vkp + c * vkq


@nb.njit(**JIT)
def rotation_svd(F, U, s, V):
    """F (3,3) = U diag(s) V^T with U, V rotations and s sorted descending, s[2] < 0 when
    det F < 0: V from the eigenvectors of F^T F (``sym3_eigen``), u_k = F v_k / s_k for the two
    largest, u_2 = u_0 x u_1 (so a tiny s_2 costs no accuracy), s_2 = u_2 . F v_2."""
    C, W, Fv = np.empty((3, 3)), np.empty((3, 3)), np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            C[i, j] = F[0, i] * F[0, j] + F[1, i] * F[1, j] + F[2, i] * F[2, j]
    sym3_eigen(C, W)
    o0, o1, o2 = 0, 1, 2                        # eigenvalues in descending order
    if C[o0, o0] < C[o1, o1]:
        o0, o1 = o1, o0
    if C[o1, o1] < C[o2, o2]:
        o1, o2 = o2, o1
    if C[o0, o0] < C[o1, o1]:
        o0, o1 = o1, o0
    for i in range(3):
        V[i, 0], V[i, 1], V[i, 2] = W[i, o0], W[i, o1], W[i, o2]
    if V[0, 0] * (V[1, 1] * V[2, 2] - V[2, 1] * V[1, 2]) - V[0, 1] * (V[1, 0] * V[2, 2] - V[2, 0] * V[1, 2]) \
            + V[0, 2] * (V[1, 0] * V[2, 1] - V[2, 0] * V[1, 1]) < 0:
        for i in range(3):
            V[i, 2] = -V[i, 2]
    for i in range(3):
        for k in range(3):
            Fv[i, k] = F[i, 0] * V[0, k] + F[i, 1] * V[1, k] + F[i, 2] * V[2, k]
    for k in range(2):
        if k == 1:                              # u_1 orthogonal to u_0 (Gram-Schmidt)
            d = Fv[0, 1] * U[0, 0] + Fv[1, 1] * U[1, 0] + Fv[2, 1] * U[2, 0]
            for i in range(3):
                Fv[i, 1] -= d * U[i, 0]
        n = math.sqrt(Fv[0, k] ** 2 + Fv[1, k] ** 2 + Fv[2, k] ** 2)
        s[k] = n
        for i in range(3):
            U[i, k] = Fv[i, k] / n if n > 0 else (1.0 if i == k else 0.0)
    U[0, 2] = U[1, 0] * U[2, 1] - U[2, 0] * U[1, 1]
    U[1, 2] = U[2, 0] * U[0, 1] - U[0, 0] * U[2, 1]
    U[2, 2] = U[0, 0] * U[1, 1] - U[1, 0] * U[0, 1]
    s[2] = U[0, 2] * Fv[0, 2] + U[1, 2] * Fv[1, 2] + U[2, 2] * Fv[2, 2]


@nb.njit(**JIT)
def iso_projected(F, prm, floor, H):
    """Adds the isotropic term's dP/dF with eigenvalues clamped to >= floor to H (9,9), from its
    closed-form eigensystem (Teran et al. 2005, Smith et al. 2019), no 9x9 eigensolver.

    With F = U diag(s) V^T, Psi is a function of s alone: Psi = mu10 sum s_i^2 + mu01 sum_{i<j}
    s_i^2 s_j^2 + f(J), J = s0 s1 s2, f the volume terms. dP/dF splits into
    - three scaling modes U diag(w) V^T, w the eigenvectors of the 3x3 Hessian in s:
      d2/ds_i2 = 2 mu10 + 2 mu01 (s_j^2 + s_k^2) + f'' s_j^2 s_k^2,
      d2/ds_i ds_j = 4 mu01 s_i s_j + f'' s_i s_j s_k^2 + f' s_k;
    - per pair (i, j), k the third: the twist (u_i v_j^T - u_j v_i^T)/sqrt 2 with eigenvalue
      (dPsi_i + dPsi_j)/(s_i + s_j) = 2 mu10 + 2 mu01 (s_k^2 + s_i s_j) + f' s_k, and the flip
      (u_i v_j^T + u_j v_i^T)/sqrt 2 with (dPsi_i - dPsi_j)/(s_i - s_j) = 2 mu10 + 2 mu01 (s_k^2
      - s_i s_j) - f' s_k: divided differences taken in closed form, so equal s_i cost nothing.
    floor = -inf rebuilds the exact dP/dF. F must have det F > 0 (else H is left unchanged).
    """
    mu10, mu01, kappa = prm[0], prm[1], prm[2]
    U, V, s = np.empty((3, 3)), np.empty((3, 3)), np.empty(3)
    rotation_svd(F, U, s, V)
    J = s[0] * s[1] * s[2]
    if not J > 0.0:
        return
    _, b1, b2 = volume_barrier(J, prm[7], prm[8])
    f1 = kappa * (J - 1) - (2 * mu10 + 4 * mu01) + b1
    f2 = kappa + b2
    A = np.empty((3, 3))
    for i in range(3):
        j, k = (i + 1) % 3, (i + 2) % 3
        A[i, i] = 2 * mu10 + 2 * mu01 * (s[j] ** 2 + s[k] ** 2) + f2 * (s[j] * s[k]) ** 2
        A[i, j] = A[j, i] = 4 * mu01 * s[i] * s[j] + f2 * s[i] * s[j] * s[k] ** 2 + f1 * s[k]
    W = np.empty((3, 3))
    sym3_eigen(A, W)
    lam = np.empty(9)
    Q = np.zeros((9, 9))                    # columns: unit eigenvectors as 9-vectors F[i, j] -> 3 i + j
    r2 = 1 / math.sqrt(2.0)
    for m in range(3):
        lam[m] = A[m, m]
        for i in range(3):
            for j in range(3):
                Q[3 * i + j, m] = U[i, 0] * W[0, m] * V[j, 0] + U[i, 1] * W[1, m] * V[j, 1] + U[i, 2] * W[2, m] * V[j, 2]
    for k in range(3):
        i, j = (k + 1) % 3, (k + 2) % 3
        common = 2 * mu10 + 2 * mu01 * s[k] ** 2
        lam[3 + k] = common + 2 * mu01 * s[i] * s[j] + f1 * s[k]       # twist
        lam[6 + k] = common - 2 * mu01 * s[i] * s[j] - f1 * s[k]       # flip
        for a in range(3):
            for b in range(3):
                x, y = U[a, i] * V[b, j], U[a, j] * V[b, i]
                Q[3 * a + b, 3 + k] = r2 * (x - y)
                Q[3 * a + b, 6 + k] = r2 * (x + y)
    for m in range(9):
        c = max(lam[m], floor)
        if c == 0.0:
            continue
        for p in range(9):
            cq = c * Q[p, m]
            for q in range(9):
                H[p, q] += cq * Q[q, m]


@nb.njit(**JIT)
def is_positive_definite(H, shift):
    """Cholesky test of H + shift I for a small symmetric matrix H (n,n)."""
    n = H.shape[0]
    L = np.zeros((n, n))
    for j in range(n):
        s = H[j, j] + shift
        for k in range(j):
            s -= L[j, k] * L[j, k]
        if not s > 0:
            return False
        L[j, j] = math.sqrt(s)
        for i in range(j + 1, n):
            s = H[i, j]
            for k in range(j):
                s -= L[i, k] * L[j, k]
            L[i, j] = s / L[j, j]
    return True


@nb.njit(**JIT)
def project_element(H, floor):
    """Clamp the eigenvalues of the symmetric block H (n,n) to >= floor, in place (eigensolver;
    the contacts' 12x12 blocks, which have no closed form here)."""
    if floor == 0.0 and is_positive_definite(H, 1e-10 * np.abs(H).max()):
        return     # eigenvalues >= -1e-10 |H|: clamping changes nothing that matters; no eigh
    w, Q = np.linalg.eigh(H)
    if w.min() >= floor:
        return
    for k in range(len(w)):
        w[k] = max(w[k], floor)
    H[:, :] = (Q * w) @ Q.T


@nb.njit(parallel=True, **JIT)
def _project_batch(H, floor):
    for t in nb.prange(H.shape[0]):
        project_element(H[t], floor)


def project_psd(H, floor=0.0):
    """Copy of symmetric blocks H (T,n,n) with eigenvalues clamped to >= floor."""
    H = np.array(H, float)
    _project_batch(H, floor)
    return H


@nb.njit(parallel=True, **JIT)
def _batch(F, d, a, prm, order, fibre, project):
    T = F.shape[0]
    psi = np.empty(T)
    P = np.zeros((T, 3, 3))
    H = np.zeros((T, 9, 9))
    for t in nb.prange(T):
        if fibre:
            psi[t] = fibre_element(F[t], d[t], a[t], prm, min(order, 1) if project else order, P[t], H[t])
            if project and order == 2:
                fibre_projected(F[t], d[t], a[t], prm, H[t])
        else:
            psi[t] = iso_element(F[t], prm, min(order, 1) if project else order, P[t], H[t])
            if project and order == 2:
                iso_projected(F[t], prm, 0.0, H[t])
    return psi, P, H


def _out(psi, P, H, order):
    return psi, (P if order >= 1 else None), (H if order == 2 else None)


def isotropic(F, m: Material, order=2, project=False):
    """Mooney-Rivlin + quasi-incompressibility: psi (T,), P (T,3,3), dP/dF (T,9,9) or None;
    ``project``: dP/dF with its negative eigenvalues clamped to 0 (``iso_projected``)."""
    F = np.ascontiguousarray(F, float)
    z = np.zeros((len(F), 3))
    return _out(*_batch(F, z, z[:, 0], m.params(), order, False, project), order)


def fibre(F, d, a, m: Material, order=2, project=False):
    """Fibre term for fibres d (T,3) (unit, rest frame) at activations a (T,): psi, P, dP/dF
    (``project``: clamped as ``fibre_projected``)."""
    F = np.ascontiguousarray(F, float)
    return _out(*_batch(F, np.ascontiguousarray(d, float), np.ascontiguousarray(a, float),
                        m.params(), order, True, project), order)
