"""The contact interface: what Newton, the contact-region test and the adjoint ask of a contact.

A contact model adds an energy E_c(X; M) to the simulation's total (paper 000 Eq. 3), a C2
function of the flesh positions X (N,3) m and the jaw transform M (4,4) alone, so the
equilibrium is a function of the controls and its derivatives are that function's. Every
method takes the positions of all N flesh vertices (constrained ones included) and the jaw
transform; a model that does not move with the jaw ignores M.

A new contact model subclasses ``ContactModel``, implements ``energy``, ``gradient`` and
``blocks`` (and ``coupled_pairs`` when it couples two vertices, ``jaw_derivative`` when it
moves with the jaw, ``acting_vertices`` for the contact-region test), and is handed to
``Simulator(model, contacts=[...])``. Nothing else changes: ``tests/plane_contact.py`` is one.
"""
from __future__ import annotations

import numpy as np

from ..materials import project_psd

CONTACT_SMOOTHING = 2e-5     # m: the cubic onset of the contact penalty


def penalty(gap, k, d=CONTACT_SMOOTHING):
    """C2 penalty of gaps (c,) with stiffness k (N/m, scalar or (c,)): energy e (J), de/dgap,
    d2e/dgap2 (each (c,)). With s = max(-gap, 0) the penetration,

        e(s) = 0 (s <= 0),  k s^3 / (6 d) (0 < s < d),  k/2 s^2 - k d/2 s + k d^2/6 (s >= d)

    a cubic onset over ``d`` joined C2 to a quadratic."""
    s = np.maximum(-gap, 0.0)
    cubic = s < d
    e = np.where(cubic, k * s ** 3 / (6 * d), k * (0.5 * s ** 2 - 0.5 * d * s + d * d / 6))
    de = -np.where(cubic, k * s ** 2 / (2 * d), k * (s - 0.5 * d))
    dde = np.where(cubic, k * s / d, k)
    return e, de, dde


def vertex_blocks(v, H):
    """Hessian blocks [(pairs (c,2), H (c,3,3))] of per-vertex terms at vertices v (c,)."""
    return [(np.stack([v, v], 1), H)]


class ContactModel:
    """One kind of contact. ``n_vertices``: the flesh vertex count N."""

    n_vertices: int = 0

    def __len__(self):
        """The number of contacts (pairs or vertices) the model holds."""
        return 0

    def energy(self, X, M):
        """Contact energy (J) at flesh positions X (N,3) m, jaw transform M (4,4)."""
        raise NotImplementedError

    def gradient(self, X, M):
        """Energy gradient (N,3) J/m: minus the contact forces (N)."""
        raise NotImplementedError

    def blocks(self, X, M, project=False):
        """Hessian blocks [(pairs (P,2) flesh vertex ids, B (P,3,3))] of the energy, summed by
        the Newton matrix's assembly; with ``project`` each contact's own Hessian projected to
        positive semi-definite (Newton's fallback ladder)."""
        raise NotImplementedError

    def projection_blocks(self, X, M):
        """Blocks that, added to the exact ``blocks``, give the projected ones: project_psd(H)
        - H per contact. The default assembles both: the projected blocks and the exact ones
        negated."""
        return self.blocks(X, M, project=True) + [(p, -B) for p, B in self.blocks(X, M)]

    def coupled_pairs(self):
        """Flesh vertex pairs (P,2) that the model's Hessian blocks may ever couple, beyond a
        vertex with itself (the sparsity pattern is built once from them)."""
        return np.zeros((0, 2), np.int64)

    def acting_vertices(self, X, M):
        """The flesh vertices (sorted ids) of the contacts acting at X, M: the contact-region
        test grows its region from them, and reports count them."""
        return np.zeros(0, np.int64)

    def jaw_derivative(self, X, M, dM):
        """d(energy gradient)/d(jaw parameter) (P,N,3) for jaw-transform derivatives dM
        (P,4,4), X held: the adjoint's term for contacts that move with the jaw (zero for the
        others)."""
        return np.zeros((len(dM), self.n_vertices, 3))


class ContactSet(ContactModel):
    """The sum of a list of contact models: what ``Simulator`` holds and Newton and the adjoint
    ask. ``of(cls)`` finds a member by its class."""

    def __init__(self, models, n_vertices):
        self.models = list(models)
        self.n_vertices = int(n_vertices)
        for m in self.models:
            if not isinstance(m, ContactModel):
                raise TypeError(f"{m!r} is not a ContactModel (sim.contact.base)")
            if m.n_vertices != self.n_vertices:
                raise ValueError(f"{type(m).__name__} was made for {m.n_vertices} flesh vertices, "
                                 f"the simulation has {self.n_vertices}")

    def __len__(self):
        return sum(len(m) for m in self.models)

    def __iter__(self):
        return iter(self.models)

    def of(self, cls):
        """The first member that is a ``cls``, or None."""
        return next((m for m in self.models if isinstance(m, cls)), None)

    def energy(self, X, M):
        return float(sum(m.energy(X, M) for m in self.models))

    def gradient(self, X, M):
        out = np.zeros((self.n_vertices, 3))
        for m in self.models:
            out += m.gradient(X, M)
        return out

    def blocks(self, X, M, project=False):
        return [b for m in self.models for b in m.blocks(X, M, project)]

    def projection_blocks(self, X, M):
        return [b for m in self.models for b in m.projection_blocks(X, M)]

    def coupled_pairs(self):
        pairs = [m.coupled_pairs() for m in self.models]
        return np.concatenate(pairs) if pairs else np.zeros((0, 2), np.int64)

    def acting_vertices(self, X, M):
        ids = [m.acting_vertices(X, M) for m in self.models]
        return np.unique(np.concatenate(ids)) if ids else np.zeros(0, np.int64)

    def jaw_derivative(self, X, M, dM):
        out = np.zeros((len(dM), self.n_vertices, 3))
        for m in self.models:
            out += m.jaw_derivative(X, M, dM)
        return out


def psd(H):
    """Each block of H (c,n,n) projected to positive semi-definite (empty stays empty)."""
    return project_psd(H) if len(H) else H
