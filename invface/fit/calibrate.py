"""Lighting and albedo calibration on a neutral plate: paper 000, Eq. 14.

    min_{gamma, c}  || F* - F(x_R(0), gamma, c) ||^2  +  lambda || S(c) ||^2,
    S(c)_i = (1/|N(i)|) sum_{j in N(i)} (c_i - c_j)     (umbrella Laplacian of the skin mesh)

The data term sums squared linear-RGB residuals over the plate's pixels. S is the paper's
sum over neighbours divided by the valence |N(i)|. Deviation, measured: with the plain sum,
the paper's lambda = 2500 over-smooths our template's albedo (valence ~6, so 36 times the
weight) and pushes the albedo's variation into the light. On a synthetic 720x540 plate
(mottled albedo, 1 % noise) the irradiance on the visible normals came back 1.1 % off and
the albedo 2.7 % with the plain sum, against 0.5 % and 0.9 % with the valence-normalised S.

A single frontal plate sees normals on about a hemisphere, where the SH functions 1, z and
3z^2 - 1 are nearly dependent: the irradiance over the visible normals is what the plate
determines, the individual coefficients only through the albedo prior (above: 5 % error in
the coefficients for 0.5 % in the irradiance; 2.4 % when the true albedo is uniform, tests/test_calibrate.py).

For a fixed pose the image is linear in the per-vertex radiance, F = W (c * B gamma), with W
the renderer's coverage operator (``FaceRenderer.coverage``: barycentric weights of fixed
stratified rays, cast by Mitsuba) and B the SH shading basis of the posed normals. The
problem is then bilinear and separates per colour channel. Each Gauss-Newton step solves
the joint (gamma, c) normal equations of one channel exactly, by a Schur complement: one
sparse Cholesky of the (V, V) albedo block (PARDISO) and a 9x9 dense system for gamma, with
a Levenberg-Marquardt damping that is lowered on success and raised on failure.

Only the product c * E is observed: scaling a channel's albedo by k and its light by 1/k
leaves the image unchanged. The gauge is fixed so that the mean albedo of the well-seen
vertices (coverage at least half the median visible vertex's) equals ``albedo_mean``
(default: the template's skin albedo), and the light carries the plate's overall brightness
and colour. Deviation: with the mean over every visible vertex, a real photo meets the gauge
with a few grazing vertices of huge albedo where the light nearly vanishes, and the light
turns blue; over the well-seen vertices (and with the unseen pull below) it stays white, at a
small cost on the synthetic plate (bench/calibrate.py).

Only pixels whose every ray hits the face enter the data term (and, if the plate has a
mask, only masked pixels); vertices no ray sees are filled in by the smoothness term.

The rigid pose is given, as in the paper (there from tracked features; here from the plate's
curves or landmarks). Refining it here from shading alone was tried: with a free
per-vertex albedo the misalignment is absorbed by the albedo, and the pose did not converge.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from ..errors import BundleError, ConfigError, ImageError
from ..io.schema import Fields
from ..mesh.triangles import unique_edges
from ..model.rig import euler_xyz
from ..render import shading
from ..render.camera import Camera
from ..render.renderer import FaceRenderer
from ..sim.linsolve import MatrixPattern, make_solver
from .lambdas import EQ14_LAMBDA

UNSEEN_PULL = 1e-4                         # weight (x lambda) pulling unseen albedo to the mean
# reweighted solves after the first (``robust_weights``) that ``calibrate --robust`` asks for.
# ``calibrate``'s default is none: on the real photos the features the first, stiff pass cannot
# explain (brows, lips) lost their weight too, and the fits' curves and image residuals came out worse
ROBUST_ROUNDS = 2
ROBUST_K = 1.5
ROBUST_STIFF = 50.0
SKIN_ALBEDO = shading.SKIN_ALBEDO           # default mean albedo (the gauge)


@dataclass
class Calibration:
    """Result of Eq. 14: gamma (9,3), albedo (V,3), the pose and camera it was solved with."""

    gamma: np.ndarray
    albedo: np.ndarray
    rotation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    translation: np.ndarray = field(default_factory=lambda: np.zeros(3))
    camera: Camera | None = None
    lam: float = EQ14_LAMBDA
    history: list = field(default_factory=list)
    plate: str = ""

    def save(self, path):
        """Write an .npz calibration file atomically."""
        path = Path(path)
        meta = {"lam": self.lam, "plate": self.plate, "history": self.history,
                "camera": None if self.camera is None else self.camera.to_dict()}
        from ..io.arrays import savez
        return savez(path, dict(gamma=self.gamma, albedo=self.albedo, rotation=self.rotation,
                                translation=self.translation, meta=np.array(json.dumps(meta))))

    @classmethod
    def load(cls, path, vertex_count=None):
        """Read a calibration file; errors name the file and the bad field."""
        from ..io.arrays import load_npz
        f = Fields(load_npz(path, BundleError, "calibration file"), path, BundleError)
        gamma, rotation, translation = (f.array(k, shape) for k, shape in
                                        (("gamma", (9, 3)), ("rotation", (3,)), ("translation", (3,))))
        alb = f.array("albedo", (None, 3))
        if vertex_count is not None and len(alb) != vertex_count:
            f.fail("albedo", f"has {len(alb)} vertices but the model has {vertex_count}; calibrate with this model")
        meta = f.json("meta", default=Fields({}, path, BundleError))
        cam = meta.mapping("camera", default=None)
        return cls(gamma=gamma, albedo=alb, rotation=rotation, translation=translation,
                   camera=None if cam is None else Camera.from_dict(cam.data, source=str(path)),
                   lam=meta.number("lam", default=EQ14_LAMBDA, low=0),
                   history=meta.listing_of("history", default=[]), plate=meta.text("plate", default=""))


def mesh_laplacian(triangles, vertex_count):
    """Umbrella Laplacian L (V, V) CSR: (L c)_i = (1/|N(i)|) sum_{j in N(i)} (c_i - c_j)."""
    e = unique_edges(triangles)[0]
    A = sp.coo_matrix((np.ones(2 * len(e)), (np.r_[e[:, 0], e[:, 1]], np.r_[e[:, 1], e[:, 0]])),
                      shape=(vertex_count, vertex_count)).tocsr()
    deg = np.maximum(np.asarray(A.sum(1)).ravel(), 1)
    return (sp.identity(vertex_count) - sp.diags(1 / deg) @ A).tocsr()


class _ChannelSolver:
    """Damped Gauss-Newton on one channel of Eq. 14 with the albedo gauge as a residual:

        f(g, c) = |W (c * B g) - y|^2 + lam |L c|^2 + sum_i e_i (c_i - ref)^2 + rho (a.c - ref)^2

