"""Split the jaw's rigid motion out of an actor's imported jaw blendshapes.

The hybrid rig (paper 000 Eq. 1-2) is x(b, j) = T(j)(n + B b): the jaw's rotation belongs
to the skinning transform T(j), and a blendshape holds only what skinning cannot do. An
imported ARKit ``jawOpen`` (or FACS AU26/27, ``jawLeft``...) has the jaw's rotation baked
into its offsets; kept as it is, the rig would open the mouth linearly, and the muscle
simulation (whose jaw bone follows j, not b) would be asked to open the skin around a
closed jaw. So, for each jaw shape, the jaw parameters j_k (6,) are fitted so that the
model's own skinning explains as much of the shape as it can (bounded least squares on
sum_v |T(j)(n_v) - (n_v + D_v)|^2 over the vertices that carry the scan's data, j within
the jaw's range that the fits keep to: a split jaw outside it is one that no fit of the
imported shape could reach), and the
shape is replaced by its unskinned remainder d_k: T(j_k)(n + d_k) equals the imported shape
exactly, and j_k is stored as the shape's paired jaw (meta['blendshape_jaw']), as the
template's own jawOpen has.

Unsplit (j = 0), an imported jaw-opening shape is a soft-tissue offset of centimetres that
Newton cannot follow; split, the simulation follows the imported shape closely
(bench/jaw_split.py measures it on ICT-FaceKit's jawOpen). A rigid fit of the chin skin alone
finds a jaw with more translation than a real jaw has, which the simulation follows less
closely.
"""
from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from ..model.rig import JAW_LOWER, JAW_UPPER, jaw_transform_derivatives, skin, skin_derivatives
from ..template.expressions import unskin

JAW_FACS = ("AU26", "AU27", "AU29", "AU30")   # jaw drop, mouth stretch, jaw thrust, sideways


def is_jaw_shape(name):
    """True for blendshape names that move the jaw: jaw* (ARKit jawOpen, jawLeft, jawRight,
    jawForward; the template's jawOpen) and FACS AU26, AU27, AU29, AU30."""
    return name.lower().startswith("jaw") or name.upper().split("_")[0] in JAW_FACS


def fit_jaw(model, shape, use):
    """Jaw parameters (6,) whose skinning T(j)(n) best matches ``shape`` (V,3) m on the
    vertices ``use`` (V,) bool: least squares from j = 0 within the jaw's range
    (``model.rig.JAW_LOWER``/``JAW_UPPER``, the bounds the fits keep to)."""
    n, w = model.neutral[use], model.jaw_weights[use]
    no_shapes = np.zeros((0,) + n.shape)       # skin_derivatives' blendshape part, unused

    def residual(j):
        return (skin(n, w, model.jaw_matrix(j)) - shape[use]).ravel()

    def jacobian(j):
        dM = jaw_transform_derivatives(j, model.jaw_pivot, model.jaw_frame)
        return skin_derivatives(n, w, model.jaw_matrix(j), no_shapes, dM).reshape(6, -1).T

    return least_squares(residual, np.zeros(6), jac=jacobian, bounds=(JAW_LOWER, JAW_UPPER),
                         xtol=1e-12, ftol=1e-12, gtol=1e-12).x


def split_jaw(model, names, deltas, known=None):
    """Jaw shapes among ``names`` with their rigid jaw motion moved into jaw parameters.

    model: the new FaceModel (neutral (V,3) m, jaw_weights (V,), jaw pivot and frame).
    deltas (K,V,3) m: the imported shapes' offsets on the model's surface.
    known (V,) bool: vertices that carry the scan's own data (the rest was extended), or None.
    Returns (deltas (K,V,3) with the jaw shapes unskinned, {name: jaw (6,) list} for every
    name (zeros for the others), {name: {"jaw": ..., "mean_before_mm", "mean_after_mm"}}
    for the split shapes: the mean offset over the fitted vertices before and after).
    """
    n = model.neutral
    use = model.jaw_weights > 0
    if known is not None:
        use &= known
    out, jaws, stats = np.array(deltas, float), {k: [0.0] * 6 for k in names}, {}
    if use.sum() < 10:                     # no skin carries the jaw: nothing to fit
        return out, jaws, stats
    for k, name in enumerate(names):
        if not is_jaw_shape(name):
            continue
        j = fit_jaw(model, n + out[k], use)
        before = np.linalg.norm(out[k][use], axis=1).mean()
        out[k] = unskin(n + out[k], model.jaw_weights, model.jaw_matrix(j)) - n
        jaws[name] = j.tolist()
        stats[name] = {"jaw": [round(float(v), 4) for v in j], "mean_before_mm": float(before * 1000),
                       "mean_after_mm": float(np.linalg.norm(out[k][use], axis=1).mean() * 1000)}
    return out, jaws, stats
