"""Curve fitting to a plate: paper 000, Eq. 15.

    min_{w^, theta, t}  || E_1(w^) ||^2 + lambda_1 || w^ ||^2,      lambda_1 = 3600

E_1 stacks, for every vertex of the model's named 3D curves (``model.curves``: eyelids and
lips by default), the 2D Euclidean distance in pixels between its projection into the plate
and the plate's curve of the same name (a polyline drawn by a roto artist, or found by a
landmark detector). Each residual is the signed distance along the direction in which it
grows (the segment normal at the foot point), so its Jacobian is exact where the foot point
is interior; with the full 2D difference vector and a fixed foot point, Gauss-Newton stalled
(the tangential part predicts decreases that sliding along the curve never gives). The rigid pose is
solved with the controls; its start comes from OpenCV's solvePnP on the curves resampled
by arc length.

Plate curve file (JSON, pixels, OpenCV convention: (0, 0) is the centre of the top-left
pixel)::

    {"image_size": [720, 540],                       # optional; checked against the plate
     "curves": {"lip_outer_upper": [[u, v], ...], "eye_L_upper": [[u, v], ...], ...}}
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InvfaceError
from ..io.jsonfile import read_object
from ..io.schema import Fields
from ..mesh.sections import resample_even as resample
from ..model.controls import FitVector
from .dogleg import dogleg, with_linear_term
from .lambdas import EQ15_ANCHOR_LAMBDA, EQ15_LAMBDA_1, EQ15_TRACK_LAMBDA
from ..model.gaze import Eyes
from ..model.pose import pose_points, posed_jacobian, posed_surface
from ..model.rig import euler_xyz, euler_xyz_derivatives
from .priors import gaze_relief, prior_rows, regulariser, sparsity_slopes, temporal_prior

PLATE_CURVES = ("lip_outer_upper", "lip_outer_lower", "lip_inner_upper", "lip_inner_lower",
                "eye_L_upper", "eye_L_lower", "eye_R_upper", "eye_R_lower")
# Curves the template snaps to the skin's nearest vertices (``template.features.frontal_curve``,
# ``curve_from_points``): they run in a staircase about half a grid cell high, 1-3 px on a
# 512 px photo. Their points are smoothed along the curve, ends held; the eyelid and inner lip
# curves follow the slits' own vertex rows and are used as they are. On the five real photos'
# fits, 4 passes took the outer lips 2.14 -> 1.36 px, the nostril base 1.76 -> 1.09 px and the jaw
# line 2.13 -> 1.89 px before any refit; the slit curves got worse (their corners shrink).
SNAPPED_CURVES = frozenset({"lip_outer_upper", "lip_outer_lower", "nose_base", "jaw_line", "brow_L", "brow_R"})
SMOOTHING_PASSES = 4
# Eq. 15's solves stop when an accepted step lowers the cost (px^2) by less than this fraction.
# The curve residuals are piecewise smooth (closest points change segment), so near the
# optimum the trust region shrinks to ~1e-5 and the default 1e-10 let the pose pass crawl
# for its 200 iterations on a real photo.
CURVE_FTOL = 1e-6
# The irises: a plate "curve" per eye of its iris's points (the detector's centre and four limbus
# points, MediaPipe 468-477), whose mean is matched to the model's pupil centre (``model.gaze``),
# each taken from its eye's corners (``CurveObjective.iris_terms``): they set the eyeLook
# controls' gaze. Each eye's two residuals (px) weigh as many rows as a lid's
# curve has points, so the gaze counts as much as a lid.
IRIS_CURVES = ("iris_L", "iris_R")
IRIS_WEIGHT = 3.0


def curve_weights(name, n):
    """(n, n): the points of the model curve ``name`` of n vertices as weighted sums of its vertices
    (rows sum to 1, so they commute with the head's pose). The binomial filter (1/4, 1/2, 1/4),
    ``SMOOTHING_PASSES`` times with the ends held, for ``SNAPPED_CURVES``; the identity otherwise."""
    W = np.eye(n)
    if name in SNAPPED_CURVES and n > 2:
        K = np.eye(n)
        i = np.arange(1, n - 1)
        K[i, i], K[i, i - 1], K[i, i + 1] = 0.5, 0.25, 0.25
        for _ in range(SMOOTHING_PASSES):
            W = K @ W
    return W


def curve_points(model, name, x):
    """(n, 3) m: the points of the model curve ``name`` on the surface x (V, 3) (``curve_weights``)."""
    v = np.asarray(x)[np.asarray(model.curves[name])]
    return curve_weights(name, len(v)) @ v


def read_curves(path, model, image_size=None):
    """{name: (n, 2) float px} from a plate curve file; names must be model curves."""
    f = Fields(read_object(path, what="curve file"), path, listing='{"curves": {name: [[u, v], ...]}, "image_size": '
               '[width, height]}')
    curves = f.mapping("curves")
    if not curves.data:
        f.fail("curves", "is empty")
    unknown = sorted(set(curves.data) - set(model.curves) - set(IRIS_CURVES))
    if unknown:
        raise InvfaceError(f"{path}: unknown curve name(s) {unknown}; the model's curves are "
                           f"{sorted(model.curves)}")
    size = f.array("image_size", (2,), default=None)
    if size is not None and (np.any(size <= 0) or np.any(size != np.round(size))):
        f.fail("image_size", f"is {size.tolist()}, not [width, height] in whole pixels: fix it or leave it out")
    if image_size is not None and size is not None and size.astype(int).tolist() != list(image_size):
        raise InvfaceError(f"{path}: curves were drawn on a {size.astype(int).tolist()} image, the plate is "
                           f"{list(image_size)}")
    out = {}
    for name in curves.data:
        a = curves.array(name, (None, 2))
        if len(a) < 2:
            curves.fail(name, "needs at least 2 [u, v] points")
        out[name] = a
    return out


def feature_of(name):
    """The facial feature a plate curve belongs to: 'lips', 'eye_L', 'eye_R', 'brow_L',
    'brow_R', 'nose', or the curve's own name (jaw_line, profile)."""
    if name.startswith("lip"):
        return "lips"
    if name in IRIS_CURVES:
        return "eye" + name[4:]
    if name.startswith(("eye_", "brow_")):
        return name[:name.index("_", 4)] if name.count("_") > 1 else name
    if name.startswith("nose"):
        return "nose"
    return name


def check_curves(curves, image_size, name="curves"):
    """Refuse plate curves that cannot belong to the plate, and say what a pose from them
    cannot know. curves: {name: (n, 2) px}; image_size: (width, height) px. Raises
    InvfaceError naming ``name`` when a curve has most of its points outside the image (more
    than 2 px beyond its border: drawn on another image, or in other units). Returns warnings
    (strings): the curves cover fewer than three facial features (a single curve, or only the
    lips, leaves the head's rotation and depth free to trade against the expression)."""
    w, h = image_size
    for c, a in curves.items():
        a = np.asarray(a, float)
        out = (a[:, 0] < -2) | (a[:, 0] > w + 1) | (a[:, 1] < -2) | (a[:, 1] > h + 1)
        if out.mean() > 0.5:
            raise InvfaceError(f"{name}: curve '{c}' lies outside the {w}x{h} plate ({int(out.sum())} of "
                               f"{len(a)} points, e.g. [{a[out][0][0]:.1f}, {a[out][0][1]:.1f}] px): were the "
                               "curves drawn on another image?")
    features = sorted({feature_of(c) for c in curves})
    if len(features) < 3:
        return [f"{name}: the {len(curves)} curve(s) cover {len(features)} facial feature(s) ({', '.join(features)}); "
                "the head's pose from them is uncertain (rotation and depth trade against the expression): "
                "draw curves on at least three features (lips, both eyes) or pass a calibration's pose"]
    return []


def write_curves(path, curves, image_size=None):
    """Write a plate curve file ({name: (n, 2) px})."""
    from ..io.jsonfile import write_object
    data = {"curves": {k: np.round(np.asarray(v, float), 3).tolist() for k, v in curves.items()}}
    if image_size is not None:
        data["image_size"] = [int(s) for s in image_size]
    write_object(path, data, indent=None)


def closest_on_polyline(points, poly, normals=False):
    """Closest points (n, 2) on the polyline ``poly`` (m, 2) to ``points`` (n, 2); with
    ``normals`` also the unit direction (n, 2) along which the distance grows: the segment's
    normal at an interior foot point, the direction from a vertex of the polyline otherwise."""
    a, b = poly[:-1], poly[1:]
    d = b - a
    t = np.einsum("nsk,sk->ns", points[:, None, :] - a[None], d) / np.maximum((d * d).sum(1), 1e-30)
    tc = np.clip(t, 0, 1)
    q = a[None] + tc[..., None] * d[None]                                     # (n, s, 2)
    k = np.argmin(((q - points[:, None, :]) ** 2).sum(-1), 1)
    i = np.arange(len(points))
    foot = q[i, k]
    if not normals:
        return foot
    seg = d[k] / np.maximum(np.linalg.norm(d[k], axis=1, keepdims=True), 1e-30)
    nrm = np.stack([-seg[:, 1], seg[:, 0]], 1)
    off = points - foot
    nrm *= np.where((off * nrm).sum(1) < 0, -1.0, 1.0)[:, None]
    dist = np.linalg.norm(off, axis=1, keepdims=True)
    at_vertex = (tc[i, k] <= 0) | (tc[i, k] >= 1)
    nrm = np.where(at_vertex[:, None] & (dist > 1e-12), off / np.maximum(dist, 1e-30), nrm)
    return foot, nrm


def projection_jacobian(camera, xr):
    """Pixels (n, 2) of world points xr (n, 3) (``Camera.project``) and d pixel / d x (n, 2, 3)."""
    uv, _ = camera.project(xr)
    X, Y, Z = (xr @ camera.R.T + camera.t).T
    K = camera.K
    dcam = np.zeros((len(xr), 2, 3))             # d (u, v) / d (X, Y, Z) in the camera frame
    dcam[:, 0, 0], dcam[:, 0, 1] = K[0, 0] / Z, K[0, 1] / Z
    dcam[:, 0, 2] = -(K[0, 0] * X + K[0, 1] * Y) / Z ** 2
    dcam[:, 1, 1], dcam[:, 1, 2] = K[1, 1] / Z, -K[1, 1] * Y / Z ** 2
    return uv, dcam @ camera.R


def rms_px(residual_px):
    """RMS (px) over all curves of {name: (n,) pixel distances}; 0 with no curves."""
    r = np.concatenate(list(residual_px.values())) if residual_px else np.zeros(1)
    return float(np.sqrt(np.mean(r ** 2)))


@dataclass
class CurveFit:
    """Eq. 15 result: controls p, pose, pixel residuals per curve, the dogleg log."""

    p: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    residual_px: dict
    history: list = field(default_factory=list)
    status: str = ""
    tracked: np.ndarray = None     # controls (P,) of the pose pass (None without one)
    iris_px: dict = field(default_factory=dict)    # {iris curve: (1,) px pupil to plate iris}

    @property
    def rms_px(self):
        return rms_px(self.residual_px)


class CurveObjective:
    """z -> (E_1 (n,) px with the lambda_1 rows, Jacobian) for named plate curves."""

    def __init__(self, model, surface_model, camera, curves, lam, prior=None):
        self.model, self.sm, self.camera, self.lam = model, surface_model, camera, lam
        self.prior = prior          # (centre z (size,), row weights (size,)): rows weight * (z - centre)
        self.vec = FitVector.of(model)
        self.curves = {k: v for k, v in curves.items() if k in model.curves}
        self.vertices = {k: np.asarray(model.curves[k]) for k in self.curves}
        self.weights = {k: curve_weights(k, len(v)) for k, v in self.vertices.items()}
        eyes = Eyes(model)
        self.eyes = eyes if len(eyes.sides) == 2 else None
        lids = [f"eye_{s}_upper" for s in ("L", "R")]
        self.irises = {e: np.asarray(curves[k], float).mean(0) for e, k in enumerate(IRIS_CURVES)
                       if k in curves and lids[e] in curves and self.eyes is not None}
        # each eye's corners: the model's upper lid's end vertices, the plate's lid's end points' midpoint
        self.corners = {e: (np.asarray(model.curves[lids[e]])[[0, -1]],
                            np.asarray(curves[lids[e]], float)[[0, -1]].mean(0)) for e in self.irises}
        # the irises fix the gaze, and an eye's two lid curves its blink (Eq. 15 only: ``gaze``
        # is the relief without the lids, for Eq. 16, whose image term does not see the eyes)
        lids = [side for s, side in (("L", "Left"), ("R", "Right"))
                if f"eye_{s}_upper" in self.curves and f"eye_{s}_lower" in self.curves]
        self.relief = gaze_relief(self.vec, bool(self.irises), lids) if self.irises or lids else None
        self.gaze = gaze_relief(self.vec) if self.irises else None

    def residuals(self, xr):
        """{name: (n, 2) projected-minus-closest px} at posed vertices xr (V, 3)."""
        out = {}
        for name, poly in self.curves.items():
            uv, _ = projection_jacobian(self.camera, self.weights[name] @ xr[self.vertices[name]])
            out[name] = uv - closest_on_polyline(uv, poly)
        return out

    def __call__(self, z):
        xr, Jall = posed_jacobian(self.sm, z, self.vec)
        rows, jac = self.rows(xr, Jall)
        if self.irises:
            r, J = self.iris_rows(z, xr, Jall)
            rows, jac = rows + [r], jac + [J]
        reg, Jreg = regulariser(z, self.vec, self.lam, relief=self.relief)
        rows, jac = rows + [reg], jac + [Jreg]
        if self.prior is not None:
            rp, Jp = prior_rows(z, self.prior)
            rows.append(rp)
            jac.append(Jp)
        return np.concatenate(rows), np.vstack(jac)

    def pupils_px(self, z):
        """(pixels (2, 2) of the model's pupil centres at z, d pixel / dz (2, 2, z size))."""
        p, th, t = self.vec.unpack(z)
        X, JX = self.eyes.pupils(p)
        R = euler_xyz(th)
        uv, duv = projection_jacobian(self.camera, X @ R.T + t)
        dX = np.concatenate([JX @ R.T, np.einsum("kij,ej->eki", euler_xyz_derivatives(th), X),
                             np.broadcast_to(np.eye(3), (2, 3, 3))], 1)            # (2, z size, 3)
        return uv, np.einsum("eij,ekj->eik", duv, dX)

    def iris_terms(self, z, xr):
        """The gaze rows: per eye, IRIS_WEIGHT x ((model pupil - model corners' midpoint) -
        (plate iris centre - plate corners' midpoint)) px, the corners being the ends of the
        eye's upper lid curve: the iris's place in the eye, which the eye's size and spacing
        do not bias. Returns (rows (2 e,), d rows / dz through the pupils (2 e, z size), the
        corner vertex ids (2 e, 2), d rows / d their posed positions (2 e, 2, 3)), for the eyes
        whose irises and upper lids the plate has."""
        uv, J = self.pupils_px(z)
        rows, jac, vids, dx = [], [], [], []
        for e in sorted(self.irises):
            vid, plate_mid = self.corners[e]
            cuv, cd = projection_jacobian(self.camera, xr[vid])
            rows.append(uv[e] - cuv.mean(0) - (self.irises[e] - plate_mid))
            jac.append(J[e])
            vids += [vid, vid]
            dx += [-0.5 * cd[:, 0], -0.5 * cd[:, 1]]
        w = IRIS_WEIGHT
        return w * np.concatenate(rows), w * np.concatenate(jac), np.array(vids), w * np.array(dx)

    def iris_rows(self, z, xr, Jall):
        """(gaze rows (2 e,) px, their Jacobian (2 e, z size)) with d xr / dz = Jall
        (z size, V, 3) (``iris_terms``)."""
        r, J, vids, dx = self.iris_terms(z, xr)
        return r, J + np.einsum("nmi,knmi->nk", dx, Jall[:, vids])

    def iris_px(self, z, xr):
        """{iris curve name: (1,) px}: how far the model's pupil sits from the plate's iris, each
        taken from its eye's corners' midpoint (``iris_terms``)."""
        if not self.irises:
            return {}
        r = self.iris_terms(z, xr)[0].reshape(-1, 2) / IRIS_WEIGHT
        return {IRIS_CURVES[e]: np.array([np.linalg.norm(d)]) for e, d in zip(sorted(self.irises), r)}

    def rows(self, xr, Jall):
        """Signed distances (lists of (n,) px per curve) and their Jacobians ((n, z size) each)
        at the posed surface xr (V, 3) with d xr / dz = Jall (z size, V, 3)."""
        rows, jac = [], []
        for vid, r, dr_dx in self.signed(xr):
            rows.append(r)
            jac.append(np.einsum("nmi,kmi->nk", dr_dx, Jall[:, vid]))
        return rows, jac

    def position_gradient(self, xr):
        """(signed distances (n,) px of all curves, their gradient (V, 3) of 1/2 |rows|^2 with
        respect to the posed vertices xr (V, 3)): the curve term for one adjoint product."""
        rows, g = [], np.zeros_like(np.asarray(xr, float))
        for vid, r, dr_dx in self.signed(xr):
            np.add.at(g, vid, np.einsum("n,nmi->mi", r, dr_dx))
            rows.append(r)
        return np.concatenate(rows) if rows else np.zeros(0), g

    def signed(self, xr):
        """Per curve: (its vertex ids (m,), signed distances (n,) px of its points
        (``curve_weights``), their Jacobian (n, m, 3) with respect to those posed vertices)."""
        for name, poly in self.curves.items():
            vid, W = self.vertices[name], self.weights[name]
            uv, duv = projection_jacobian(self.camera, W @ xr[vid])
            foot, nrm = closest_on_polyline(uv, poly, normals=True)
            g = np.einsum("ni,nij->nj", nrm, duv)
            yield vid, np.einsum("ni,ni->n", uv - foot, nrm), W[:, :, None] * g[:, None, :]


def initial_pose(model, camera, curves, rotation=None, translation=None, samples=20):
    """Rigid pose (theta (3,), t (3,)) from the neutral curves and the plate curves by
    solvePnP on arc-length resampled point pairs; the given pose is the PnP start."""
    import cv2
    from scipy.spatial.transform import Rotation
    th = np.zeros(3) if rotation is None else np.asarray(rotation, float)
    t = np.zeros(3) if translation is None else np.asarray(translation, float)
    obj, img = [], []
    for name, poly in curves.items():
        if name not in model.curves:
            continue
        o, q = resample(curve_points(model, name, model.neutral), samples), resample(poly, samples)
        # pair points in the model curve's direction (plate curves may run either way)
        u, _ = camera.project(pose_points(o, th, t))
        if np.linalg.norm(u[[0, -1]] - q[[0, -1]]) > np.linalg.norm(u[[0, -1]] - q[[-1, 0]]):
            q = q[::-1]
        obj.append(o)
        img.append(q)
    obj, img = np.concatenate(obj), np.concatenate(img)
    # camera-frame pose of the model: R_c R(theta), R_c t + t_c
    R0 = camera.R @ euler_xyz(th)
    rvec, tvec = cv2.Rodrigues(R0)[0], (camera.R @ t + camera.t).reshape(3, 1)
    ok, rvec, tvec = cv2.solvePnP(obj, img, camera.K, None, rvec, tvec, useExtrinsicGuess=True,
                                  flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        return th, t
    Rm = camera.R.T @ cv2.Rodrigues(rvec)[0]
    # euler_xyz is R = Rz Ry Rx: scipy's extrinsic "xyz" convention
    th = Rotation.from_matrix(Rm).as_euler("xyz")
    return th, camera.R.T @ (tvec.ravel() - camera.t)


def pose_anchor(vec, z, lam):
    """The pose pass's anchor (ours): EQ15_ANCHOR_LAMBDA |(t - t_0) / 1 mm|^2, scaled with the face
    as lam / EQ15_LAMBDA_1, on the head translation about z's: (centre z (size,), row weights
    (size,)) for ``prior_rows``. Eyes and lips hardly fix the head's depth: with the tracking
    pass's weak regulariser the expression made up for it, and on the open-mouth sample plate
    the pose pass ended 7.6 mm deeper than the truth (12.1 mm from the given pose), outside what
    the shading stage recovers (10.1 mm posed error after it)."""
    w = np.zeros(vec.size)
    w[vec.translation] = np.sqrt(EQ15_ANCHOR_LAMBDA * lam / EQ15_LAMBDA_1) / vec.scales()[vec.translation]
    return np.asarray(z, float).copy(), w


def fit_curves(model, camera, curves, kind="blendshape", lam=EQ15_LAMBDA_1, p0=None, rotation=None,
               translation=None, solve_pose=True, max_iter=200, previous=None, temporal=0.0, anchored=False,
               progress=None):
    """Solve Eq. 15: controls from plate curves, and first the rigid pose. Returns a CurveFit.

    The paper's pose comes from tracked features; here, with ``solve_pose``, it comes from
    the curves: solvePnP on the neutral curves, then a tracking pass over pose and controls
    with the weak ``EQ15_TRACK_LAMBDA``, so the expression does not have to be explained by the
    pose (with lambda_1 = 3600 the weights of a smile stay near 0.05 and the pose turns and
    shifts to make up for it: 0.06 rad and 12 mm off on the sample smile plate). Eq. 15 then
    solves the controls from that pose. The history logs both passes ("pass": "pose" or
    "controls").

    In a sequence, ``previous`` (the previous frame's z) and ``temporal`` (px^2 per
    ``FitVector.scales()`` unit^2) add temporal |(z - previous) / scales|^2 to both passes:
    weights, jaw and pose change between frames only as far as the curves ask. Without a
    previous frame, ``anchored`` holds the pose pass's head translation near the given one
    (``pose_anchor``): for a given pose that means something, a calibration frame's."""
    if not curves:
        raise InvfaceError("no plate curves to fit")
    sm, vec = model.surface_model(kind), FitVector.of(model)
    z = vec.pack(p0, rotation, translation)
    lo, hi = vec.bounds()
    history = []

    def solve(z, lam, pose, name, prior):
        lo_, hi_ = lo.copy(), hi.copy()
        if not pose:
            lo_[vec.pose], hi_[vec.pose] = z[vec.pose], z[vec.pose]
        log = (lambda h: progress(dict(h, **{"pass": name}))) if progress else None
        obj = CurveObjective(model, sm, camera, curves, lam, prior)
        fun = with_linear_term(obj, sparsity_slopes(vec, lam, relief=obj.relief))
        res = dogleg(fun, z, lo_, hi_, max_iter=max_iter, ftol=CURVE_FTOL, progress=log)
        history.extend(dict(h, **{"pass": name}) for h in res.history)
        return res

    prior = temporal_prior(vec, previous, temporal)
    tracked = None
    if solve_pose:
        _, rot, tr = vec.unpack(z)
        anchor = pose_anchor(vec, z, lam) if anchored and prior is None else prior
        z = vec.with_pose(z, *initial_pose(model, camera, curves, rot, tr))
        z = solve(z, EQ15_TRACK_LAMBDA, True, "pose", anchor).x
        tracked = vec.unpack(z)[0]
    res = solve(z, lam, False, "controls", prior)
    obj = CurveObjective(model, sm, camera, curves, lam)
    _, xr = posed_surface(sm, res.x, vec)
    resid = {k: np.linalg.norm(v, axis=1) for k, v in obj.residuals(xr).items()}
    p, rot, tr = vec.unpack(res.x)
    return CurveFit(p=p, rotation=rot, translation=tr, residual_px=resid, history=history, status=res.status,
                    tracked=tracked, iris_px=obj.iris_px(res.x, xr))
