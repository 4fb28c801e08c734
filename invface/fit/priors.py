"""The prior rows of the fits' least-squares objectives: the regulariser of Eq. 13, 15 and 16
and a sequence's temporal term, as (rows, Jacobian) over the fit vector z (``FitVector``)."""
from __future__ import annotations

import numpy as np


# The weights' L1 term: its slope is SPARSITY times the L2 regulariser's slope at weight 1 (so
# a control moves off 0 only where the data pull on it is stronger than that). With ARKit's 52
# controls an L2 prior alone lets the curves spread an expression, and the actor's identity,
# over many of them; the L1 term keeps a fit to the few the image asks for (paper 000 Fig. 6).
SPARSITY = 0.4


# The eyeLook controls' share of the weights' L2 and L1 terms where the plate's irises fix the
# gaze (``fit.curves.IRIS_CURVES``): a gaze is not an expression that the prior should hold at
# rest, and at the full Eq. 15 lambda_1 (60 px per unit weight) the prior outweighs the few
# pixels an iris moves, so the fitted gaze would stop short of the irises.
GAZE_PRIOR = 0.02

# The blink's share of Eq. 15's prior where the plate has both lids of that eye: a lid's curves
# are few points that travel little, so at the full lambda_1 the prior outweighs a whole blink
# and the curve stage fits a shut eye half open. eyeSquint and eyeWide keep the full prior: with
# theirs relieved too the fit opened and squinted the same eye at once on real photos.
LID_PRIOR = 0.1
LID_CONTROLS = ("eyeBlink",)


# The opposite pairs' (``arkit.OPPOSITES``) weight, as a share of the prior's lambda: a pair set
# to w each costs what one control at 2 w does under the full prior, whatever relief the pair
# has (the eyeLook controls' GAZE_PRIOR). Tuned on the split's tuned real photos
# (bench/history/2026-12.md).
OPPOSITE_PRIOR = 4.0
# keeps the pair rows smooth at (0, 0), in weight units
OPPOSITE_EPS = 0.01


def gaze_relief(vec, irises=True, lids=()):
    """(P,) factors on the controls' prior: GAZE_PRIOR on the eyeLook weights (with
    ``irises``), LID_PRIOR on the LID_CONTROLS of the sides in ``lids`` ("Left", "Right": the
    actor's own, whose both lid curves the plate has), 1 elsewhere."""
    f = np.ones(vec.P)
    names = vec.blendshape_names
    if irises:
        f[[i for i, n in enumerate(names) if n.startswith("eyeLook")]] = GAZE_PRIOR
    if lids:
        f[[i for i, n in enumerate(names) if n.startswith(LID_CONTROLS) and n.endswith(tuple(lids))]] = LID_PRIOR
    return f


def sparsity_slopes(vec, lam, kappa=SPARSITY, relief=None):
    """The L1 term's slopes c (vec.size,): kappa * lam on the blendshape weights (all >= 0),
    0 on the jaw and the pose, times ``relief`` (P,) when given (``gaze_relief``); the term is
    c . z (``dogleg.with_linear_term``)."""
    c = np.zeros(vec.size)
    c[vec.weights] = kappa * lam
    if relief is not None:
        c[vec.controls] *= relief
    return c


def temporal_prior(vec, previous, temporal):
    """A sequence's temporal term |(z - previous) / scales|^2 times ``temporal``: (centre
    previous (size,), row weights sqrt(temporal) / ``vec.scales()`` (size,)) for
    ``prior_rows``, or None when there is no previous frame or the weight is 0."""
    if previous is None or temporal <= 0:
        return None
    return np.asarray(previous, float), np.sqrt(temporal) / vec.scales()


def prior_rows(z, prior):
    """Rows w (z - c) (size,) of a prior (c, w) (``temporal_prior``) and their Jacobian diag(w)."""
    c, w = prior
    return w * (np.asarray(z, float) - c), np.diag(w)


def prior_units(vec):
    """(P,): the unit in which the prior measures each control: 1 for the blendshape weights and
    the jaw's hinge (rad), the bound of its range for the jaw's other five DOF
    (``rig.JAW_LOWER`` / ``JAW_UPPER``: 0.15 rad of yaw and roll, 8 mm of slide), so that a DOF at
    its bound costs what a weight of 1 does (ARKit's jawLeft/Right/Forward are those ratios). In
    rad and m they would be all but free (8 mm would cost what a weight of 0.008 does), and the
    curve fit could slide the jaw to its bounds to trace the head's outline."""
    from ..model.rig import JAW_LOWER, JAW_UPPER
    u = np.ones(vec.P)
    u[vec.jaw][1:] = np.maximum(np.abs(JAW_LOWER), np.abs(JAW_UPPER))[1:]
    return u


def opposite_rows(z, vec, lam):
    """Rows sqrt(lam OPPOSITE_PRIOR) h(w_a, w_b) (n,), one per opposite pair of the model's
    blendshapes (``vec.opposites``), and their Jacobian (n, vec.size). h = 2 a b / (a + b + eps),
    the pair's harmonic mean: w at a = b = w, about 2 min(a, b) where one dominates, 0 where
    either is; smooth, where min(a, b) is not. A face makes one control of a pair at a time, so
    the part they share is charged."""
    z = np.asarray(z, float)
    i, j = vec.opposites.T
    a, b = np.maximum(z[i], 0.0), np.maximum(z[j], 0.0)
    d = a + b + OPPOSITE_EPS
    s = np.sqrt(lam * OPPOSITE_PRIOR)
    J = np.zeros((len(i), vec.size))
    rows = np.arange(len(i))
    J[rows, i] = s * 2 * b * (b + OPPOSITE_EPS) / d ** 2
    J[rows, j] = s * 2 * a * (a + OPPOSITE_EPS) / d ** 2
    return s * 2 * a * b / d, J


def regulariser(z, vec, lam, center=None, relief=None, lam_opposite=None):
    """Rows and their Jacobian (n, vec.size) of the weights' prior: first sqrt(lam) (p - center)
    / units (P,), the lambda |w|^2 terms of Eq. 13 and 15 and Eq. 16's lambda_2 |w - w^|^2
    (center: default 0), each control in its ``prior_units``, ``relief`` (P,) factors on lam per
    control (``gaze_relief``); then the opposite pairs' rows (``opposite_rows``) at
    ``lam_opposite`` (default lam), n = P + len(vec.opposites)."""
    c = 0 if center is None else center
    s = np.sqrt(lam * (1.0 if relief is None else np.asarray(relief, float))) / prior_units(vec)
    J = np.zeros((vec.P, vec.size))
    J[:, vec.controls] = np.diag(np.broadcast_to(s, (vec.P,)))
    ro, Jo = opposite_rows(z, vec, lam if lam_opposite is None else lam_opposite)
    return np.concatenate([s * (np.asarray(z, float)[vec.controls] - c), ro]), np.vstack([J, Jo])
