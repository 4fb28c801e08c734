"""The actor's identity from the curves of one plate or of several frames: a smooth correction
of the model's neutral.

A model built from another face (the template, or an actor scanned once) leaves a fixed gap to
the person in a clip: lid and lip shapes the controls cannot make, since the blendshapes and
muscles change an expression, not a face: on a real clip the curve RMS then sits at one level
on every frame, flat over time. Paper 000 starts from an actor
model built from a scan of that actor (paper 001); from video alone, the neutral-looking frame
the calibration is made on (Eq. 14) stands in for the scan. With that frame's controls and pose
from Eq. 15 held, the neutral moves by a displacement field d (V,3) m minimising

    sum_i r_i(d)^2 + mu * int |Delta d|^2 dA + eps * int |d|^2 dA

r_i: Eq. 15's signed pixel distances of the model curves' vertices to the plate curves;
Delta: the surface's finite-volume Laplacian (``morph.surface.fv_laplacian``), so the field is
smooth over ``IDENTITY_LENGTH`` and cannot copy the frame's pixel noise into the face; the
small eps term keeps the field near zero where no curve is (the depth along the view is only
known through the smoothness). Gauss-Newton on the foot points, each step one sparse solve.

Before the field, the neutral moves in a face-shape space, where the model has one
(``morph.identity_space``: ICT-FaceKit's 20 identity shapes S_i, in standard deviations), by
sum_i c_i S_i under the Gaussian prior |c|^2 n IDENTITY_PRIOR_PX^2 (n residuals: a coefficient at
1 sd costs as much as all the curves at that RMS). From one frontal view the curves see no
depth; the space moves the depth with the outline as real faces do. It is fitted jointly with
the head's proportions, smooth over the whole head (paper 001 morphs a
template onto a face the same way, global shape first): the neutral about the curves' centre
c, with y = (Y - c_y) / 0.1 m,

    x' = x e^a (1 + t y),   y' = y e^b (1 + v y),   z' = z e^((a + b)/2)

(width and its taper with height, height and the lower face's against the upper face's;
the depth, not seen from the front, follows the mean scale). Faces differ most in these: on
the real photos the field alone moved every curve by 4-8 mm and the jaw line by up to 15 mm.
Each parameter is held near zero by a prior that costs as much as the curves' pixels at 1 px
when it reaches ``IDENTITY_MAX_SCALE``. The jaw line is a silhouette: the face's outline, where
the surface turns away, not a line of fixed vertices. It steers the proportions fully but the
field only at ``SILHOUETTE_WEIGHT``: at full weight the field pulled the outline's vertices out
alone, into lumps at the cheeks of a round face (13 mm at ear height). On the real clip's frames
not fitted this costs 0.06 px against full weight; on 0-f15-hao it leaves the lumps small.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from ..errors import InvfaceError
from ..model.rig import euler_xyz
from .curves import CurveObjective, rms_px
from ..model.pose import pose_points

IDENTITY_LENGTH = 0.007     # m: the smoothness scale of the identity field (a third of an eye's width;
                            # on the real clip 0.012 left 2.05 px on frames not fitted, 0.007 1.9 px)
IDENTITY_ANCHOR = 0.06      # m: beyond this from the curves the field fades to zero
IDENTITY_MAX_MM = 20.0      # a larger field (after the proportions) is not an identity: not applied (wrong frame or
                            # curves); on the real photos the fields reach 7-12 mm
IDENTITY_MAX_SCALE = 0.15   # the proportions' prior: each parameter's +- this costs as much as the curves at 1 px
IDENTITY_PRIOR_PX = 0.15    # the shape space's prior: a coefficient at 1 sd costs as much as the curves at this RMS
SILHOUETTES = ("jaw_line",)  # outline curves: they steer the proportions, and the field only weakly,
SILHOUETTE_WEIGHT = 0.3      # with this weight on their squared residuals


@dataclass
class IdentityFit:
    """displacement (V,3) m of the neutral (the face-shape space, the proportions and the field
    together); rms_before / rms_after px of all the curves on the fitting frames; proportions
    (4,): (a, b, t, v) of the module's docstring; max_mm: the field's largest vertex
    displacement beyond the space and the proportions; coefficients (K,): the face-shape
    space's (``morph.identity_space``), in standard deviations (empty where the model has
    no space); views: how many frames it was fitted on."""
    displacement: np.ndarray
    rms_before: float
    rms_after: float
    max_mm: float
    proportions: np.ndarray
    coefficients: np.ndarray = field(default_factory=lambda: np.zeros(0))
    views: int = 1

    def describe(self):
        a, b = self.proportions[:2]
        space = (f"the face-shape space at {np.linalg.norm(self.coefficients):.2f} sd "
                 f"(largest c{int(np.argmax(np.abs(self.coefficients)))} "
                 f"{self.coefficients[np.argmax(np.abs(self.coefficients))]:+.2f}), "
                 if len(self.coefficients) else "")
        frames = "the fitting frame" if self.views == 1 else f"the {self.views} fitting frames"
        return (f"identity from the curves: curve RMS {self.rms_before:.2f} -> {self.rms_after:.2f} px on "
                f"{frames}; {space}face width x{np.exp(a):.3f}, height x{np.exp(b):.3f}, then moved up to "
                f"{self.max_mm:.1f} mm")


def curve_data(x, rotation, translation, bias=None):
    """The curve term of the surface x (V,3) m posed by rotation (3,) rad and translation (3,) m,
    as a function ``data(d, *objs)`` of a neutral correction d (V,3) m (posed with the head), objs:
    (CurveObjective, weight) pairs: (signed distances (n,) px, their gradient (V,3) of 1/2 |r|^2,
    per curve (vertex ids (m,), d r / d d (n_b,m,3)), in the order of the rows). ``bias``
    {curve: (n,) px} is subtracted from the signed distances (``detector_bias``)."""
    R = euler_xyz(np.asarray(rotation, float))
    bias = bias or {}

    def data(d, *objs):
        xr = pose_points(x + d, rotation, translation)
        rows, g, blocks = [np.zeros(0)], np.zeros(x.shape), []
        for obj, w in objs:
            for name, (vid, r, dr_dx) in zip(obj.curves, obj.signed(xr)):
                b = bias.get(name)
                r = r - b if b is not None and len(b) == len(r) else r
                r, a = np.sqrt(w) * r, np.sqrt(w) * dr_dx @ R
                np.add.at(g, vid, np.einsum("n,nmi->mi", r, a))
                rows.append(r)
                blocks.append((vid, a))
        return np.concatenate(rows), g, blocks
    return data


def detector_bias(model, camera, curves, p, rotation, translation, detect):
    """{curve: (n,) px}: the signed offsets of the detector's curves from the model's own on a
    render of the model at controls p (P,), posed by rotation (3,) rad and translation (3,) m,
    through ``camera`` (studio light, the model's skin albedo): on a face the model fits
    exactly, what the detector's habits add (where its face oval and nose base lie against the
    model's outline and nose), which the face-shape space could take for a face
    (``bench/identity_3d.py`` fits with and without them). ``detect(image_srgb)`` ->
    {curve: (n,2) px} or None (no face); the curves of ``curves`` it does not give have no
    bias."""
    from ..io.images import linear_to_srgb
    from ..render.synthetic import render_plate, skin_albedo, studio_light
    from .curves import CurveObjective
    sm = model.surface_model("blendshape")
    x = sm.surface(np.asarray(p, float))
    image, _ = render_plate(model, x, camera, studio_light(), skin_albedo(model), rotation, translation, noise=0.0,
                            spp=16, parts_x=model.parts_positions(np.asarray(p, float)))
    found = detect(linear_to_srgb(image))
    if not found:
        return {}
    obj = CurveObjective(model, sm, camera, {k: v for k, v in found.items() if k in curves}, 0.0)
    xr = pose_points(x, rotation, translation)
    return {name: r for name, (_, r, _) in zip(obj.curves, obj.signed(xr))}


def _operators(model):
    from ..morph.surface import fv_laplacian
    A, area = fv_laplacian(model.neutral, model.triangles)
    Minv = sp.diags(1.0 / np.maximum(area, 1e-30))
    return (A @ Minv @ A).tocsr(), sp.diags(area)


@dataclass
class IdentityView:
    """One frame the identity is fitted on: its ``camera``, curves {name: (n,2) px}, the
    controls p (P,) and pose (rotation (3,) rad, translation (3,) m) of Eq. 15 on it, and the
    curve source's own offsets ``bias`` {curve: (n,) px} (``detector_bias``; None for drawn
    curves). The identity is shared by the views; expression and pose are each view's own."""
    camera: object
    curves: dict
    p: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    bias: dict | None = None


