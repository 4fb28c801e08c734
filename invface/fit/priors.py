"""The prior rows of the fits' least-squares objectives: the regulariser of Eq. 13, 15 and 16
and a sequence's temporal term, as (rows, Jacobian) over the fit vector z (``FitVector``)."""
from __future__ import annotations

import numpy as np


# The weights' L1 term: its slope is SPARSITY times the L2 regulariser's slope at weight 1 (so
# a control moves off 0 only where the data pull on it is stronger than that). With 51 ARKit
# controls an L2 prior alone lets the curves spread an expression, and the actor's identity,
# over many of them; the L1 term keeps a fit to the few the image asks for (paper 000 Fig. 6).
SPARSITY = 0.4


def sparsity_slopes(vec, lam, kappa=SPARSITY):
    """The L1 term's slopes c (vec.size,): kappa * lam on the blendshape weights (all >= 0),
    0 on the jaw and the pose; the term is c . z (``dogleg.with_linear_term``)."""
    c = np.zeros(vec.size)
    c[vec.weights] = kappa * lam
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


def regulariser(z, vec, lam, center=None):
    """Rows sqrt(lam) (p - center) (P,) and their Jacobian (P, vec.size): the lambda |w|^2
    terms of Eq. 13 and 15 and Eq. 16's lambda_2 |w - w^|^2 (center: default 0)."""
    c = 0 if center is None else center
    J = np.zeros((vec.P, vec.size))
    J[:, vec.controls] = np.sqrt(lam) * np.eye(vec.P)
    return np.sqrt(lam) * (np.asarray(z, float)[vec.controls] - c), J
