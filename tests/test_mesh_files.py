"""Mesh files as scanners write them (issue 62 item 1): PLY triangle strips in ASCII and both
binary byte orders, and a point cloud refused with what to do."""
import struct

import numpy as np
import pytest

from invface.errors import MeshError
from invface.io.meshes import read_mesh


def _grid(nx=5, ny=4):
    """A grid of vertices in the z = 0 plane, and its rows as triangle strips (each strip
    alternates the two rows: top-left, bottom-left, top-next, bottom-next, ...)."""
    x, y = np.meshgrid(np.arange(nx, dtype=float), np.arange(ny, dtype=float))
    V = np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], 1)
    strips = []
    for r in range(ny - 1):
        s = np.ravel(np.stack([(r + 1) * nx + np.arange(nx), r * nx + np.arange(nx)], 1))
        strips += s.tolist() + [-1]
    return V, strips[:-1]


def _ply(path, V, strips, fmt):
    head = (f"ply\nformat {fmt} 1.0\ncomment made by the test\nelement vertex {len(V)}\nproperty float x\n"
            f"property float y\nproperty float z\nproperty uchar confidence\nelement tristrips 1\n"
            "property list int int vertex_indices\nend_header\n").encode()
    if fmt == "ascii":
        body = "".join(f"{a} {b} {c} 7\n" for a, b, c in V) + f"{len(strips)} " + " ".join(map(str, strips)) + "\n"
        path.write_bytes(head + body.encode())
        return
    o = "<" if fmt == "binary_little_endian" else ">"
    body = b"".join(struct.pack(o + "fffB", *v, 7) for v in V)
    body += struct.pack(o + "i", len(strips)) + struct.pack(o + f"{len(strips)}i", *strips)
    path.write_bytes(head + body)


@pytest.mark.parametrize("fmt", ["ascii", "binary_little_endian", "binary_big_endian"])
def test_a_ply_of_triangle_strips_reads_as_its_triangles(tmp_path, fmt):
    """Every grid cell comes back as two triangles, all facing the same way (the strips' odd
    triangles flipped), none degenerate, in every PLY format."""
    V, strips = _grid()
    _ply(tmp_path / "scan.ply", V, strips, fmt)
    Vr, F = read_mesh(tmp_path / "scan.ply")
    np.testing.assert_allclose(Vr, V)
    assert len(F) == 2 * 4 * 3
    n = np.cross(Vr[F[:, 1]] - Vr[F[:, 0]], Vr[F[:, 2]] - Vr[F[:, 0]])
    assert np.all(np.abs(n[:, 2]) > 0.4) and len(set(np.sign(n[:, 2]))) == 1       # one winding
    area = 0.5 * np.abs(n[:, 2]).sum()
    assert area == pytest.approx(4 * 3)                                           # the whole grid, once


def test_a_point_cloud_is_refused_with_what_to_do(tmp_path):
    path = tmp_path / "cloud.ply"
    V = np.random.default_rng(0).normal(size=(50, 3))
    path.write_bytes(("ply\nformat ascii 1.0\nelement vertex 50\nproperty float x\nproperty float y\n"
                      "property float z\nend_header\n" + "".join(f"{a} {b} {c}\n" for a, b, c in V)).encode())
    with pytest.raises(MeshError, match=r"cloud.ply: the file holds no triangle mesh \(50 points and no faces: a "
                                        r"point cloud; mesh it first"):
        read_mesh(path)