def fit_identity(model, camera, curves, p, rotation, translation, iterations=6, length=IDENTITY_LENGTH,
                 silhouette=SILHOUETTE_WEIGHT, space=False, bias=None):
    """Smooth neutral correction (IdentityFit) so that the model at controls p (P,), posed by
    rotation (3,) rad and translation (3,) m, meets the plate curves {name: (n,2) px} seen by
    ``camera``: one view of ``fit_identity_views``, whose docstring gives the terms."""
    return fit_identity_views(model, [IdentityView(camera, curves, p, rotation, translation, bias)],
                              iterations=iterations, length=length, silhouette=silhouette, space=space)


def fit_identity_views(model, views, iterations=6, length=IDENTITY_LENGTH, silhouette=SILHOUETTE_WEIGHT,
                       space=False):
    """Smooth neutral correction (IdentityFit) shared by ``views`` (IdentityView, each frame
    with its own controls and pose), so that the model meets every view's curves: with
    ``space``, the face-shape space (where the model has one, ``morph.identity_space``) with
    the proportions, else the proportions alone; then the field. Several views with different
    head poses pin the depth that one frontal view leaves to the space's prior: the views'
    residuals add, while the priors stay those of one view (a prior on the face, not on each
    frame). The weight mu of the field's bi-Laplacian is set per view so that a correction of
    width ``length`` (m) costs as much as a pixel at each of the vertices of a curve across
    it: mu = (k length)^2 n_per_length, with k the camera's px per metre at the face, summed
    over the views; ``silhouette``: the weight of the outline curves (``SILHOUETTES``) in the
    field. Curve RMS before and after are over all the views' curves."""
    views = list(views)
    if not views:
        raise InvfaceError("identity: no frame to fit the identity on")
    sm = model.surface_model("blendshape")
    terms = [_view_terms(model, sm, v, length) for v in views]
    if not any(inner.curves or outline.curves for _, inner, outline, _ in terms):
        raise InvfaceError("identity: none of the plate curves is a model curve")
    V = len(model.neutral)
    every = _joint([(data, ((inner, 1.0), (outline, 1.0))) for data, inner, outline, _ in terms])
    field_data = _joint([(data, ((inner, 1.0), (outline, silhouette))) for data, inner, outline, _ in terms])

    n0 = np.asarray(model.neutral, float)
    r0 = every(0.0)[0]
    c = n0[np.concatenate([v for _, inner, outline, _ in terms for obj in (inner, outline)
                           for v in obj.vertices.values()])].mean(0)
    from ..morph.identity_space import identity_shapes
    S = identity_shapes(model) if space else None
    D, q, coef = _global_shape(n0, c, np.zeros((0, V, 3)) if S is None else S, every, views=len(views))
    d = np.zeros((V, 3))
    mu = sum(m for *_, m in terms)
    if mu > 0:
        K, M = _operators(model)
        reg = sp.kron(mu * K + mu / IDENTITY_ANCHOR ** 4 * M, sp.eye(3)).tocsr()
        d = _field(field_data, D, reg, V, iterations)
    rms = lambda r: rms_px({"all": r})         # noqa: E731
    return IdentityFit(D + d, rms(r0), rms(every(D + d)[0]),
                       float(np.linalg.norm(d, axis=1).max() * 1e3), q, coef, len(views))