e_i = UNSEEN_PULL lam on vertices no ray sees (1e-8 elsewhere): without it the smoothness
term alone extends the face's albedo linearly over the rest of the head, and on a photo
(small face, masked to the face oval) 41 % of the head's vertices came out negative: a black
scalp in every render; with the pull, none. It fades the extension to the gauge's mean.

    a = mean over the well-seen vertices. The (V, V) albedo block is sparse plus the rank-one
    gauge term (Sherman-Morrison); gamma's 9 unknowns are eliminated by a Schur complement."""

    def __init__(self, W, LtL, lam, seen, eps=1e-8):
        self.W, self.LtL, self.lam = W, LtL, lam
        self.eps = np.where(seen > 0, eps, UNSEEN_PULL * lam)
        V = W.shape[1]
        cover = np.asarray(W.sum(0)).ravel() * seen
        well = (cover > 0.5 * np.median(cover[cover > 0])).astype(float)
        self.a = well / max(well.sum(), 1)
        self.rho = 1e3 * W.shape[0]
        self.WtW = (W.T @ W).tocsr()
        self.pattern = MatrixPattern(self.WtW + LtL + sp.identity(V))
        self.solver = make_solver(self.pattern)

    def objective(self, B, g, c, y, ref):
        r = self.W @ (c * (B @ g)) - y
        return float(r @ r + self.lam * np.sum((self.LtL @ c) * c) + self.eps @ (c - ref) ** 2
                     + self.rho * (self.a @ c - ref) ** 2)

    def step(self, B, g, c, y, ref, mu):
        """The damped Gauss-Newton step (dg (9,), dc (V,))."""
        s = B @ g                                   # shading per vertex
        Jc = (self.W @ sp.diags(s)).tocsr()
        Jg = self.W @ (c[:, None] * B)              # (M, 9) dense
        r = self.W @ (c * s) - y
        A = (sp.diags(s) @ self.WtW @ sp.diags(s) + self.lam * self.LtL
             + sp.diags(self.eps + mu)).tocsr()
        self.solver.factor(self.pattern.values(A))
        C = Jc.T @ Jg                               # (V, 9) coupling
        ga = -(Jc.T @ r + self.lam * (self.LtL @ c) + self.eps * (c - ref)
               + self.rho * (self.a @ c - ref) * self.a)
        gb = -(Jg.T @ r)
        X = self.solver.solve(np.column_stack([C, ga, self.a]))
        # (A + rho a a^T)^-1 by Sherman-Morrison
        u = X[:, -1]
        X = X[:, :-1] - np.outer(u, self.rho * (self.a @ X[:, :-1]) / (1 + self.rho * self.a @ u))
        S = Jg.T @ Jg + mu * np.eye(9) - C.T @ X[:, :9]
        dg = np.linalg.solve(S, gb - C.T @ X[:, 9])
        dc = X[:, 9] - X[:, :9] @ dg
        return dg, dc


