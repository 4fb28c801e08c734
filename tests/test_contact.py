"""The contact interface (sim.contact): a contact model written in its own file (the jaw-carried
plate of tests/plane_contact.py) plugs into Simulator and the adjoint with no edit elsewhere:
Newton solves with it, alone and beside the face's own contacts, and the adjoint of a surface
loss matches finite differences of cold solves, jaw controls included (the plate moves with
the jaw, so its jaw term is in the adjoint)."""
import numpy as np
import pytest
from plane_contact import JawPlate, chin_plate

from invface.sim.contact import ContactModel, ContactSet, EyeballContacts, TriangleContacts
from invface.sim.driven import DrivenSimulation
from invface.sim.quasistatic import Simulator


def _fd_blocks(c, X, M, dX, h=1e-8):
    """(finite-difference directional derivative of the gradient, Hessian blocks times dX)."""
    dg = (c.gradient(X + h * dX, M) - c.gradient(X - h * dX, M)) / (2 * h)
    Hd = np.zeros_like(X)
    for pairs, B in c.blocks(X, M):
        np.add.at(Hd, pairs[:, 0], np.einsum("pij,pj->pi", B, dX[pairs[:, 1]]))
    return dg, Hd


def test_the_plate_is_a_contact_model_with_consistent_derivatives(small_expressive_model):
    m = small_expressive_model
    plate = chin_plate(m)
    assert isinstance(plate, ContactModel) and len(plate) > 5
    jaw = np.array([0.05, 0.01, -0.01, 0.0004, -0.0003, 0.0002])
    M = m.jaw_matrix(jaw)
    rng = np.random.default_rng(0)
    X = m.rest_positions + 2e-4 * rng.standard_normal(m.rest_positions.shape)
    assert len(plate.acting_vertices(X, M)) > 0
    dX = rng.standard_normal(X.shape)
    h = 1e-8
    fd = (plate.energy(X + h * dX, M) - plate.energy(X - h * dX, M)) / (2 * h)
    assert np.isclose(fd, np.sum(plate.gradient(X, M) * dX), rtol=1e-6)
    dg, Hd = _fd_blocks(plate, X, M, dX)
    assert np.linalg.norm(dg - Hd) <= 1e-6 * np.linalg.norm(dg)
    from invface.model.rig import jaw_transform_derivatives
    dM = jaw_transform_derivatives(jaw, m.jaw_pivot, m.jaw_frame)
    J = plate.jaw_derivative(X, M, dM)
    for i, hj in enumerate([1e-6] * 3 + [1e-7] * 3):
        e = np.zeros(6)
        e[i] = hj
        fdj = (plate.gradient(X, m.jaw_matrix(jaw + e)) - plate.gradient(X, m.jaw_matrix(jaw - e))) / (2 * hj)
        assert np.linalg.norm(fdj - J[i]) <= 1e-5 * np.linalg.norm(fdj), i


def test_simulator_takes_a_list_of_contact_models(small_expressive_model):
    m = small_expressive_model
    plate = chin_plate(m)
    alone = Simulator(m, contact=False, contacts=[plate])
    assert alone.contacts.models == [plate]
    r = alone.solve()
    assert r.converged
    gap = lambda X: (X[plate.v] - plate.p0) @ plate.n0
    assert gap(m.rest_positions).min() < -9e-4          # the plate starts 1 mm into the chin...
    assert gap(r.X).min() > 0.5 * gap(m.rest_positions).min()     # ...and pushes it back
    both = Simulator(m, contacts=[plate])
    assert [type(c) for c in both.contacts] == [TriangleContacts, EyeballContacts, JawPlate]
    assert both.contacts.of(JawPlate) is plate
    r = both.solve({"orbicularis_oris_inferior_L": 0.5, "orbicularis_oris_inferior_R": 0.5}
                   if "orbicularis_oris_inferior_L" in both.muscle_names else None, jaw=[0.1, 0, 0, 0, 0, 0])
    assert r.converged and gap(r.X).min() > 0.5 * gap(m.rest_positions).min()   # at least halved
    assert Simulator(m, contact=False).contacts is None
    with pytest.raises(TypeError, match="not a ContactModel"):
        ContactSet([object()], len(m.rest_positions))


def test_adjoint_through_the_plate_matches_cold_finite_differences(small_expressive_model):
    """L(p) = sum(g * surface(p)) with only the plate as contact: the adjoint gradient against
    central differences of solves from rest, for a smile, a pucker and three jaw DOF (the plate
    rides the jaw: ``JawPlate.jaw_derivative`` is in the adjoint)."""
    m = small_expressive_model
    ds = DrivenSimulation(m, contact=False, contacts=[chin_plate(m, depth=2e-3)])
    p = m.parameters({"weights": {"mouthSmileLeft": 0.4, "mouthPucker": 0.3},
                      "jaw": [0.05, 0.01, -0.01, 0.0004, -0.0003, 0.0002]})
    r = ds.solve(p, warm=None, rtol=1e-10)
    plate = ds.sim.contacts.of(JawPlate)
    assert len(plate.acting_vertices(r.X, m.jaw_matrix(ds.split(p)[1]))) >= 3
    gx = np.random.default_rng(3).standard_normal(m.neutral.shape)
    g = ds.surface_vjp(p, gx)
    L = lambda q: np.sum(gx * ds.surface_of(ds.solve(q, warm=None, rtol=1e-10)))
    names = ds.parameter_names
    for name, h in [("mouthSmileLeft", 1e-4), ("mouthPucker", 1e-4), ("jaw_rx", 1e-5), ("jaw_ry", 1e-5),
                    ("jaw_tz", 1e-6)]:
        i = names.index(name)
        e = np.zeros_like(p)
        e[i] = h
        fd = (L(p + e) - L(p - e)) / (2 * h)
        assert abs(g[i] - fd) <= 1e-3 * max(abs(fd), 1e-3 * np.abs(g).max()), (name, g[i], fd)