def _view_terms(model, sm, view, length=IDENTITY_LENGTH):
    """One view's (curve data of ``curve_data``, inner CurveObjective, outline CurveObjective,
    its share mu of the field's weight (0 without inner curves))."""
    curves = view.curves
    inner = CurveObjective(model, sm, view.camera, {k: v for k, v in curves.items() if k not in SILHOUETTES}, 0.0)
    outline = CurveObjective(model, sm, view.camera, {k: v for k, v in curves.items() if k in SILHOUETTES}, 0.0)
    x = sm.surface(np.asarray(view.p, float))
    mu = 0.0
    if inner.curves:
        cam = view.camera
        depth = float(np.median((pose_points(x, view.rotation, view.translation) @ cam.R.T + cam.t)[:, 2]))
        k = float(cam.K[0, 0]) / max(depth, 1e-6)                       # px per metre at the face
        spacing = float(np.median([np.linalg.norm(np.diff(x[v], axis=0), axis=1).mean()
                                   for v in inner.vertices.values()]))
        mu = (k * length) ** 2 * (length / spacing)
    return curve_data(x, view.rotation, view.translation, view.bias), inner, outline, mu


def _joint(parts):
    """The curve term of several views as one ``data(d)``: parts: (a view's ``curve_data``,
    its (CurveObjective, weight) pairs); rows and blocks in the views' order, gradients added."""
    def data(d):
        rows, g, blocks = [], 0.0, []
        for view_data, objs in parts:
            r, gv, b = view_data(d, *objs)
            rows.append(r)
            g = g + gv
            blocks += b
        return np.concatenate(rows), g, blocks
    return data