def robust_weights(residual, k=ROBUST_K):
    """Per-pixel weights (M,) of Eq. 14's data rows from their residuals (M, 3): 1 within k
    robust standard deviations (1.4826 x the median residual norm), then falling as (k s / r)^2
    (Cauchy-like), so that pixels the face's light and albedo cannot explain (a hand, hair, a
    frame's edge) stop pulling the albedo; the smoothness term fills it in from around them."""
    r = np.linalg.norm(np.asarray(residual, float), axis=1)
    s = 1.4826 * max(float(np.median(r)), 1e-12)
    return np.minimum(1.0, (k * s / np.maximum(r, 1e-30)) ** 2)


def calibrate(model_triangles, x, plate_image, camera, rotation=None, translation=None,
              lam=EQ14_LAMBDA, albedo_mean=SKIN_ALBEDO, mask=None, max_iter=30, tol=1e-7,
              gamma0=None, albedo0=None, samples=3, progress=None, parts=None, parts_x=None, robust=0):
    """Solve Eq. 14 for gamma (9,3) and albedo (V,3) on one plate.

    model_triangles (F,3); x (V,3) m: the neutral surface; plate_image (H,W,3) linear;
    camera: the plate's (undistorted) Camera; rotation (3,) rad / translation (3,) m: the
    rigid head pose; lam: lambda of Eq. 14; albedo_mean (3,): the gauge; mask (H, W): plate
    pixels to use; samples: rays per pixel side in the coverage operator; progress: called
    with each iteration's log entry; parts, parts_x: the model's ``InnerParts`` and their
    unposed positions (P,3) m (default at rest): pixels where an eye or the mouth shows are
    left out of the data term (their albedo is the parts' own, not solved for); robust: that
    many reweighted solves after a first one ROBUST_STIFF times smoother (``robust_weights``),
    for a plate with something over the face. Returns a Calibration with the iteration log."""
    img = np.asarray(plate_image, np.float64)
    if img.shape[:2] != (camera.height, camera.width):
        raise ImageError(f"plate is {img.shape[1]}x{img.shape[0]} px, camera is "
                         f"{camera.width}x{camera.height}")
    if lam < 0:
        raise ConfigError(f"lambda must be >= 0, got {lam}")
    x = np.asarray(x, float)
    V = len(x)
    rot = np.zeros(3) if rotation is None else np.asarray(rotation, float)
    tr = np.zeros(3) if translation is None else np.asarray(translation, float)
    renderer = FaceRenderer(model_triangles, camera, spp=8, silhouette_spp=0.5, parts=parts)
    L = mesh_laplacian(model_triangles, V)
    LtL = (L.T @ L).tocsr()
    ref = np.broadcast_to(np.asarray(albedo_mean, float), 3)
    gamma = shading.constant_light(1.0) if gamma0 is None else np.array(gamma0, float)
    c = np.tile(ref, (V, 1)) if albedo0 is None else np.array(albedo0, float)
    history = []
    t0 = time.perf_counter()
    pixels, W = renderer.coverage(x, rot, tr, samples=samples, parts_x=parts_x)
    if mask is not None:
        keep = np.asarray(mask, bool).reshape(-1)[pixels]
        pixels, W = pixels[keep], W[keep]
    if len(pixels) < 100:
        raise ImageError(f"only {len(pixels)} plate pixels are covered by the face at this "
                         "pose; check the camera and the pose")
    y = img.reshape(-1, 3)[pixels]
    Xr = x @ euler_xyz(rot).T + tr
    B = shading.shading_basis(shading.vertex_normals(Xr, model_triangles))
    seen = (np.asarray(W.sum(0)).ravel() > 1e-3).astype(float)
    weights = np.ones(len(pixels))
    for rnd in range(1 + max(int(robust), 0)):
        if rnd:       # reweighted: the rows of pixels the last solve could not explain weigh less
            weights = robust_weights(W @ (c * (B @ gamma)) - y)
        sw = np.sqrt(weights)
        stiff = ROBUST_STIFF if robust and rnd == 0 else 1.0
        sv = _ChannelSolver((sp.diags(sw) @ W).tocsr(), LtL, lam * stiff, seen)
        _solve_channels(sv, B, gamma, c, sw[:, None] * y, ref, max_iter, tol, history, t0, progress,
                        rms=lambda: float(np.sqrt(np.mean((W @ (c * (B @ gamma)) - y) ** 2))), round_=rnd)
    return Calibration(gamma=gamma, albedo=c, rotation=rot, translation=tr, camera=camera,
                       lam=float(lam), history=history)


