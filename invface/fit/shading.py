"""Shape from shading on a plate: paper 000, Eq. 16.

    min_z  1/2 || E_2(z) ||^2 + lambda_1/2 || E_1(z) ||^2 + lambda_2/2 || w - w^ ||^2
    E_2 = G(F* - F(x_R(z), gamma, c)),   lambda_1 = 1e-2 (the paper: 1e-4; ``fit.lambdas``), lambda_2 = 1,
    z = (w, theta, t)

In a sequence (ours, not the paper's) a temporal term lambda_t/2 || (z - z_prev) / s ||^2 joins
it (s: ``FitVector.scales``), the previous frame's z_prev; the depth of the head is what the
image term alone pins least, and without the term it jumps frame to frame.

G is a three-level Gaussian pyramid (the 5x5 binomial blur and every other pixel of OpenCV's
``pyrDown``, written here as sparse separable matrices so that its adjoint is exact) of the
per-pixel RGB differences between the plate F* and the render F (linear light), gamma and
c are the calibration's (Eq. 14), E_1 the curve distances of Eq. 15 (pixels; optional) and
w^ the curve solution that starts the solve. The rigid pose is solved too. The plate is the
renderer's backplate, so the background around the face is the plate's own and silhouette
derivatives see it; ``fit_shading`` first fills the pixels the head covers at the start
from the background around them (``render.backplate``: with the plate itself behind the
head, the fit pulled the head 1-2 mm away from the camera). A plate mask M (the alpha
channel, or the landmark detector's face oval on a photo) restricts the data term to the
face: E_2 = G(M * (F* - F)), so hair and background the model's scalp and neck happen to
cover do not pull on the pose. Each row of E_2 enters through the Huber loss (``huber_rows``,
threshold ``ROBUST_DELTA``; the paper's plain square with ``robust=None``): quadratic for the
residuals of a face the model can match, linear for pixels it cannot (a hand over the mouth,
glasses, hair), whose pull on the shape is then bounded. Gauss-Newton takes the rows psi(r)
and their Jacobian psi'(r) dr/dz.

Two solvers. The default is the paper's dogleg (``fit.dogleg``) on the Gauss-Newton normal
equations: g = J^T r exactly, from one backward pass through the render (the image adjoint
G^T M G M (F - F*) sent back through Dr.Jit to the posed vertices, then through the model's
Jacobian d x_R / dz: the rig's, or the simulation's tangent solves on the converged Newton
factorisation), and H = J^T J from the image Jacobian's columns, one forward-mode pass per
parameter through a second, cheaper render (``jacobian_spp`` samples per pixel), each sent
through G M. Both are computed only for accepted steps; a rejected trial costs one render.
Only the face's window of the plate is rendered (``face_window``). The gradient-only path
(L-BFGS-B on the adjoint gradient, one render and one backward pass per evaluation, through
``bridge.PosedSurfaceFunction``: one adjoint product of the surface model) is for parameter
counts where K+12 forward passes are too many. The renderer keeps one sample seed,
so the objective is a deterministic function of z.

The model's inner parts (teeth, tongue, mouth lining, eyes) are rendered where z's jaw and
pose put them, so an open mouth on the plate meets a dark mouth and teeth in the render, not
the plate's background. They carry no derivative: the skin's edges against them do, their own
motion does not (their interior term is negligible, and Mitsuba sampling their edges would
count edges hidden behind the skin).
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import ImageError, InvfaceError, SimulationError
from ..model.controls import FitVector
from ..render.backplate import background_plate, head_silhouette
from ..render.jacobian import RasterJacobian
from ..render.renderer import FaceRenderer
from .curves import CurveObjective
from .lambdas import EQ15_LAMBDA_1, EQ16_LAMBDA_1, EQ16_LAMBDA_2
from ..model.pose import posed_jacobian, posed_parts, posed_surface
from .priors import prior_rows, regulariser, sparsity_slopes, temporal_prior

LEVELS = 3
#: Huber threshold of the image rows (linear light, per pyramid sample and channel): about 10x
#: the sample plates' noise (0.005) and twice the residual RMS of a calibrated real photo's
#: face (0.05), so a fit's own residuals stay quadratic and a hand or a strand of hair in front
#: of the face pulls with a bounded force
ROBUST_DELTA = 0.1
#: the dogleg's image Jacobian (``ShadingObjective.image_jacobian``): 'forward' (Dr.Jit, one
#: forward-mode pass per control), 'hybrid' (the blendshapes' rows with visibility held fixed,
#: the jaw's and pose's 12 by forward mode) or 'analytic' (every row with visibility held fixed,
#: as the paper's OpenDR). On the sample plates the fixed-visibility rows made the dogleg take
#: more steps and land further from the truth (bench/RESULTS.md), so forward mode stays the default
JACOBIAN = "forward"
JACOBIAN_SAMPLES = 1     # rays per pixel along each axis of the analytic Jacobian


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
    levels (level 0 is the image), each sample times sqrt(weight); ``adjoint`` is its exact
    transpose. The forward map is OpenCV's ``pyrDown`` (the same taps and borders as the
    sparse matrices, equal to them to rounding and 70x faster); the adjoint uses the
    matrices' transposes."""

    def __init__(self, height, width, levels=LEVELS, weight=1.0):
        self.shapes, self.mats = [(height, width)], []
        self.scale = float(np.sqrt(weight))
        for _ in range(levels - 1):
            h, w = self.shapes[-1]
            self.mats.append((_pyr_matrix(h), _pyr_matrix(w)))
            self.shapes.append(((h + 1) // 2, (w + 1) // 2))

    def __len__(self):
        """The number of samples of one channel over all levels."""
        return sum(h * w for h, w in self.shapes)

    def __call__(self, image, out=None):
        """G image (len(self) * C,): float64, or in ``out``'s dtype written into ``out`` (the
        image Jacobian's float32 rows, without the float64 copies)."""
        import cv2
        cur = np.asarray(image, np.float64 if out is None else out.dtype)
        c = cur.shape[2]
        parts = [cur]
        for _ in self.mats:
            cur = cv2.pyrDown(cur, borderType=cv2.BORDER_REFLECT_101).reshape(-1, (cur.shape[1] + 1) // 2, c)
            parts.append(cur)
        if out is None:
            out = np.concatenate([a.ravel() for a in parts])
        else:
            ends = np.cumsum([0] + [a.size for a in parts])
            for a, i, j in zip(parts, ends[:-1], ends[1:]):
                out[i:j] = a.ravel()
        if self.scale != 1.0:
            out *= self.scale
        return out

    def columns(self, images):
        """G of each of m images at once: images (H, W, C, m) -> (m, len(self) * C) float32, row
        j = G(images[..., j]) (pyrDown takes the C*m channels in one pass)."""
        import cv2
        H, W, c, m = images.shape
        cur = np.ascontiguousarray(images, np.float32).reshape(H, W, c * m)
        parts = [cur]
        for _ in self.mats:
            cur = cv2.pyrDown(cur, borderType=cv2.BORDER_REFLECT_101).reshape(-1, (cur.shape[1] + 1) // 2, c * m)
            parts.append(cur)
        out = np.concatenate([np.moveaxis(a.reshape(-1, c, m), 2, 0).reshape(m, -1) for a in parts], 1)
        if self.scale != 1.0:
            out *= self.scale
        return out

    def adjoint(self, vec, channels=3):
        """G^T vec: (H, W, channels)."""
        sizes = [h * w * channels for h, w in self.shapes]
        parts = np.split(np.asarray(vec, np.float64) * self.scale, np.cumsum(sizes)[:-1])
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
    """Eq. 16 at z = (p, theta, t) (``FitVector``): ``__call__`` (cost, gradient) with one
    render and one backward pass; ``normal_equations`` for the dogleg. window (x0, y0, width, height)
    px: render and compare only that part of the plate (``face_window``); outside it the
    render shows the plate itself, so the image term there is a constant. levels: the
    pyramid's levels; image_weight: the image rows' weight (a coarse stage's, ``fit_shading``);
    curve_camera: the camera of the curve term's pixels (default ``camera``); jacobian:
    'analytic' or 'forward' (``image_jacobian``; default the module's JACOBIAN, which benches
    set to compare the two); jacobian_samples: the analytic Jacobian's rays per pixel and axis;
    lam_curves: Eq. 15's lambda_1 (px^2 per unit weight^2) that the curves were fitted with,
    which sets the opposite pairs' weight (``priors.opposite_rows``)."""

    def __init__(self, model, surface_model, camera, plate, gamma, albedo, p_hat, curves=None,
                 lam1=EQ16_LAMBDA_1, lam2=EQ16_LAMBDA_2, mask=None, spp=8, silhouette_spp=0.5, seed=1, window=None,
                 jacobian_spp=2, backplate=None, robust=ROBUST_DELTA, previous=None, temporal=0.0,
                 levels=LEVELS, image_weight=1.0, curve_camera=None, jacobian=None,
                 jacobian_samples=JACOBIAN_SAMPLES, lam_curves=EQ15_LAMBDA_1):
        import drjit as dr
        self.dr = dr
        self.model, self.sm = model, surface_model
        self.vec = FitVector.of(model)
        plate = np.asarray(plate, np.float32)
        if plate.shape[:2] != (camera.height, camera.width):
            raise ImageError(f"plate is {plate.shape[1]}x{plate.shape[0]} px, the camera "
                             f"is {camera.width}x{camera.height}")
        mask = (np.ones(plate.shape[:2], np.float32) if mask is None
                else np.asarray(mask, np.float32).reshape(plate.shape[:2]))
        x0, y0, w, h = (0, 0, camera.width, camera.height) if window is None else window
        self.plate = plate[y0:y0 + h, x0:x0 + w]
        self.mask = mask[y0:y0 + h, x0:x0 + w, None]
        self.G = Pyramid(h, w, levels, image_weight)
        self.target = self.G(self.plate * self.mask)
        self.gamma, self.albedo = np.asarray(gamma, float), np.asarray(albedo, float)
        self.renderer = FaceRenderer(model.triangles, camera, spp=spp, silhouette_spp=silhouette_spp,
                                     seed=seed, backplate=plate if backplate is None else backplate, crop=window,
                                     parts=model.parts)
        self.p_hat, self.lam1, self.lam2 = np.asarray(p_hat, float), lam1, lam2
        # the opposite pairs cost what they cost in Eq. 15, in Eq. 16's units (its curve rows
        # weigh lam1 per px^2): at lam2 the image term, which sees the lids, outweighs them and
        # sets both controls of a pair again
        self.lam_opposite = lam1 * lam_curves
        self.jacobian_spp = int(jacobian_spp)
        jacobian = jacobian or JACOBIAN
        if jacobian not in ("hybrid", "analytic", "forward"):
            raise InvfaceError(f"jacobian must be 'hybrid', 'analytic' or 'forward', not {jacobian!r}")
        self.jacobian = jacobian
        self.raster = RasterJacobian(self.renderer, jacobian_samples, window) if jacobian != "forward" else None
        self.temporal = temporal_prior(self.vec, previous, temporal)     # a sequence's, or None
        self.robust = None if not robust else float(robust)
        self.curves = CurveObjective(model, surface_model, curve_camera or camera, curves, 0.0) if curves else None
        self.terms = {}
        from ..bridge import PosedSurfaceFunction
        self.bridge = PosedSurfaceFunction(surface_model, self.vec)     # the gradient-only path's

    def _prior_rows(self, z):
        """The prior's rows (``priors.regulariser``: K+6, then the opposite pairs'), then the
        temporal term's z-size rows in a sequence: (rows, their Jacobian (n, z size))."""
        rows, jac = regulariser(z, self.vec, self.lam2, self.p_hat, lam_opposite=self.lam_opposite)
        if self.temporal is None:
            return rows, jac
        rt, Jt = prior_rows(z, self.temporal)
        return np.concatenate([rows, rt]), np.vstack([jac, Jt])

    def _prior_and_curves(self, z, xr, Jall=None):
        """Residual rows of the prior, temporal and curve terms at z (posed surface xr), scaled
        by the square roots of their weights, in that order (``_prior_rows`` first): (rows (n,),
        their Jacobian (n, z size), or None without Jall)."""
        rp, Jp = self._prior_rows(z)
        rows, jac = [rp], ([Jp] if Jall is not None else None)
        if self.curves is not None:
            if Jall is None:
                rows += [np.sqrt(self.lam1) * np.linalg.norm(d, axis=1) for d in self.curves.residuals(xr).values()]
            else:
                rc, Jc = self.curves.rows(xr, Jall)
                rows += [np.sqrt(self.lam1) * r for r in rc]
                jac += [np.sqrt(self.lam1) * J for J in Jc]
            if self.curves.irises:              # the gaze: the pupils on the plate's irises
                if Jall is None:
                    rows.append(np.sqrt(self.lam1) * self.curves.iris_terms(z, xr)[0])
                else:
                    ri, Ji = self.curves.iris_rows(z, xr, Jall)
                    rows.append(np.sqrt(self.lam1) * ri)
                    jac.append(np.sqrt(self.lam1) * Ji)
        return np.concatenate(rows), (None if jac is None else np.vstack(jac))

    def _cost(self, r_image, r_rest):
        """Eq. 16's value from the image rows and the prior, temporal and curve rows
        (``_prior_and_curves``); ``terms`` keeps its parts."""
        P = self.vec.P + len(self.vec.opposites)
        T = P if self.temporal is None else P + self.vec.size
        part = lambda r: 0.5 * float(r @ r)
        self.terms = {"image": part(r_image), "prior": part(r_rest[:P]), "curves": part(r_rest[T:])}
        if self.temporal is not None:
            self.terms["temporal"] = part(r_rest[P:T])
        return sum(self.terms.values())

    def _render(self, xr, parts_x=None):
        """Render the posed surface (V, 3) (and the posed inner parts (P, 3), which carry no
        gradient) with gradients on: (Dr.Jit positions, image, image residual
        r = G M (F - F*) (m,))."""
        mi = self.renderer.mi
        x = mi.Float(xr.astype(np.float32).ravel())
        self.dr.enable_grad(x)
        img = self.renderer.render(x, self.gamma, self.albedo, parts_x=parts_x)
        rgb = self._rgb = np.array(img, np.float32)[..., :3]
        return x, img, self.G(rgb * self.mask) - self.target

    def _backward(self, x, img, r, Jall):
        """J^T r (z size,) of the image rows: the adjoint G^T M r sent back through the render
        to the positions x, then through d x_R / dz = Jall (z size, V, 3)."""
        self.dr.backward(img * self._image_adjoint(r))
        return np.einsum("kvi,vi->k", Jall, np.array(self.dr.grad(x), np.float64).reshape(-1, 3))

    def _image_adjoint(self, r):
        """TensorXf (h, w, 4): G^T M r, the image's adjoint for the residual r."""
        adj = np.zeros(self.plate.shape[:2] + (4,), np.float32)
        adj[..., :3] = self.G.adjoint(r) * self.mask
        return self.renderer.mi.TensorXf(adj)

    def __call__(self, z):
        """(cost, gradient (z size,)) for gradient-only solvers: one render and one backward
        pass through the Dr.Jit graph z -> x_R(z) (``bridge.PosedSurfaceFunction``) -> image,
        so the surface model's derivative costs one adjoint product (``surface_vjp``: one
        back-substitution for the simulation), not its Jacobian. The curve term's gradient
        with respect to x_R joins the same backward pass. Same positions, render and cost as
        ``normal_equations``."""
        dr, mi = self.dr, self.renderer.mi
        z = np.asarray(z, np.float64)
        zd = mi.Float(z.astype(np.float32))
        dr.enable_grad(zd)
        xr = self.bridge(zd, exact=z)
        xr_np = self.bridge.last
        img = self.renderer.render(xr, self.gamma, self.albedo, parts_x=posed_parts(self.model, z, self.vec))
        r = self.G(np.array(img, np.float32)[..., :3] * self.mask) - self.target
        psi, dpsi = huber_rows(r, self.robust)
        prior, Jp = self._prior_rows(z)
        rows, g_xr = [prior], np.zeros_like(xr_np)
        if self.curves is not None:
            rc, g_xr = self.curves.position_gradient(xr_np)
            rows.append(np.sqrt(self.lam1) * rc)
            g_xr = self.lam1 * g_xr
        g_pupils = 0.0
        if self.curves is not None and self.curves.irises:      # the gaze rows: pupils and eye corners
            ri, Ji, vids, dx = self.curves.iris_terms(z, xr_np)
            rows.append(np.sqrt(self.lam1) * ri)
            g_pupils = self.lam1 * ri @ Ji
            np.add.at(g_xr, vids, self.lam1 * ri[:, None, None] * dx)
        dr.backward(dr.sum(img.array * self._image_adjoint(psi * dpsi).array)
                    + dr.sum(xr * mi.Float(g_xr.astype(np.float32).ravel())))
        g = np.array(dr.grad(zd), np.float64) + prior @ Jp + g_pupils
        return self._cost(psi, np.concatenate(rows)), g

    def normal_equations(self, z):
        """Gauss-Newton pieces of Eq. 16 at z, for the dogleg: a lazy ``NormalEquations``.

        The cost needs one render (and, for the simulation, one solve). Its derivatives,
        asked for only when the dogleg accepts z, need d x_R / dz (the rig's, or the
        simulation's tangent solves), the backward pass of this render for g = J^T r, and
        for H = J^T J the image Jacobian: one forward-mode pass per parameter through a
        render at ``jacobian_spp`` (~0.025 s each at 2 spp on a 460x540 window, silhouettes
        included), each sent through G M."""
        from .dogleg import NormalEquations
        _, xr = posed_surface(self.sm, z, self.vec)
        parts_x = posed_parts(self.model, z, self.vec)
        x, img, r = self._render(xr, parts_x)
        rgb = self._rgb                  # this point's render: the analytic Jacobian's edge term
        rr, _ = self._prior_and_curves(z, xr)
        psi, dpsi = huber_rows(r, self.robust)
        cost = self._cost(psi, rr)

        at = {}

        def gradient():
            at["xr"], at["J"] = xr2, Jall = posed_jacobian(self.sm, z, self.vec)
            # backward first: the renderer's adjoint pass reads the scene's current vertex
            # positions, which the Jacobian's render replaces
            g = self._backward(x, img, psi * dpsi, Jall)
            rr2, at["Jr"] = self._prior_and_curves(z, xr2, Jall)
            return g + rr2 @ at["Jr"]

        def hessian(free):
            # the image Jacobian's columns only for the variables that can move
            f = np.flatnonzero(free)
            C = self.image_jacobian(at["xr"], at["J"][f], parts_x=parts_x, index=f, image=rgb)
            if self.robust is not None:
                C *= dpsi[None, :].astype(np.float32)
            H = at["Jr"].T @ at["Jr"]
            H[np.ix_(f, f)] += (C @ C.T).astype(np.float64)
            return H

        return NormalEquations(cost, gradient_fn=gradient, hessian_fn=hessian)

    def image_jacobian(self, xr, Jall, spp=None, parts_x=None, index=None, image=None):
        """J^T of the image residual r = G M (F - F*): (z size, m) float32, one row per
        parameter along d xr / dz_k = Jall[k] (V, 3), for the posed surface xr (V, 3) with the
        inner parts at parts_x (P, 3), fixed. index: the z entries of Jall's rows (default all);
        image: the render at xr (h, w, 3) for the analytic rows' edge term (default the last
        render's).
        jacobian 'analytic': every row by ``analytic_jacobian`` (visibility held fixed, one ray
        cast for all rows); 'forward': every row by ``forward_jacobian``; 'hybrid': the
        blendshape weights' rows analytic and the jaw's and the head pose's 12 by forward mode
        (their image change is mostly the outline's motion, which forward mode samples
        exactly), so the render passes stay 12 whatever the number of blendshapes."""
        if self.jacobian == "forward":
            return self.forward_jacobian(xr, Jall, spp, parts_x)
        if self.jacobian == "analytic":
            return self.analytic_jacobian(xr, Jall, parts_x, image)
        index = np.arange(len(Jall)) if index is None else np.asarray(index)
        shapes = index < self.vec.K
        C = np.empty((len(Jall), len(self.target)), np.float32)
        if shapes.any():
            C[shapes] = self.analytic_jacobian(xr, Jall[shapes], parts_x, image)
        if (~shapes).any():
            C[~shapes] = self.forward_jacobian(xr, Jall[~shapes], spp, parts_x)
        return C

    def analytic_jacobian(self, xr, Jall, parts_x=None, image=None):
        """``image_jacobian`` with visibility held fixed (``render.jacobian``): one ray cast
        linearises the image at xr, and every row is products with its sparse barycentric
        matrix; at silhouettes and occlusion edges, the render's image gradient (``image`` at xr,
        default the last render's) times the skin's motion on the screen (OpenDR's boundary
        derivative; the gradient's backward pass keeps the exact silhouette term of the render)."""
        lin = self.raster.linearise(xr, self.gamma, self.albedo, parts_x=parts_x,
                                    image=self._rgb if image is None else image)
        C = np.empty((len(Jall), len(self.target)), np.float32)

        def rows(k0, block):
            C[k0:k0 + block.shape[-1]] = self.G.columns(block * self.mask[..., None])
        lin.columns(Jall, rows)
        return C

    def forward_jacobian(self, xr, Jall, spp=None, parts_x=None):
        """``image_jacobian`` by Dr.Jit: one forward-mode pass per row through one render of the
        posed surface xr (V, 3) (the inner parts at parts_x (P, 3), fixed) at ``spp`` (default
        ``jacobian_spp``) samples per pixel, seeded as the objective's renders, along
        d xr / dz_k = Jall[k] (V, 3); silhouettes included."""
        dr, mi = self.dr, self.renderer.mi
        C = np.empty((len(Jall), len(self.target)), np.float32)
        with _forward_mode(dr):
            x = mi.Float(xr.astype(np.float32).ravel())
            dr.enable_grad(x)
            img = self.renderer.render(x, self.gamma, self.albedo, spp=spp or self.jacobian_spp, parts_x=parts_x)
            for k in range(len(Jall)):
                dr.set_grad(x, mi.Float(Jall[k].astype(np.float32).ravel()))
                dr.enqueue(dr.ADMode.Forward, x)
                dr.traverse(dr.ADMode.Forward, flags=dr.ADFlag.ClearInterior)
                self.G(np.array(dr.grad(img), np.float32)[..., :3] * self.mask, out=C[k])
                dr.clear_grad(img)
        return C


def huber_rows(r, delta):
    """Residual rows psi(r) whose half squared norm is the Huber loss of r with threshold
    ``delta`` (quadratic within it, linear beyond: an occluder's pixels pull with a bounded
    force), and d psi / d r (both like r). psi = r inside, sign(r) sqrt(2 delta |r| - delta^2)
    outside; psi psi' = clip(r, -delta, delta). delta None: the plain L2 rows (r, 1)."""
    if delta is None:
        return r, np.ones_like(r)
    a = np.abs(r)
    out = a > delta
    psi = np.where(out, np.sign(r) * np.sqrt(np.maximum(2 * delta * a - delta * delta, 0.0)), r)
    dpsi = np.where(out, delta / np.maximum(np.abs(psi), 1e-30), 1.0)
    return psi.astype(r.dtype), dpsi.astype(r.dtype)


class _forward_mode:
    """Dr.Jit settings under which a recorded render can be differentiated forwards again
    and again: loops, calls and conditionals evaluated, not recorded symbolically."""

    def __init__(self, dr):
        self.scopes = [dr.scoped_set_flag(f, False) for f in
                       (dr.JitFlag.SymbolicLoops, dr.JitFlag.SymbolicCalls, dr.JitFlag.SymbolicConditionals)]

    def __enter__(self):
        for sc in self.scopes:
            sc.__enter__()

    def __exit__(self, *exc):
        for sc in reversed(self.scopes):
            sc.__exit__(*exc)


def level_inputs(level, camera, plate, mask, render):
    """A coarse stage's ``ShadingObjective`` inputs: (camera, plate, mask, render options)
    at pyramid level ``level`` (``Camera.pyramid_level``; plate, mask and render["backplate"]
    pyrDown-ed), with the pyramid's remaining levels, the curve term on the plate's own
    camera, and the image rows weighted as on the whole pyramid (a smooth residual's
    squares sum in proportion to the samples)."""
    full, levels = Pyramid(camera.height, camera.width), LEVELS - level
    render = dict(render)
    plate, mask, render["backplate"] = (None if a is None else _pyr_down(a, level)
                                        for a in (plate, mask, render.get("backplate")))
    render.update(curve_camera=camera, levels=levels)
    camera = camera.pyramid_level(level)
    render["image_weight"] = len(full) / len(Pyramid(camera.height, camera.width, levels))
    return camera, plate, mask, render


def _pyr_down(image, level):
    """``image`` (H, W) or (H, W, C) after ``level`` OpenCV pyrDowns (the pyramid's level), float32."""
    import cv2
    a = np.asarray(image, np.float32)
    for _ in range(level):
        a = cv2.pyrDown(a, borderType=cv2.BORDER_REFLECT_101)
    return a


def face_window(camera, xr, margin=0.15, align=1 << (LEVELS - 1)):
    """(x0, y0, width, height) px: the bounding box of the posed surface xr (V, 3) in the
    camera's image, grown by ``margin`` of its size (+8 px) on every side for the motion of
    a fit, clipped to the image, corners on multiples of ``align`` (the pyramid's levels
    then sample the same pixels as on the whole plate)."""
    uv, _ = camera.project(xr)
    lo, hi = uv.min(0), uv.max(0)
    pad = margin * (hi - lo).max() + 8
    size = np.array(camera.size)
    a = np.clip(np.floor((lo - pad) / align) * align, 0, size).astype(int)
    b = np.clip(np.ceil((hi + pad) / align) * align, 0, size).astype(int)
    if np.any(b - a < 2 * align):
        return 0, 0, int(size[0]), int(size[1])
    return int(a[0]), int(a[1]), int(b[0] - a[0]), int(b[1] - a[1])


EYE_OPENINGS = (("eye_L_upper", "eye_L_lower"), ("eye_R_upper", "eye_R_lower"))


def without_eyes(mask, curves, shape):
    """The data term's mask (H, W) float32 (``mask`` (H, W) or None: all ones) less the eye
    openings between the plate's lid curves (``curves`` {name: (n, 2) px}, EYE_OPENINGS).
    The model's eyeballs turn with the gaze that the plate's irises set (the curve term's iris
    rows, ``fit.curves.IRIS_CURVES``), but they carry no gradient in the image Jacobian (held
    still there); the iris and the pupil moving with the pose put a 25 % error into the
    translation's Jacobian column (1677 against 2241 from differences) on the small head. The
    lids' edges against the eyes stay in the term where the model's lids are more open than the
    plate's. A photo's detector mask has the openings removed already (``landmarks.face_mask``)."""
    import cv2
    out = (np.ones(shape, np.float32) if mask is None else np.asarray(mask, np.float32).reshape(shape)).copy()
    for up, lo in EYE_OPENINGS:
        if curves and up in curves and lo in curves:
            ring = np.concatenate([np.asarray(curves[up], float), np.asarray(curves[lo], float)[::-1]])
            cv2.fillPoly(out, [np.round(ring * 16).astype(np.int32)], 0.0, lineType=cv2.LINE_8, shift=4)
    return out


def fit_shading(model, camera, plate, gamma, albedo, p_hat, rotation, translation, kind="blendshape",
                curves=None, lam1=EQ16_LAMBDA_1, lam2=EQ16_LAMBDA_2, mask=None, max_iter=25, p0=None,
                solver="dogleg", ftol=5e-3, restarts=2, previous=None, temporal=0.0, progress=None, level=0,
                radius=1.0, **render):
    """Solve Eq. 16 from the curve solution (p_hat (K+6,), rotation (3,), translation (3,)), or
    from p0 (K+6,) when given (p_hat stays the prior's centre).

    plate: linear (H, W, 3) float, undistorted, the camera's size; gamma (9, 3), albedo (V, 3)
    from the calibration; curves: the plate curves of Eq. 15 or None; mask (H, W) bool or None:
    the plate pixels of the data term, less the eye openings between the curves' lids
    (``without_eyes``). solver: "dogleg" (the paper's: Gauss-Newton on the
    image Jacobian, ``ShadingObjective.normal_equations``: analytic with visibility held fixed,
    or Dr.Jit's forward-mode passes with the render option jacobian="forward") or
    "lbfgs" (the gradient-only path: L-BFGS-B on adjoint gradients, one render and one
    backward pass per evaluation, for parameter counts where K+12 forward passes are too
    many); max_iter: iterations of either; ftol: the dogleg stops after a step that lowers
    the cost by less than this fraction; previous (z size,) and temporal (linear light^2 per
    ``FitVector.scales()`` unit^2): a sequence's previous frame and the temporal term's
    weight. level: 0 fits the plate's whole pyramid; 1 a coarse stage, the render at half the
    plate's resolution against the pyramid's lower levels (level 1 of the plate and below,
    their weight raised to the whole pyramid's), a quarter of the pixels to render and
    differentiate. radius: the dogleg's first trust radius in ``FitVector.scales()`` units.
    ``render`` options go to ``ShadingObjective`` (spp, silhouette_spp, seed, jacobian,
    jacobian_samples, jacobian_spp, lam_curves, backplate: default the plate with the head
    filled in from its surroundings). Returns a ShadingFit."""
    from .dogleg import dogleg, with_linear_term
    sm, vec = model.surface_model(kind), FitVector.of(model)
    z0 = vec.pack(p_hat if p0 is None else p0, rotation, translation)
    xr0 = posed_surface(sm, z0, vec)[1]
    if "backplate" not in render:
        render["backplate"] = background_plate(plate, head_silhouette(camera, xr0, model.triangles))
    mask = without_eyes(mask, curves, plate.shape[:2])
    if level:
        camera, plate, mask, render = level_inputs(level, camera, plate, mask, render)
    window = face_window(camera, xr0, align=1 << (render.get("levels", LEVELS) - 1))
    obj = ShadingObjective(model, sm, camera, plate, gamma, albedo, p_hat, curves, lam1, lam2, mask,
                           window=window, previous=previous, temporal=temporal, **render)
    # one unit of the optimiser's variables (``FitVector.scales``): the balance evens out the
    # curvature the solvers see; the size sets L-BFGS's first trial step and the dogleg's
    # first trust radius (``radius``; from the curve solution a unit step of a weight by 1 or
    # the head by 0.1 rad overshot to costs 10-15x the start's)
    s = vec.scales()
    lo, hi = vec.bounds()
    history, t0 = [], time.perf_counter()

    def log(f, **extra):
        history.append({"iteration": len(history), "cost": f, **obj.terms, **extra,
                        "seconds": time.perf_counter() - t0})
        if progress is not None:
            progress(history[-1])

    if solver == "dogleg":
        def fun(u):
            try:
                ne = obj.normal_equations(u * s)
            except SimulationError:
                # the dogleg rejects this trial; its log entry keeps the verdicts aligned
                history.append({"iteration": len(history), "failed": True, "seconds": time.perf_counter() - t0})
                raise
            log(ne.cost)
            return _ScaledEquations(ne, s)
        relief = obj.curves.gaze if obj.curves is not None else None
        res = dogleg(with_linear_term(fun, sparsity_slopes(vec, lam2, relief=relief) * s), z0 / s, lo / s, hi / s,
                     max_iter=max_iter, radius=radius, ftol=ftol, min_radius=1e-2, adapt_curvature=True)
        for h, step in zip(history[1:], res.history):       # the dogleg's verdict on each trial
            h.update(accepted=step["accepted"], rho=step["rho"], radius=step["radius"], mu=step["mu"])
        z, status = res.x * s, res.status
    elif solver == "lbfgs":
        z, status = _lbfgs(obj, z0, s, lo, hi, max_iter, restarts, log)
    else:
        raise InvfaceError(f"unknown solver '{solver}': use 'dogleg' or 'lbfgs'")
    p, rot, tr = vec.unpack(z)
    return ShadingFit(p=p, rotation=rot, translation=tr, history=history, status=status)


class _ScaledEquations:
    """NormalEquations in the scaled variables u = z / s: g_u = s g, H_u = s H s."""

    def __init__(self, ne, s):
        self.ne, self.s, self.cost = ne, s, ne.cost

    @property
    def gradient(self):
        return self.s * self.ne.gradient

    @property
    def hessian(self):
        return self.hessian_on(None)

    def hessian_on(self, free):
        return self.ne.hessian_on(free) * np.outer(self.s, self.s)


def _lbfgs(obj, z0, s, lo, hi, max_iter, restarts, log):
    """L-BFGS-B on the adjoint gradient in scaled variables: (z, status)."""
    from scipy.optimize import minimize
    seen = []

    def fun(u):
        try:
            f, g = obj(u * s)
        except SimulationError:
            if not seen:
                raise
            # the simulation cannot reach this trial point: a cost above every one seen
            # makes the line search step back, as the dogleg rejects such a step
            log(10 * max(seen), failed=True)
            return 10 * max(seen), np.zeros(len(u))
        seen.append(f)
        log(f)
        return f, g * s

    bounds = list(zip(np.where(np.isfinite(lo), lo / s, None), np.where(np.isfinite(hi), hi / s, None)))
    u, status = z0 / s, ""
    # The sampled image is piecewise constant where silhouettes cross fixed samples, so the
    # line search can stop on a sample pattern; restarting with fresh samples continues.
    for restart in range(restarts + 1):
        obj.renderer.seed = obj.renderer.seed + restart
        res = minimize(fun, u, jac=True, method="L-BFGS-B", bounds=bounds,
                       options={"maxiter": max_iter, "maxfun": 2 * max_iter, "ftol": 1e-4, "gtol": 1e-6})
        u, status = res.x, str(res.message)
        if "ABNORMAL" not in status or len(seen) >= 2 * max_iter:
            break
    return u * s, status
