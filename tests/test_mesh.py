import numpy as np

from meshes import box_tets

from invface.mesh.embedding import barycentric_matrix, moving_least_squares
from invface.mesh.tets import (boundary_faces, dihedral_angles, harmonic, laplacian, locate, locate_near,
                               radius_ratio, signed_volumes)
from invface.mesh.triangles import covered_from_front

REG = np.array([[1, 1, 1], [1, -1, -1], [-1, 1, -1], [-1, -1, 1]], float)


def test_regular_tet_quality():
    t = np.array([[0, 1, 2, 3]])
    X = REG if signed_volumes(REG, t)[0] > 0 else REG[[0, 2, 1, 3]]
    assert np.allclose(np.degrees(dihedral_angles(X, t)), np.degrees(np.arccos(1 / 3)))
    assert np.isclose(radius_ratio(X, t)[0], 1.0)
    flat = X.copy()
    flat[3] = (X[0] + X[1] + X[2]) / 3 + 1e-9
    assert radius_ratio(flat, t)[0] < 1e-6


def test_laplacian_reproduces_linear_fields():
    X, T = box_tets()
    L = laplacian(X, T)
    f = 0.3 + X @ np.array([1.0, -2.0, 0.5])
    interior = np.nonzero(np.all((X > 1e-9) & (X < 1 - 1e-9), axis=1))[0]
    assert np.abs((L @ f)[interior]).max() < 1e-12
    bnd = np.setdiff1d(np.arange(len(X)), interior)
    u = harmonic(L, bnd, f[bnd])
    assert np.abs(u - f).max() < 1e-10


def test_boundary_faces_of_a_cube():
    X, T = box_tets((2, 2, 2))
    F, owner = boundary_faces(T)
    assert len(F) == 6 * 2 * 2 * 2
    n = np.cross(X[F[:, 1]] - X[F[:, 0]], X[F[:, 2]] - X[F[:, 0]])
    out = X[F].mean(1) - 0.5
    assert np.all(np.einsum("ij,ij->i", n, out) > 0)


def test_locate_near_keeps_a_point_on_its_side_of_a_slit():
    """Two slabs 2 mm apart (the lips of a closed slit): a point in the gap, nearer the lower
    slab, is found in the lower slab by the plain search, but kept in the upper slab (the
    side its start tet is on) by locate_near, with weights that still reproduce it."""
    X, t = box_tets((3, 3, 2), (0.03, 0.03, 0.01))
    upper = X + [0, 0, 0.011]
    Xs, tets = np.concatenate([X, upper]), np.concatenate([t, t + len(X)])
    p = np.array([[0.016, 0.014, 0.0104]])
    t_plain, _ = locate(Xs, tets, p)
    assert t_plain[0] < len(t)                                   # the lower slab: nearer
    start = np.array([len(t) + int(np.argmin(np.linalg.norm(Xs[tets[len(t):]].mean(1) - p, axis=1)))])
    t_near, w = locate_near(Xs, tets, p, start)
    assert t_near[0] >= len(t)                                   # the upper slab
    assert np.allclose(np.einsum("pk,pkj->pj", w, Xs[tets[t_near]]), p)
    assert w.min() > -0.2                                        # the best tet near the start


def _sheet_in_box():
    """A 4 cm box of 4x4x4 cells and a fine 61x61 sheet of points 1 cm deep in it."""
    X, T = box_tets((4, 4, 4), (0.04, 0.04, 0.04))
    g = np.linspace(0.003, 0.037, 61)
    P = np.stack([*np.meshgrid(g, g, indexing="ij"), np.full((61, 61), 0.013)], -1).reshape(-1, 3)
    t, w = locate(X, T, P)
    return X, T, P, t, w


