"""Open eyes at rest: the template's lid slits rotated apart over the eyeballs.

The skin field closes the lids over each eyeball (``shape.head_field``) and the grid cuts a
slit between them (``surfaces``). An adult face at rest shows a palpebral fissure about
10 mm high: the upper lid's margin lies about 4.5 mm above the pupil's centre (it covers
the iris's top 1-2 mm) and the lower lid's near the iris's lower edge, about 5 mm below it.
The lids slide over the eyeball as rotations about its centre, so the fissure is opened the
same way: every point of a lid is turned about the horizontal axis through the eyeball's
centre, upwards on the upper lid and downwards on the lower, by

    d_phi = A g(theta) f(u) h(r),    u = |phi - phi_slit(theta)| / W

with phi the point's elevation and theta its azimuth seen from the eyeball's centre,
phi_slit the slit's elevation at that azimuth, g = 1 - t^2 the fissure's almond profile
(t = -1..1 between the canthi, 0 beyond them), f a smoothstep from 1 at the slit to 0 at
W (the lid's tissue is compressed towards the orbital rim, not torn), and h a fade with the
distance r from the eyeball's centre (1 up to ``FADE[0]``, 0 from ``FADE[1]``), so that the
brow and the bone do not move. The map is continuous and, with A * 1.5 / W < 1, one to one
on each side of the slit; the two sides of the slit (the slit's original and duplicated
vertices) are told apart by index, everything else by the sign of phi - phi_slit.
"""
from __future__ import annotations

import numpy as np

from . import grid
from .shape import EYE_CENTER, EYE_RADIUS

UPPER_MARGIN = 0.33     # rad: the upper lid margin's elevation at the fissure's middle (~4.5 mm)
LOWER_MARGIN = -0.40    # rad: the lower lid margin's (~5 mm below the pupil's centre line)
UPPER_WIDTH = 1.2       # rad: W of the upper lid (the tissue up to the orbital rim)
LOWER_WIDTH = 0.8       # rad: W of the lower lid
FADE = (0.016, 0.026)   # m from the eyeball's centre
LID_GAP = 0.0002        # m: the lids' inner surface rests this far outside the eyeball
MIN_LID = 0.0012        # m: the thinnest lid (skin to its inner surface)
CANTHAL_REACH = 0.0095  # m: lids slide on the eyeball up to this far to either side of its centre


def eye_centres():
    """(2,3) the left and right eyeballs' centres (m)."""
    return EYE_CENTER * np.array([[1.0, 1, 1], [-1.0, 1, 1]])


def on_eyeball(P, tol=0.0003):
    """(n,) bool: points P (n,3) of the lids' inner surface that slide on an eyeball: within
    ``tol`` of the sphere EYE_RADIUS + LID_GAP about either eyeball's centre (or inside it)
    and less than ``CANTHAL_REACH`` to the side of its centre. Beyond that the canthal
    tendons hold the lids' corners to the orbit's rim (free corners let a closing lid ring
    pull them inwards instead of closing: the lateral canthus moved 4 mm forwards)."""
    d = np.asarray(P, float)[:, None, :] - eye_centres()[None]
    near = (np.linalg.norm(d, axis=2) < EYE_RADIUS + LID_GAP + tol) & (np.abs(d[..., 0]) < CANTHAL_REACH)
    return near.any(1)


def lid_inner_radii(alpha, beta, r_skin, r_inner):
    """The flesh's inner radii (...) along the rays (alpha, beta) from grid.CENTER, moved out
    to the eyeball where a ray meets it before its tissue depth ends: the lids' inner layer
    lies on the eyeball (``LID_GAP`` outside it, the lid at least ``MIN_LID`` thick) and
    slides on it (sim.contact.EyeballContacts) instead of being fixed inside it."""
    d = grid.directions(alpha, beta)
    out = np.array(r_inner, float)
    for c in eye_centres():
        o = grid.CENTER - c
        b = d @ o
        disc = b * b - (o @ o - (EYE_RADIUS + LID_GAP) ** 2)
        hit = -b + np.sqrt(np.maximum(disc, 0.0))
        out = np.where((disc > 0) & (hit > out), np.minimum(hit, r_skin - MIN_LID), out)
    return out


def _polar(p):
    """Elevation phi, azimuth theta (rad) and distance r (m) of points p (n,3), given for the
    left eye (x >= 0) about EYE_CENTER."""
    d = p - EYE_CENTER
    phi = np.arctan2(d[:, 1], d[:, 2])
    theta = np.arctan2(d[:, 0], np.hypot(d[:, 1], d[:, 2]))
    return phi, theta, np.linalg.norm(d, axis=1)


def _smoothstep_down(u):
    u = np.clip(u, 0.0, 1.0)
    return 1.0 - u * u * (3.0 - 2.0 * u)


def open_lids(P, slit, upper_ids, lower_ids, column=None):
    """Points P (n,3) m with the lids of both eyes opened (a new array).

    slit: (s,3) the left eye's slit on the skin, corner to corner (it fixes phi_slit(theta)
    and the canthi); upper_ids / lower_ids: ids into P of the points that belong to the upper
    / lower lid by construction (the slit's original and duplicated columns, both eyes);
    column: (n,) optional id of the skin point whose side a point takes (the layered shell:
    a deep point takes its skin column's side), default each point its own.
    """
    P = np.asarray(P, float)
    q = P.copy()
    q[:, 0] = np.abs(q[:, 0])
    phi, theta, r = _polar(q)
    s_phi, s_theta, _ = _polar(np.asarray(slit, float))
    order = np.argsort(s_theta)
    s_phi, s_theta = s_phi[order], s_theta[order]
    t0, t1 = s_theta[0], s_theta[-1]
    t = (theta - 0.5 * (t0 + t1)) / (0.5 * (t1 - t0))
    g = np.clip(1.0 - t * t, 0.0, 1.0)
    slit_phi = np.interp(theta, s_theta, s_phi)
    mid = np.interp(0.5 * (t0 + t1), s_theta, s_phi)
    col = np.arange(len(P)) if column is None else np.asarray(column)
    up = (phi - slit_phi)[col] > 0
    up[np.isin(col, upper_ids)] = True
    up[np.isin(col, lower_ids)] = False
    A = np.where(up, UPPER_MARGIN - mid, LOWER_MARGIN - mid)
    W = np.where(up, UPPER_WIDTH, LOWER_WIDTH)
    u = np.where(up, phi - slit_phi, slit_phi - phi) / W
    fade = _smoothstep_down((r - FADE[0]) / (FADE[1] - FADE[0]))
    dphi = A * g * _smoothstep_down(u) * fade
    d = q - EYE_CENTER
    c, s = np.cos(dphi), np.sin(dphi)
    out = q.copy()
    out[:, 1] = EYE_CENTER[1] + c * d[:, 1] + s * d[:, 2]
    out[:, 2] = EYE_CENTER[2] - s * d[:, 1] + c * d[:, 2]
    out[:, 0] = P[:, 0]
    return out
