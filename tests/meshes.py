"""Small tet meshes shared by the tests."""
import numpy as np

from invface.mesh.tets import signed_volumes


def box_tets(counts=(4, 4, 4), size=(1.0, 1.0, 1.0)):
    """A box of counts[0]*counts[1]*counts[2] cubes, 6 positive tets each (Kuhn split
    around the cube diagonal): X (N,3), tets (T,4)."""
    g = np.stack(np.meshgrid(*[np.linspace(0, s, n + 1) for s, n in zip(size, counts)], indexing="ij"), -1)
    idx = np.arange(g[..., 0].size).reshape(g.shape[:3])
    nx, ny, nz = counts
    tets = []
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                c = [idx[i + a, j + b, k + d] for a in (0, 1) for b in (0, 1) for d in (0, 1)]
                for t in ([0, 1, 3, 7], [0, 3, 2, 7], [0, 2, 6, 7], [0, 6, 4, 7], [0, 4, 5, 7], [0, 5, 1, 7]):
                    tets.append([c[s] for s in t])
    X, tets = g.reshape(-1, 3), np.array(tets)
    neg = signed_volumes(X, tets) < 0
    tets[neg] = tets[neg][:, [0, 2, 1, 3]]
    return X, tets
