"""The template's skull and mandible: implicit bone shapes, meshed by marching cubes.

The bone's outer surface is the face without its soft parts (shape.head_field with
soft=False: no neck, no cartilaginous nose, no eyeballs) moved inwards by the forensic soft
tissue depth of shape.DEPTH_SITES, so the skin lies over the bone at the table's depths at
every craniometric site. On that offset the bone's own features are cut and added:

- cranium: orbits (39 x 31 mm openings, sockets narrowing backwards), the pear-shaped nasal
  (piriform) aperture under the nasal bones, zygomatic arches from the cheekbones back to
  the temporal bone, the maxilla ending at the alveolar (gum) line above the upper teeth;
- mandible: the body from the chin to the angle (gonion), hollowed on its lingual side into
  a U that holds the tongue, the ramus rising to the condyle at the jaw hinge
  (shape.JAW_PIVOT, +-shape.CONDYLE_X) and the coronoid process in front of it, ending at
  the alveolar line under the lower teeth.

The occlusal plane (the teeth's biting plane, template.parts) splits cranium from mandible;
the teeth (template.parts) fill the band between the alveolar lines.
"""
from __future__ import annotations

import numpy as np

from ..mesh.closest import closest_points
from ..mesh.triangles import edge_components
from . import grid
from .sdf import ellipsoid, round_cone, smax, smin
from .shape import CONDYLE_X, JAW_PIVOT, MOUTH_Y, OCCLUSAL_TILT, head_field, tissue_depth

VOXEL = 0.002                    # m, marching-cubes cell
BOX = ((-0.090, 0.090), (-0.115, 0.165), (-0.115, 0.140))
ALVEOLAR_UP = 0.009              # m above the occlusal plane: the maxilla's gum line
ALVEOLAR_DOWN = 0.008            # m below it: the mandible's


def occlusal_y(z):
    """Height (m) of the occlusal plane at depth z (..., ) m: 1 mm under the stomion at the
    incisors, rising 10 degrees towards the back (as the teeth in template.parts)."""
    return (MOUTH_Y - 0.001) + (0.108 - z) * OCCLUSAL_TILT


def _offset_face(p):
    """The face without its soft parts moved inwards by the tissue depth (no cartilage)."""
    f = head_field(p, soft=False)
    d = p - grid.CENTER
    d /= np.maximum(np.linalg.norm(d, axis=-1, keepdims=True), 1e-9)
    on_skin = p - f[..., None] * d                  # nearest skin point along the ray (approx.)
    return f + tissue_depth(on_skin, cartilage=False)


def cranium_field(p):
    """Signed distance-like field (m) of the cranium and maxilla, p (..., 3) m."""
    q = p.copy()
    q[..., 0] = np.abs(q[..., 0])
    f = _offset_face(q)
    # zygomatic arch: from the cheekbone's body back to the temporal bone above the condyle
    f = smin(f, round_cone(q, (0.054, 0.010, 0.050), (0.064, 0.012, 0.004), 0.0045, 0.0035), 0.004)
    # orbits: a wide opening whose rim is the offset face, a socket narrowing backwards
    f = smax(f, -ellipsoid(q, (0.032, 0.035, 0.086), (0.0195, 0.0155, 0.022)), 0.003)
    f = smax(f, -round_cone(q, (0.032, 0.035, 0.080), (0.022, 0.030, 0.040), 0.014, 0.006), 0.003)
    # piriform aperture: wide below, narrow between the nasal bones' lower ends
    f = smax(f, -ellipsoid(q, (0.0, -0.001, 0.100), (0.0125, 0.0115, 0.030)), 0.003)
    f = smax(f, -ellipsoid(q, (0.0, 0.003, 0.100), (0.0070, 0.0090, 0.022)), 0.003)
    # the maxilla ends at the upper gum line; nothing of the face mass under the skull base
    f = smax(f, occlusal_y(q[..., 2]) + ALVEOLAR_UP - q[..., 1], 0.002)
    return f


def mandible_field(p):
    """Signed distance-like field (m) of the mandible at rest, p (..., 3) m."""
    q = p.copy()
    q[..., 0] = np.abs(q[..., 0])
    body = _offset_face(q)
    body = smax(body, q[..., 1] - (occlusal_y(q[..., 2]) - ALVEOLAR_DOWN), 0.002)
    body = smax(body, -0.004 - q[..., 2], 0.004)                    # nothing behind the ramus
    # the lingual hollow: the body is a U of ~12 mm thick bone around the floor of the mouth
    body = smax(body, -ellipsoid(q, (0.0, -0.060, 0.020), (0.037, 0.060, 0.064)), 0.004)
    # ramus: a plate from the angle up to the condylar neck, the condyle, the coronoid process
    cx, cy, cz = CONDYLE_X, JAW_PIVOT[1], JAW_PIVOT[2]
    ramus = ellipsoid(q, (cx - 0.002, -0.030, 0.008), (0.0045, 0.036, 0.016))
    neck = round_cone(q, (cx - 0.002, -0.020, 0.004), (cx, cy - 0.004, cz), 0.004, 0.0035)
    condyle = ellipsoid(q, (cx, cy, cz), (0.0095, 0.0050, 0.0050))
    coronoid = round_cone(q, (cx - 0.003, -0.026, 0.018), (cx - 0.006, 0.002, 0.020), 0.005, 0.002)
    f = smin(body, ramus, 0.006)
    f = smin(f, neck, 0.004)
    f = smin(f, condyle, 0.003)
    return smin(f, coronoid, 0.003)


def _march(field, voxel):
    """Triangle mesh (V (n,3) m, F (m,3), outward) of field's zero level inside BOX."""
    from skimage.measure import marching_cubes

    axes = [np.arange(lo, hi + 1e-9, voxel) for lo, hi in BOX]
    P = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    # in chunks: the depth sites' weights are (points, sites, 3) floats
    vals = np.concatenate([field(P[k:k + 100_000]) for k in range(0, len(P), 100_000)])
    V, F, _, _ = marching_cubes(vals.reshape([len(a) for a in axes]), 0.0, spacing=(voxel,) * 3)
    V += [a[0] for a in axes]
    # the largest connected piece only (marching cubes leaves specks at thin junctions)
    comp = edge_components(F[:, [0, 1, 1, 2]], len(V))
    F = F[comp[F[:, 0]] == np.argmax(np.bincount(comp))]
    used, inv = np.unique(F, return_inverse=True)
    return V[used], inv.reshape(-1, 3).astype(np.int64)       # skimage's winding: outwards


def skull_meshes(voxel=VOXEL):
    """(cranium (V, F), mandible (V, F)) triangle meshes, metres, outward-facing normals."""
    return _march(cranium_field, voxel), _march(mandible_field, voxel)


def tissue_depths(points, bone_meshes):
    """Distance (n,) m from each skin point (n,3) m to the nearest point of the bone meshes
    [(V, F), ...]: the soft-tissue depth as forensic tables measure it."""
    return np.min([closest_points(points, V, F, k=32)[2] for V, F in bone_meshes], axis=0)