def test_moving_least_squares_reproduces_affine_maps_and_is_smooth_across_tet_faces():
    """The smooth embedding moves the sheet exactly with any affine map of the nodes. Under a
    bend (dz = 40 x^2) its second differences along the sheet stay near the bend's own
    (2 * 40 * dx^2), where the barycentric sheet is flat inside each tet and creased at its
    faces. A bump one cell wide is followed about as well as barycentric weights follow it;
    without the nodal correction the approximant flattens it."""
    X, T, P, t, w = _sheet_in_box()
    W = moving_least_squares(X, T, P, t, w)
    assert np.allclose(np.asarray(W.sum(1)).ravel(), 1.0, atol=1e-12)
    G, c = np.array([[1.1, 0.2, -0.1], [0.05, 0.9, 0.3], [-0.2, 0.1, 1.2]]), np.array([0.01, -0.02, 0.005])
    assert np.abs(W @ (X @ G.T + c) - (P @ G.T + c)).max() < 1e-12
    bent = X + np.c_[np.zeros((len(X), 2)), 40.0 * X[:, 0] ** 2]
    dx = P[61, 0] - P[0, 0]
    exact = 2 * 40.0 * dx ** 2

    def bump(Y):
        return 0.002 * np.exp(-((Y - [0.02, 0.02, 0.013]) ** 2).sum(1) / 0.01 ** 2)
    bumped = X + np.c_[np.zeros((len(X), 2)), bump(X)]
    crease, rms = {}, {}
    for name, E in (("mls", W), ("barycentric", barycentric_matrix(T, t, w, len(X))),
                    ("uncorrected", moving_least_squares(X, T, P, t, w, correct=False))):
        z = (E @ bent)[:, 2].reshape(61, 61)
        crease[name] = np.abs(np.diff(z, 2, axis=0) - exact).max() / exact
        rms[name] = np.sqrt(np.mean(((E @ bumped)[:, 2] - P[:, 2] - bump(P)) ** 2))
    assert crease["barycentric"] > 10 and crease["mls"] < 0.2 * crease["barycentric"], crease      # 16.6, 1.4
    assert rms["mls"] < 1.2 * rms["barycentric"] < rms["uncorrected"], rms                          # 0.25, 0.23, 0.37 mm


def test_moving_least_squares_keeps_a_point_on_its_side_of_a_slit():
    """Two slabs 1 mm apart, well within the kernel's reach: the points of the upper slab blend
    only its own nodes, so they follow it exactly when it moves and the lower slab does not."""
    X, t = box_tets((3, 3, 2), (0.03, 0.03, 0.01))
    Xs, tets = np.concatenate([X, X + [0, 0, 0.011]]), np.concatenate([t, t + len(X)])
    p = np.array([[0.016, 0.014, 0.0112], [0.005, 0.02, 0.0115]])
    start = len(t) + np.argmin(np.linalg.norm(Xs[tets[len(t):]].mean(1)[None] - p[:, None], axis=2), axis=1)
    tid, w = locate_near(Xs, tets, p, start)
    W = moving_least_squares(Xs, tets, p, tid, w, radius=3.0)
    assert W[:, :len(X)].nnz == 0
    moved = Xs + np.where(np.arange(len(Xs)) >= len(X), 0.005, 0.0)[:, None] * [0, 0, 1]
    assert np.allclose(W @ moved, p + [0, 0, 0.005], atol=1e-12)


def test_covered_from_front_on_a_sphere():
    """A closed sphere: the back half is covered along +z, the front half is not."""
    import trimesh
    s = trimesh.creation.icosphere(4, radius=0.1)
    hidden = covered_from_front(s.vertices, s.faces)
    nz = s.face_normals[:, 2]
    assert hidden[nz < -0.02].all() and not hidden[nz > 0.02].any()


def test_radius_ratio_of_a_collapsed_tet_is_zero():
    """Two corners (nearly) coincident made 0/0 in the circumradius: 3.8e281 once, which passed
    the morph's quality bound and broke the skin embedding's solves (a builder test)."""
    from invface.mesh.tets import radius_ratio
    rng = np.random.default_rng(0)
    base = np.array([[0.0749, 0.0536, -0.0027], [0.0750, 0.0481, -0.0007], [0.0741, 0.0471, -0.0011]])
    X = np.concatenate([base, base[1] + rng.normal(0, 1, (200, 3)) * 10.0 ** rng.uniform(-19, -12, (200, 1))])
    tets = np.stack([np.zeros(200, int), np.ones(200, int), np.full(200, 2), 3 + np.arange(200)], 1)
    rr = radius_ratio(X, tets)
    assert np.all((rr >= 0) & (rr < 1e-3))
    assert radius_ratio(np.eye(4)[:, :3] * 0.01 + [[0, 0, 0]] * 4, np.array([[3, 0, 1, 2]]))[0] > 0.5
