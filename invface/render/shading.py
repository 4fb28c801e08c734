"""Lambertian shading under a 9-coefficient spherical-harmonics light (paper 000, Sec. 8.3).

Lighting ``gamma`` (9, 3): the SH coefficients L_lm of the incident radiance, one column per
colour channel, in the real SH basis ordered (l,m) = (0,0), (1,-1), (1,0), (1,1), (2,-2),
(2,-1), (2,0), (2,1), (2,2), in the world (model) frame. The irradiance on a surface of
normal n is Ramamoorthi-Hanrahan's E(n) = sum_lm A_l L_lm Y_lm(n) with A = (pi, 2pi/3, pi/4);
a constant radiance L gives E = pi L. A Lambertian vertex of albedo c (3,) in [0, 1] then
leaves radiance c * E(n) / pi, so a white constant light of radiance L shows albedo c as c*L.

Every function exists twice: numpy (float64, for solvers and tests) and Dr.Jit (float32,
differentiable, for the renderer). Flat Dr.Jit arrays are vertex-major: x0 y0 z0 x1 ...
"""
from __future__ import annotations

import numpy as np

from ..mesh.triangles import vertex_normals  # noqa: F401 - part of this module's API

# Real SH normalisation constants of Y_lm, and the clamped-cosine convolution A_l per basis fn
_Y = np.array([0.282095, 0.488603, 0.488603, 0.488603, 1.092548, 1.092548, 0.315392,
               1.092548, 0.546274])
BAND_WEIGHTS = np.array([np.pi] + [2 * np.pi / 3] * 3 + [np.pi / 4] * 5)
SH_COUNT = 9
SKIN_ALBEDO = np.array([0.62, 0.45, 0.37])   # a mean skin albedo, linear RGB


def sh_basis(normals):
    """Real SH basis Y_lm (..., 9) at unit ``normals`` (..., 3)."""
    n = np.asarray(normals, float)
    x, y, z = n[..., 0], n[..., 1], n[..., 2]
    one = np.ones_like(x)
    return np.stack([_Y[0] * one, _Y[1] * y, _Y[2] * z, _Y[3] * x, _Y[4] * x * y, _Y[5] * y * z,
                     _Y[6] * (3 * z * z - 1), _Y[7] * x * z, _Y[8] * (x * x - y * y)], -1)


def shading_basis(normals):
    """(..., 9) matrix B with E(n)/pi = B @ gamma: the radiance per unit albedo is linear in gamma."""
    return sh_basis(normals) * (BAND_WEIGHTS / np.pi)


def irradiance(normals, gamma):
    """Irradiance E (..., 3) W/m^2-like units of gamma, for normals (..., 3) and gamma (9, 3)."""
    return (sh_basis(normals) * BAND_WEIGHTS) @ np.asarray(gamma, float)


def constant_light(radiance):
    """gamma (9, 3) of a constant environment of RGB radiance ``radiance`` (3,) or scalar."""
    g = np.zeros((SH_COUNT, 3))
    g[0] = np.broadcast_to(np.asarray(radiance, float), 3) * 4 * np.pi * _Y[0]
    return g


def vertex_radiance(vertices, triangles, gamma, albedo):
    """Outgoing radiance (V, 3) = albedo * E(n) / pi of each vertex (numpy)."""
    return np.asarray(albedo, float) * irradiance(vertex_normals(vertices, triangles), gamma) / np.pi


# ---------------------------------------------------------------------------- Dr.Jit versions

def _gather3(Float, flat, n):
    import drjit as dr
    idx = dr.arange(dr.uint32_array_t(Float), n)
    return [dr.gather(Float, flat, 3 * idx + k) for k in range(3)]


def _scatter3(Float, comps):
    import drjit as dr
    n = dr.width(comps[0])
    out = dr.zeros(Float, 3 * n)
    idx = dr.arange(dr.uint32_array_t(Float), n)
    for k in range(3):
        dr.scatter(out, comps[k], 3 * idx + k)
    return out


def vertex_normals_dr(positions, faces):
    """Unit area-weighted vertex normals as three Float arrays (V,), differentiable.

    positions: flat Float (3V,) m; faces: flat UInt32 (3F,)."""
    import drjit as dr
    Float = type(positions)
    UInt = dr.uint32_array_t(Float)
    nv, nf = dr.width(positions) // 3, dr.width(faces) // 3
    fi = dr.arange(UInt, nf)
    corners = [dr.gather(UInt, faces, 3 * fi + k) for k in range(3)]
    p = [[dr.gather(Float, positions, 3 * c + k) for k in range(3)] for c in corners]
    e1 = [p[1][k] - p[0][k] for k in range(3)]
    e2 = [p[2][k] - p[0][k] for k in range(3)]
    fn = [e1[1] * e2[2] - e1[2] * e2[1], e1[2] * e2[0] - e1[0] * e2[2], e1[0] * e2[1] - e1[1] * e2[0]]
    n = [dr.zeros(Float, nv) for _ in range(3)]
    for c in corners:
        for k in range(3):
            dr.scatter_add(n[k], fn[k], c)
    inv = dr.rsqrt(dr.maximum(n[0] * n[0] + n[1] * n[1] + n[2] * n[2], 1e-30))
    return [nk * inv for nk in n]


def vertex_radiance_dr(positions, faces, gamma, albedo):
    """Flat Float (3V,) radiance albedo * E(n)/pi per vertex, differentiable in all inputs.

    positions (3V,) m, faces UInt32 (3F,), gamma Float (27,) = gamma (9,3) row-major,
    albedo (3V,)."""
    import drjit as dr
    Float = type(positions)
    UInt = dr.uint32_array_t(Float)
    x, y, z = vertex_normals_dr(positions, faces)
    Y = [float(v) for v in _Y]      # python floats: numpy scalars would turn Dr.Jit into numpy
    basis = [Y[0] + 0 * x, Y[1] * y, Y[2] * z, Y[3] * x, Y[4] * x * y, Y[5] * y * z,
             Y[6] * (3 * z * z - 1), Y[7] * x * z, Y[8] * (x * x - y * y)]
    w = [float(v) for v in BAND_WEIGHTS / np.pi]
    c = _gather3(Float, albedo, dr.width(x))
    out = []
    for ch in range(3):
        s = 0
        for k in range(SH_COUNT):
            s = s + w[k] * basis[k] * dr.gather(Float, gamma, UInt(3 * k + ch))
        out.append(c[ch] * s)
    return _scatter3(Float, out)


def pose_dr(positions, rotation, translation):
    """x_R = R(theta) x + t on a flat Float (3V,), R = Rz Ry Rx (``model.rig.euler_xyz``).

    rotation, translation: Float (3,) rad and m; differentiable in all three."""
    import drjit as dr
    Float = type(positions)
    UInt = dr.uint32_array_t(Float)
    th = [dr.gather(Float, rotation, UInt(k)) for k in range(3)]
    t = [dr.gather(Float, translation, UInt(k)) for k in range(3)]
    cx, cy, cz = (dr.cos(a) for a in th)
    sx, sy, sz = (dr.sin(a) for a in th)
    R = [[cz * cy, cz * sy * sx - sz * cx, cz * sy * cx + sz * sx],
         [sz * cy, sz * sy * sx + cz * cx, sz * sy * cx - cz * sx],
         [-sy, cy * sx, cy * cx]]
    p = _gather3(Float, positions, dr.width(positions) // 3)
    return _scatter3(Float, [R[i][0] * p[0] + R[i][1] * p[1] + R[i][2] * p[2] + t[i]
                             for i in range(3)])
