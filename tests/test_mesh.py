import numpy as np

from meshes import box_tets

from invface.mesh.tets import (boundary_faces, dihedral_angles, harmonic, laplacian, radius_ratio,
                               signed_volumes)

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