def _solve_channels(sv, B, gamma, c, y, ref, max_iter, tol, history, t0, progress, rms, round_=0):
    """Damped Gauss-Newton on the three channels of Eq. 14 in place (gamma (9, 3), c (V, 3)),
    until the objective's relative change is below ``tol``; logs each iteration."""
    mu = np.full(3, 1e-3 * float(sv.W.power(2).sum()) / max(len(c), 1))

    def objective():
        return sum(sv.objective(B, gamma[:, ch], c[:, ch], y[:, ch], ref[ch]) for ch in range(3))
    obj = objective()
    for it in range(max_iter):
        for ch in range(3):
            args = (B, gamma[:, ch], c[:, ch], y[:, ch], ref[ch])
            f0 = sv.objective(*args)
            for _ in range(8):
                dg, dc = sv.step(*args, mu[ch])
                g1, c1 = gamma[:, ch] + dg, c[:, ch] + dc
                if sv.objective(B, g1, c1, y[:, ch], ref[ch]) <= f0:
                    gamma[:, ch], c[:, ch] = g1, c1
                    mu[ch] *= 0.3
                    break
                mu[ch] *= 10
        new = objective()
        history.append({"iteration": len(history), "round": round_, "objective": new, "rms": rms(),
                        "seconds": time.perf_counter() - t0})
        if progress is not None:
            progress(history[-1])
        done = abs(obj - new) <= tol * max(obj, 1e-30)
        obj = new
        if done:
            break


def comparison_image(model_triangles, x, calibration, plate_image, spp=16, parts=None, parts_x=None):
    """(H, 3W, 3) linear image: plate | render with the calibration | |difference| x 4.
    parts, parts_x: the inner parts and their unposed positions, as in ``calibrate``."""
    cal = calibration
    r = FaceRenderer(model_triangles, cal.camera, spp=spp, parts=parts)
    img = r.image(x, cal.gamma, cal.albedo, cal.rotation, cal.translation, parts_x=parts_x)
    a = img[..., 3:4]
    render = img[..., :3] + (1 - a) * plate_image         # the face over the plate
    diff = np.clip(4 * np.abs(render - plate_image), 0, 1)
    return np.concatenate([plate_image, render, diff], 1).astype(np.float32)
