"""The template's eyeballs, teeth, tongue and mouth lining (``model.parts.InnerParts``).

Built procedurally from the head's anatomical positions (``shape``) and its bone surface, in
millimetre-scale adult proportions:

- eyeballs: spheres of radius ``EYE_RADIUS`` (12.2 mm; adult axial length ~24 mm) at the
  orbit centres, looking along +Z; iris radius 6 mm, pupil 2 mm; behind each the
  conjunctiva that the open fissure shows at its corners;
- teeth: an upper and a lower dental arch (half-ellipse 27 mm half-width at the second
  molars, 45 mm deep), crowns 10 -> 7 mm tall and 7 -> 10 mm thick from incisors to molars,
  with gums, the occlusal plane 1 mm under the stomion at the incisors and rising 10 degrees
  towards the molars, 1 mm of overbite and 3 mm of overjet; upper teeth on the cranium,
  lower on the jaw;
- the tongue, an ellipsoid on the jaw resting on the floor of the mouth;
- the lining of the oral cavity, an ellipsoid open in front of the teeth, its upper half on
  the cranium and its lower half on the jaw, blended across the occlusal plane.

The mouth is dark in a photograph because little light reaches inside it; the renderer has no
shadows, so that occlusion is baked into the parts' albedo (darker towards the back).
"""
from __future__ import annotations

import numpy as np

from ..model.parts import concatenate
from .shape import EYE_CENTER, EYE_RADIUS, MOUTH_Y, OCCLUSAL_TILT

MM = 1e-3
SCLERA = (0.68, 0.64, 0.60)
IRIS = (0.20, 0.11, 0.06)
PUPIL = (0.015, 0.015, 0.015)
CONJUNCTIVA = (0.42, 0.18, 0.16)
TOOTH = (0.72, 0.68, 0.58)
GUM = (0.55, 0.24, 0.24)
TONGUE = (0.45, 0.17, 0.16)
LINING = (0.16, 0.05, 0.05)
# upper tooth widths along the arch from the midline (mm): incisors, canine, premolars, molars
UPPER_WIDTHS = (8.5, 6.5, 7.5, 7.0, 6.5, 10.0, 9.0)
LOWER_WIDTHS = (5.5, 6.0, 7.0, 7.0, 7.0, 11.0, 10.5)


def grid_triangles(n_u, n_v, wrap_v=False):
    """Triangles (F,3) of an n_u x n_v vertex grid (vertex u*n_v + v), optionally closed in v."""
    vv = n_v if wrap_v else n_v - 1
    u, v = np.meshgrid(np.arange(n_u - 1), np.arange(vv), indexing="ij")
    a = u * n_v + v
    b = u * n_v + (v + 1) % n_v
    c, d = a + n_v, b + n_v
    return np.concatenate([np.stack([a, c, b], -1).reshape(-1, 3), np.stack([b, c, d], -1).reshape(-1, 3)])


def orient_away(V, F, inner):
    """Flip the triangles whose normal points towards ``inner`` (F,3) (a point inside the part
    for each triangle): afterwards every normal points away from it."""
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    flip = np.einsum("fi,fi->f", n, V[F].mean(1) - inner) < 0
    F = F.copy()
    F[flip] = F[flip][:, [0, 2, 1]]
    return F


def _sphere(centre, radii, thetas, n_phi):
    """Vertices of an ellipsoid by polar rings around +Z: rings at polar angles ``thetas``
    (ending poles 0 and pi included), n_phi points each; returns (V, F, theta per vertex)."""
    th = np.asarray(thetas, float)
    ph = np.linspace(0, 2 * np.pi, n_phi, endpoint=False)
    T, P = np.meshgrid(th[1:-1], ph, indexing="ij")
    ring = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    unit = np.concatenate([[[0, 0, 1.0]], ring, [[0, 0, -1.0]]])
    V = np.asarray(centre) + unit * np.asarray(radii)
    n_r = len(th) - 2
    F = [grid_triangles(n_r, n_phi, wrap_v=True) + 1]
    k = np.arange(n_phi)
    F.append(np.stack([np.zeros(n_phi, int), 1 + k, 1 + (k + 1) % n_phi], 1))
    last = 1 + (n_r - 1) * n_phi
    F.append(np.stack([np.full(n_phi, len(V) - 1), last + (k + 1) % n_phi, last + k], 1))
    F = orient_away(V, np.concatenate(F), np.asarray(centre, float))
    theta = np.concatenate([[0.0], np.repeat(th[1:-1], n_phi), [np.pi]])
    return V, F, theta


