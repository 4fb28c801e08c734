import numpy as np

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


def _cube_mesh(n=4):
    g = np.linspace(0, 1, n + 1)
    X = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    idx = np.arange(len(X)).reshape(n + 1, n + 1, n + 1)
    tets = []
    for i in range(n):
        for j in range(n):
            for k in range(n):
                c = [idx[i + a, j + b, k + d] for a in (0, 1) for b in (0, 1) for d in (0, 1)]
                for t in ([0, 1, 3, 7], [0, 3, 2, 7], [0, 2, 6, 7], [0, 6, 4, 7], [0, 4, 5, 7], [0, 5, 1, 7]):
                    tets.append([c[s] for s in t])
    tets = np.array(tets)
    neg = signed_volumes(X, tets) < 0
    tets[neg] = tets[neg][:, [0, 2, 1, 3]]
    return X, tets


def test_laplacian_reproduces_linear_fields():
    X, T = _cube_mesh()
    L = laplacian(X, T)
    f = 0.3 + X @ np.array([1.0, -2.0, 0.5])
    interior = np.nonzero(np.all((X > 1e-9) & (X < 1 - 1e-9), axis=1))[0]
    assert np.abs((L @ f)[interior]).max() < 1e-12
    bnd = np.setdiff1d(np.arange(len(X)), interior)
    u = harmonic(L, bnd, f[bnd])
    assert np.abs(u - f).max() < 1e-10


def test_boundary_faces_of_a_cube():
    X, T = _cube_mesh(2)
    F, owner = boundary_faces(T)
    assert len(F) == 6 * 2 * 2 * 2
    n = np.cross(X[F[:, 1]] - X[F[:, 0]], X[F[:, 2]] - X[F[:, 0]])
    out = X[F].mean(1) - 0.5
    assert np.all(np.einsum("ij,ij->i", n, out) > 0)
