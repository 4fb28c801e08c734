"""Shape from shading on a plate: paper 000, Eq. 16.

    min_z  1/2 || E_2(z) ||^2 + lambda_1/2 || E_1(z) ||^2 + lambda_2/2 || w - w^ ||^2
    E_2 = G(F* - F(x_R(z), gamma, c)),   lambda_1 = 1e-4, lambda_2 = 1,   z = (w, theta, t)

G is a three-level Gaussian pyramid (the 5x5 binomial blur and every other pixel of OpenCV's
``pyrDown``, written here as sparse separable matrices so that its adjoint is exact) of the
per-pixel RGB differences between the plate F* and the render F (linear light), gamma and
c are the calibration's (Eq. 14), E_1 the curve distances of Eq. 15 (pixels; optional) and
w^ the curve solution that starts the solve. The rigid pose is solved too. The plate is the
renderer's backplate, so the background around the face is the plate's own and silhouette
derivatives see it. A plate mask M (the alpha channel, or the landmark detector's face oval
on a photo) restricts the data term to the face: E_2 = G(M * (F* - F)), so hair and
background the model's scalp and neck happen to cover do not pull on the pose.

The solver is the gradient path of the design: L-BFGS-B (box constraints on the controls) on
the adjoint gradient. One evaluation is one render with its derivative pass (the image
adjoint G^T G (F - F*) sent back through Dr.Jit to the posed vertices) and the model's
Jacobian d x_R / dz (the rig's, or the simulation's tangent solves on the converged Newton
factorisation), so its cost does not grow with the number of pixels per parameter the way
a forward-mode Jacobian for the paper's dogleg does (33 renders per iteration). The renderer
keeps one sample seed, so the objective is a deterministic function of z.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import ImageError
from ..render.renderer import FaceRenderer
from ..sim.quasistatic import SimulationError
from .curves import CurveObjective
from .scan import control_bounds, posed_jacobian

LAMBDA_1 = 1e-4        # paper 000, Eq. 16: weight of the curve term (pixels^2)
LAMBDA_2 = 1.0         # paper 000, Eq. 16: pull towards the curve solution w^
LEVELS = 3


def _pyr_matrix(n):
    """(ceil(n/2), n) sparse matrix of one pyrDown axis: taps [1 4 6 4 1]/16 centred on every
    other sample, borders reflected without repeating the edge sample (BORDER_REFLECT_101)."""
    import scipy.sparse as sp
    m = (n + 1) // 2
    rows, cols, vals = [], [], []
    for off, w in zip(range(-2, 3), np.array([1, 4, 6, 4, 1]) / 16.0):
        j = 2 * np.arange(m) + off
        j = np.abs(j)                                  # reflect-101 at 0
        j = np.where(j > n - 1, 2 * (n - 1) - j, j)    # and at n-1
        rows.append(np.arange(m))
        cols.append(j)
        vals.append(np.full(m, w))
    return sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                         shape=(m, n))


class Pyramid:
    """The linear map G: image (H, W, C) -> flat concatenation of ``levels`` Gaussian pyramid
    levels (level 0 is the image); ``adjoint`` is its exact transpose."""

    def __init__(self, height, width, levels=LEVELS):
        self.shapes, self.mats = [(height, width)], []
        for _ in range(levels - 1):
            h, w = self.shapes[-1]
            self.mats.append((_pyr_matrix(h), _pyr_matrix(w)))
            self.shapes.append(((h + 1) // 2, (w + 1) // 2))

    def __call__(self, image):
        cur = np.asarray(image, np.float64)
        out = [cur.ravel()]
        for Dh, Dw in self.mats:
            h, w, c = cur.shape
            cur = Dh @ cur.reshape(h, w * c)                                   # rows
            cur = (Dw @ cur.reshape(-1, w, c).transpose(1, 0, 2).reshape(w, -1))  # columns
            cur = cur.reshape(Dw.shape[0], Dh.shape[0], c).transpose(1, 0, 2)
            out.append(cur.ravel())
        return np.concatenate(out)

    def adjoint(self, vec, channels=3):
        """G^T vec: (H, W, channels)."""
        sizes = [h * w * channels for h, w in self.shapes]
        parts = np.split(np.asarray(vec, np.float64), np.cumsum(sizes)[:-1])
        acc = parts[-1].reshape(*self.shapes[-1], channels)
        for k in range(len(self.mats) - 1, -1, -1):
            Dh, Dw = self.mats[k]
            h, w = self.shapes[k]
            m, n = self.shapes[k + 1]
            a = acc.transpose(1, 0, 2).reshape(n, m * channels)
            a = (Dw.T @ a).reshape(w, m, channels).transpose(1, 0, 2)          # (m, w, c)
            a = (Dh.T @ a.reshape(m, w * channels)).reshape(h, w, channels)
            acc = a + parts[k].reshape(h, w, channels)
        return acc


@dataclass
class ShadingFit:
    """Eq. 16 result: controls p, pose, the iteration log."""

    p: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    history: list = field(default_factory=list)
    status: str = ""


class ShadingObjective:
    """z = (p, theta, t) -> (cost, gradient (P+6,)) of Eq. 16, one render and one backward."""

    def __init__(self, model, surface_model, camera, plate, gamma, albedo, p_hat, curves=None,
                 lam1=LAMBDA_1, lam2=LAMBDA_2, mask=None, spp=8, silhouette_spp=0.5, seed=1):
        import drjit as dr
        self.dr = dr
        self.model, self.sm = model, surface_model
        self.P = len(model.blendshape_names) + 6
        self.plate = np.asarray(plate, np.float32)
        if self.plate.shape[:2] != (camera.height, camera.width):
            raise ImageError(f"plate is {self.plate.shape[1]}x{self.plate.shape[0]} px, the camera "
                             f"is {camera.width}x{camera.height}")
        self.G = Pyramid(camera.height, camera.width)
        self.mask = (np.ones(self.plate.shape[:2] + (1,), np.float32) if mask is None
                     else np.asarray(mask, np.float32).reshape(self.plate.shape[:2] + (1,)))
        self.target = self.G(self.plate * self.mask)
        self.gamma, self.albedo = np.asarray(gamma, float), np.asarray(albedo, float)
        self.renderer = FaceRenderer(model.triangles, camera, spp=spp, silhouette_spp=silhouette_spp,
                                     seed=seed, backplate=self.plate)
        self.p_hat, self.lam1, self.lam2 = np.asarray(p_hat, float), lam1, lam2
        self.curves = CurveObjective(model, surface_model, camera, curves, 0.0) if curves else None
        self.terms = {}

    def __call__(self, z):
        dr, mi = self.dr, self.renderer.mi
        P = self.P
        xr, Jall = posed_jacobian(self.sm, z, P)
        x = mi.Float(xr.astype(np.float32).ravel())
        dr.enable_grad(x)
        img = self.renderer.render(x, self.gamma, self.albedo)
        rgb = np.array(img, np.float32)[..., :3]
        r = self.G(rgb * self.mask) - self.target                  # G M (F - F*)
        adj = np.zeros(rgb.shape[:2] + (4,), np.float32)
        adj[..., :3] = self.G.adjoint(r) * self.mask
        dr.backward(img * mi.TensorXf(adj))
        gx = np.array(dr.grad(x), np.float64).reshape(-1, 3)
        grad = np.einsum("kvi,vi->k", Jall, gx)
        image = 0.5 * float(r @ r)
        dp = z[:P] - self.p_hat
        prior = 0.5 * self.lam2 * float(dp @ dp)
        grad[:P] += self.lam2 * dp
        curve = 0.0
        if self.curves is not None:
            rc, Jc = self.curves(z)
            n = len(rc) - P                                       # without its zero regulariser rows
            curve = 0.5 * self.lam1 * float(rc[:n] @ rc[:n])
            grad += self.lam1 * (rc[:n] @ Jc[:n])
        self.terms = {"image": image, "curves": curve, "prior": prior}
        return image + curve + prior, grad


# one unit of the optimiser's variables: weights 1, jaw rotations 0.1 rad, jaw translations
# and the head translation 1 cm, head rotation 0.1 rad (balances L-BFGS's first steps)
def _scales(P):
    s = np.ones(P + 6)
    s[P - 6:P - 3], s[P - 3:P] = 0.1, 0.01
    s[P:P + 3], s[P + 3:] = 0.1, 0.01
    return s


def fit_shading(model, camera, plate, gamma, albedo, p_hat, rotation, translation, kind="blendshape",
                curves=None, lam1=LAMBDA_1, lam2=LAMBDA_2, mask=None, max_iter=40, p0=None, restarts=2,
                progress=None, **render):
    """Solve Eq. 16 from the curve solution (p_hat (P,), rotation (3,), translation (3,)), or
    from p0 (P,) when given (p_hat stays the prior's centre).

    plate: linear (H, W, 3) float, undistorted, the camera's size; gamma (9, 3), albedo (V, 3)
    from the calibration; curves: the plate curves of Eq. 15 or None; mask (H, W) bool or None:
    the plate pixels of the data term. ``render`` options go to
    ``FaceRenderer`` (spp, silhouette_spp, seed). Returns a ShadingFit."""
    from scipy.optimize import minimize
    sm = model.surface_model(kind)
    obj = ShadingObjective(model, sm, camera, plate, gamma, albedo, p_hat, curves, lam1, lam2, mask, **render)
    P = obj.P
    s = _scales(P)
    z0 = np.r_[np.asarray(p_hat if p0 is None else p0, float), rotation, translation]
    lo, hi = control_bounds(model)
    history, t0 = [], time.perf_counter()

    def fun(u, restart=0):
        try:
            f, g = obj(u * s)
        except SimulationError:
            if not history:
                raise
            # the simulation cannot reach this trial point: a cost above every one seen makes
            # the line search step back, as the dogleg rejects such a step
            f, g = 10 * max(h["cost"] for h in history), np.zeros(len(u))
            history.append({"iteration": len(history), "cost": f, "failed": True, "restart": restart,
                            "seconds": time.perf_counter() - t0})
            return f, g
        history.append({"iteration": len(history), "cost": f, **obj.terms, "restart": restart,
                        "seconds": time.perf_counter() - t0})
        if progress is not None:
            progress(history[-1])
        return f, g * s

    bounds = list(zip(np.where(np.isfinite(lo), lo / s, None), np.where(np.isfinite(hi), hi / s, None)))
    u, status = z0 / s, ""
    # The sampled image is piecewise constant where silhouettes cross fixed samples, so the
    # line search can stop on a sample pattern; restarting with fresh samples continues.
    for restart in range(restarts + 1):
        obj.renderer.seed = obj.renderer.seed + restart
        res = minimize(lambda v: fun(v, restart), u, jac=True, method="L-BFGS-B", bounds=bounds,
                       options={"maxiter": max_iter, "maxfun": 2 * max_iter, "ftol": 1e-7, "gtol": 1e-6})
        u, status = res.x, str(res.message)
        if "ABNORMAL" not in status or len(history) >= 2 * max_iter:
            break
    z = u * s
    return ShadingFit(p=z[:P], rotation=z[P:P + 3], translation=z[P + 3:], history=history, status=status)
