"""Tet untangling and quality optimisation (mesh.untangle), used by the volume morph."""
import numpy as np

from invface.mesh.tets import boundary_faces, radius_ratio, signed_volumes
from invface.mesh.untangle import _delta, _energy, untangle


def test_energy_gradient_matches_finite_differences():
    rng = np.random.default_rng(0)
    X0 = rng.normal(size=(5, 3))
    tets = np.array([[0, 1, 2, 3], [1, 2, 3, 4]])
    neg = signed_volumes(X0, tets) < 0
    tets[neg] = tets[neg][:, [1, 0, 2, 3]]
    D0 = (X0[tets][:, 1:] - X0[tets][:, :1]).transpose(0, 2, 1)
    inv, w = np.linalg.inv(D0), np.array([1.0, 2.0])
    X = X0 + 0.4 * rng.normal(size=X0.shape)     # large enough to invert a tet
    E, g = _energy(X, inv, w, tets, 0.05)
    fd = np.zeros_like(X)
    for i in range(5):
        for j in range(3):
            d = np.zeros_like(X)
            d[i, j] = 1e-6
            fd[i, j] = (_energy(X + d, inv, w, tets, 0.05)[0] - _energy(X - d, inv, w, tets, 0.05)[0]) / 2e-6
    assert np.abs(fd - g).max() < 1e-6 * np.abs(g).max()
    # a similarity of the reference scores 1 per unit weight, the minimum
    Q = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    Q *= np.sign(np.linalg.det(Q))
    E0, g0 = _energy(2.0 * X0 @ Q.T + 1.0, inv, w, tets, 1e-9)
    assert abs(E0 - w.sum()) < 1e-6 and np.abs(g0).max() < 1e-6


def test_untangles_a_scrambled_template(small_model):
    X0, T = small_model.rest_positions, small_model.tets
    rng = np.random.default_rng(1)
    skin = np.unique(boundary_faces(T)[0])
    moved = np.setdiff1d(rng.choice(len(X0), 40, replace=False), skin)
    X = X0.copy()
    X[moved] += rng.normal(size=(len(moved), 3)) * 0.006
    assert (signed_volumes(X, T) <= 0).sum() > 20
    region = np.zeros(len(X), bool)
    region[moved] = True
    for _ in range(2):
        region[np.unique(T[region[T].any(1)])] = True
    free = np.setdiff1d(np.flatnonzero(region), skin)
    Y = untangle(X, X0, T, free)
    assert (signed_volumes(Y, T) > 0).all()
    assert radius_ratio(Y, T).min() >= 0.5 * radius_ratio(X0, T).min()
    held = np.setdiff1d(np.arange(len(X)), free)
    assert np.array_equal(Y[held], X[held])


def test_a_shrunken_tet_costs_no_less_than_a_good_one():
    """The mean-ratio distortion is scale-free: a tet shrunk to a twentieth of its size (1e-4
    of its volume) is as good as the reference, and a sliver at that size worse. A fixed
    regulariser of 0.01 scored the shrunken tet below a good one's 1, so the untangling left
    tets of an ICT face's temple shrunk to slivers (radius ratio 1e-4) and the build stopped.
    The regulariser now follows the smallest volume ratio once none is inverted and a tet is
    under a thousandth of its volume."""
    X0 = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    tets = np.array([[0, 1, 2, 3]])
    inv = np.linalg.inv((X0[1:] - X0[:1]).T)[None]
    w = np.array([1.0])
    for X, least in ((0.05 * X0, 0.99), (0.05 * X0 * [1, 1, 0.05], 2.0)):
        ratio = np.linalg.det((X[1:] - X[:1]).T @ inv[0])
        assert ratio > 0
        assert _energy(X, inv, w, tets, _delta(np.array([ratio])))[0] >= least
    assert _energy(0.05 * X0, inv, w, tets, 0.01)[0] < 0.5       # the fixed regulariser's score
    assert _delta(np.array([-0.2, 0.5])) > 0.01                   # inverted: wide, to pass through zero