def eyeball(centre, radius=EYE_RADIUS, iris=6.0 * MM, pupil=2.0 * MM):
    """One eyeball (V, F, albedo) looking along +Z: sclera, iris with a darker limbal ring,
    pupil; rings are placed on the iris's and pupil's edges so the colours stay sharp."""
    t_iris, t_pupil = np.arcsin(iris / radius), np.arcsin(pupil / radius)
    thetas = np.unique(np.concatenate([
        np.linspace(0, t_pupil, 4), np.linspace(t_pupil, t_iris, 6), [t_iris + 0.03],
        np.linspace(t_iris + 0.08, np.pi, 14)]))
    V, F, th = _sphere(centre, (radius,) * 3, thetas, 36)
    alb = np.tile(SCLERA, (len(V), 1))
    ring = np.clip((th - 0.75 * t_iris) / (0.25 * t_iris), 0, 1)           # limbal darkening
    alb[th <= t_iris + 1e-9] = np.array(IRIS) * (1 - 0.5 * ring[th <= t_iris + 1e-9, None])
    alb[th <= t_pupil + 1e-9] = PUPIL
    return V, F, alb


def conjunctiva(centre):
    """The conjunctival sac behind an open eye's corners (V, F, albedo): an ellipsoidal cap
    4 mm behind the eyeball's centre, 15.5 mm to either side and 12 mm up, down and forwards,
    so it stays behind the eyeball (its front is 4 mm behind the cornea's base) and fills
    what the fissure shows beyond the eyeball's outline at the canthi (the fissure is 26 mm
    wide, the eyeball 24.4 mm); it lies 2.7 mm or more inside the skin."""
    V, F, _ = _sphere(np.asarray(centre) - (0, 0, 4 * MM), (15.5 * MM, 12 * MM, 12 * MM),
                      np.linspace(0, np.radians(110), 12), 36)
    return V, F, np.tile(CONJUNCTIVA, (len(V), 1))


def _arch(z_front, half_width, depth, step=0.7 * MM, widths=UPPER_WIDTHS):
    """Samples along a dental arch x = a sin(phi), z = z_front - b (1 - cos phi) from one
    second molar to the other: positions (n,3) at y = 0, outward horizontal normals (n,3),
    arc length from the midline (n,) m, and each sample's distance along the arch to the
    nearest boundary between two teeth (n,) m."""
    phi = np.linspace(-np.radians(82), np.radians(82), 4001)
    P = np.stack([half_width * np.sin(phi), np.zeros_like(phi), z_front - depth * (1 - np.cos(phi))], 1)
    s = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(P, axis=0), axis=1))])
    s -= np.interp(0.0, phi, s)                                        # 0 on the midline
    bounds = np.cumsum((0,) + tuple(widths)) * MM
    bounds = bounds[bounds <= s[-1]]
    gaps = np.concatenate([-bounds[::-1], bounds[1:]])
    half = np.unique(np.round(np.concatenate([
        np.arange(0, s[-1], step), bounds - 0.35 * MM, bounds, bounds + 0.35 * MM, [s[-1]]]), 7))
    half = half[(half >= 0) & (half <= s[-1])]
    samples = np.concatenate([-half[:0:-1], half])                    # symmetric about the midline
    pos = np.stack([np.interp(samples, s, P[:, k]) for k in range(3)], 1)
    tangent = np.stack([np.interp(samples, s, np.gradient(P[:, k], s)) for k in range(3)], 1)
    normal = np.stack([tangent[:, 2], np.zeros(len(samples)), -tangent[:, 0]], 1)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    normal *= np.sign(normal[:, 2:3] + 1e-12)                         # away from the mouth's inside
    gap = np.min(np.abs(samples[:, None] - gaps[None, :]), axis=1)
    return pos, normal, np.abs(samples), gap