def _field(data, D, reg, V, iterations):
    """The field d (V,3) m on top of the global shape D (V,3) m: Gauss-Newton on the curve term
    ``data`` with the regulariser ``reg`` (3V,3V), one sparse solve per step."""
    d = np.zeros((V, 3))
    _, g, blocks = data(D)
    # the data Jacobian's pattern (rows: residuals, columns: 3 vid + axis), the same every step
    first = np.cumsum([0] + [len(a) for _, a in blocks])
    rows = np.concatenate([np.broadcast_to((f + np.arange(len(a)))[:, None, None], a.shape).ravel()
                           for f, (_, a) in zip(first, blocks)])
    cols = np.concatenate([np.broadcast_to(3 * v[None, :, None] + np.arange(3), a.shape).ravel()
                           for v, a in blocks])
    for _ in range(iterations):
        A = sp.csr_matrix((np.concatenate([a.ravel() for _, a in blocks]), (rows, cols)), shape=(first[-1], 3 * V))
        H = reg + (A.T @ A).tocsr()
        step = spsolve(H.tocsc(), -(reg @ d.ravel() + g.ravel())).reshape(V, 3)
        d = d + step
        _, g, blocks = data(D + d)
        if np.abs(step).max() < 1e-6:
            break
    return d


def _global_shape(x, c, S, data, iterations=10, step=1e-4, views=1):
    """The face-shape space's coefficients and the proportions (module docstring) for the neutral
    x (V,3) m about c (3,), jointly: (their displacement (V,3) m, the proportions (4,), the
    coefficients (K,)). S (K,V,3) m: the space's shapes (K may be 0); ``data(d)``: the curves'
    (residuals (n,) px, gradient, blocks (vertex ids (m,), d r / d d (n_b,m,3))) of a
    displacement d (V,3), over ``views`` frames. Gauss-Newton with the coefficients' Jacobian
    from the blocks and the proportions' by finite differences; the priors cost
    |c|^2 n IDENTITY_PRIOR_PX^2 (a Gaussian, the shapes being in standard deviations) and
    |q|^2 n / ln(1 + IDENTITY_MAX_SCALE)^2, with n the residuals of one view (their count over
    the views divided by ``views``)."""
    K = len(S)
    theta = np.zeros(K + 4)
    proportions = _proportion_field(x, c)

    def displacement(t):
        return np.tensordot(t[:K], S, axes=1) + proportions(t[K:])

    r, _, blocks = data(displacement(theta))
    prior = len(r) / views * np.concatenate([np.full(K, IDENTITY_PRIOR_PX ** 2),
                                     np.full(4, 1 / np.log1p(IDENTITY_MAX_SCALE) ** 2)])
    for _ in range(iterations):
        J = np.zeros((len(r), K + 4))
        if K:
            J[:, :K] = space_jacobian(blocks, S)
        for j in range(4):
            t = theta.copy()
            t[K + j] += step
            J[:, K + j] = (data(displacement(t))[0] - r) / step
        dt = np.linalg.solve(J.T @ J + np.diag(prior), -(J.T @ r + prior * theta))
        theta = theta + dt
        r, _, blocks = data(displacement(theta))
        if np.abs(dt).max() < 1e-6:
            break
    return displacement(theta), theta[K:], theta[:K]


def space_jacobian(blocks, S):
    """d r / d c (n,K) px per sd: the curve residuals' blocks (vertex ids (m,), d r / d d
    (n_b,m,3)), in the order of their rows, against the shapes S (K,V,3) m."""
    return np.concatenate([np.einsum("nmj,kmj->nk", a, S[:, vid]) for vid, a in blocks])


def _proportion_field(x, c):
    """The proportions' displacement (V,3) m of the neutral x (V,3) m about c (3,) as a
    function of (a, b, t, v) (module docstring)."""
    u = x - c
    y = u[:, 1] / 0.1

    def displacement(q):
        a, b, t, v = q
        return np.stack([u[:, 0] * np.exp(a) * (1 + t * y), u[:, 1] * np.exp(b) * (1 + v * y),
                         u[:, 2] * np.exp(0.5 * (a + b))], 1) - u
    return displacement