def teeth(z_front, y_occlusal, tilt, half_width=27 * MM, depth=45 * MM, upper=True):
    """One dental arch with its gums (V, F, albedo). z_front: the incisors' labial face on
    the midline (m); y_occlusal: the biting edge there (m); tilt: rise of the occlusal plane
    per metre towards the back (tan of its angle)."""
    pos, normal, arc, gap = _arch(z_front, half_width, depth, widths=UPPER_WIDTHS if upper else LOWER_WIDTHS)
    f = np.clip(arc / (0.5 * depth + half_width), 0, 1)               # 0 incisors .. 1 molars
    h = (10.0 - 3.0 * f) * MM                                          # crown height
    t = (7.0 + 3.0 * f) * MM                                           # crown thickness
    # profile (inward offset, height above the biting edge, is tooth) from the labial gum
    # over the crown to the lingual gum
    prof = [(-0.6 * MM, h + 4 * MM, 0), (0, h + 0.5 * MM, 0), (0, h, 1), (0, 0.5 * h, 1),
            (0.5 * MM, 0 * h, 1), (t - 0.5 * MM, 0 * h, 1), (t, 0.5 * h, 1), (t, h, 1),
            (t + 0.3 * MM, h + 0.5 * MM, 0), (t + 0.6 * MM, h + 4 * MM, 0)]
    sign = 1.0 if upper else -1.0
    base_y = y_occlusal + (z_front - pos[:, 2]) * tilt
    rows, is_tooth = [], []
    # the lower front teeth lean forwards (about 20 degrees), their roots behind their edges
    lean = 0.0 if upper else 0.35 * (1 - f)
    for off, up, tooth in prof:
        p = pos - (np.asarray(off) + lean * up)[..., None] * normal
        p[:, 1] = base_y + sign * up
        rows.append(p)
        is_tooth.append(np.full(len(pos), tooth))
    n_s = len(pos)
    V = np.stack(rows, 1).reshape(-1, 3)                              # sample-major
    F = grid_triangles(n_s, len(prof))
    axis = (pos - 0.5 * t[:, None] * normal)
    axis[:, 1] = base_y + sign * 0.5 * h
    F = orient_away(V, F, np.repeat(axis, len(prof), 0)[F[:, 0]])
    tooth = np.stack(is_tooth, 1).reshape(-1).astype(bool)
    lingual = np.tile(np.arange(len(prof)) >= 6, n_s)
    ao = np.repeat(0.35 + 0.65 * np.exp(-(arc / (30 * MM)) ** 2), len(prof))
    groove = np.repeat(1 - 0.35 * np.exp(-(gap / (0.25 * MM)) ** 2), len(prof))
    alb = np.where(tooth[:, None], np.array(TOOTH) * groove[:, None], GUM)
    alb = alb * (ao * np.where(lingual, 0.6, 1.0))[:, None]
    return V, F, alb


def mouth_parts(z_front, y_occlusal, tilt=OCCLUSAL_TILT):
    """The teeth, tongue and cavity lining as (name, V, F, albedo, jaw weights) tuples."""
    out = []
    V, F, a = teeth(z_front, y_occlusal, tilt, upper=True)
    out.append(("upper_teeth", V, F, a, 0.0))
    V, F, a = teeth(z_front - 3 * MM, y_occlusal + 0.5 * MM, tilt, half_width=25.5 * MM, depth=43 * MM,
                    upper=False)
    out.append(("lower_teeth", V, F, a, 1.0))
    centre = np.array([0.0, y_occlusal - 9 * MM + 20 * MM * tilt, z_front - 30 * MM])
    th = np.linspace(0, np.pi, 16)
    V, F, _ = _sphere(centre, (17 * MM, 8 * MM, 20 * MM), th, 28)
    depth = np.clip((z_front - V[:, 2]) / (25 * MM), 0, None)
    out.append(("tongue", V, F, np.array(TONGUE) * (0.25 + 0.75 * np.exp(-depth))[:, None], 1.0))
    # the lining: an ellipsoid around teeth and tongue without its front cap (62 degrees
    # around +Z, the mouth's opening), facing inwards
    centre = np.array([0.0, y_occlusal - 2 * MM + 30 * MM * tilt, z_front - 32 * MM])
    radii = np.array([31 * MM, 22 * MM, 35 * MM])
    V, F, th = _sphere(centre, radii, np.linspace(0, np.pi, 24), 40)
    cut = th < np.radians(62)
    used, inv = np.unique(F[~cut[F].any(1)], return_inverse=True)
    V, F = V[used], inv.reshape(-1, 3)[:, [0, 2, 1]]                  # normals into the cavity
    depth = np.clip((z_front - V[:, 2]) / (20 * MM), 0, None)
    occl = y_occlusal + (z_front - V[:, 2]) * tilt
    w = np.clip((occl + 2 * MM - V[:, 1]) / (8 * MM) + 0.5, 0, 1)
    out.append(("mouth_lining", V, F, np.array(LINING) * (0.3 + 0.7 * np.exp(-depth))[:, None], w))
    return out


def template_parts(inner_vertices):
    """The template's InnerParts. inner_vertices (B,3) m: the flesh's inner surface (the free
    mucosa moved 1 mm forwards), which puts the incisors 1.5 mm behind the upper lip's."""
    B = np.asarray(inner_vertices, float)
    near = (np.abs(B[:, 0]) < 8 * MM) & (B[:, 1] > MOUTH_Y) & (B[:, 1] < MOUTH_Y + 12 * MM)
    z_front = float(B[near, 2].max()) - 1.5 * MM
    parts = []
    for side, sx in (("L", 1.0), ("R", -1.0)):
        V, F, a = eyeball(EYE_CENTER * (sx, 1, 1))
        parts.append((f"eye_{side}", V, F, a, 0.0))
        parts.append((f"conjunctiva_{side}", *conjunctiva(EYE_CENTER * (sx, 1, 1)), 0.0))
    parts += mouth_parts(z_front, MOUTH_Y - 1 * MM)
    return concatenate(parts)

