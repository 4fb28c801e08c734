"""The Dr.Jit bridge: controls -> surface vertices as a differentiable Dr.Jit operation.

    import drjit as dr
    op = invface.bridge.SurfaceFunction(model.surface_model("simulation"))
    p = dr.llvm.ad.Float(model.parameters(w)); dr.enable_grad(p)
    x = op(p)                         # flat Float (3V,), vertex-major x0 y0 z0 x1 ...
    loss = image_loss(render(x)); dr.backward(loss); p.grad  # reaches the controls

The forward runs the surface model (blendshape rig or driven simulation) in float64 numpy;
the reverse pass calls its adjoint (``surface_vjp``: one sparse back-substitution for the
simulation) and forward-mode AD its tangent Jacobian, the pattern of Mitsuba's
``mi.ad.LargeSteps`` (a sparse solve inside a ``dr.CustomOp``). This module is the one place
where the simulation's derivatives meet Dr.Jit arrays.

``PosedSurfaceFunction`` adds the rigid head pose, z = (p, rotation, translation) -> x_R:
shape from shading's gradient-only path (``fit.shading.ShadingObjective.__call__``, what
``--solver lbfgs`` calls) renders its output, so one ``dr.backward`` reaches every control
and the pose through one adjoint product.
"""
from __future__ import annotations

import drjit as dr
import numpy as np


class _SurfaceOp(dr.CustomOp):
    def eval(self, model, p):
        self.model = model
        self.ftype = type(p)
        self.p = np.array(p, dtype=np.float64)
        x = model.surface(self.p)
        return self.ftype(np.ascontiguousarray(x, np.float32).reshape(-1))

    def forward(self):
        dp = np.array(self.grad_in("p"), dtype=np.float64)
        J = self.model.surface_jacobian(self.p)                    # (P, V, 3)
        self.set_grad_out(self.ftype(np.tensordot(dp, J, axes=(0, 0)).reshape(-1).astype(np.float32)))

    def backward(self):
        gx = np.array(self.grad_out(), dtype=np.float64).reshape(-1, 3)
        self.set_grad_in("p", self.ftype(self.model.surface_vjp(self.p, gx).astype(np.float32)))

    def name(self):
        return "invface surface x(w)"


class _PosedSurfaceOp(dr.CustomOp):
    def eval(self, function, z, exact):
        from .model.pose import posed_surface
        self.model, self.vector, self.ftype = function.model, function.vector, type(z)
        self.z = np.array(z, dtype=np.float64) if exact is None else np.asarray(exact, np.float64)
        self.x, xr = posed_surface(self.model, self.z, self.vector)
        function.last = xr
        return self.ftype(np.ascontiguousarray(xr, np.float32).reshape(-1))

    def forward(self):
        from .model.pose import posed_jacobian
        dz = np.array(self.grad_in("z"), dtype=np.float64)
        _, J = posed_jacobian(self.model, self.z, self.vector)              # (size, V, 3)
        self.set_grad_out(self.ftype(np.tensordot(dz, J, axes=(0, 0)).reshape(-1).astype(np.float32)))

    def backward(self):
        from .model.pose import posed_vjp
        g = np.array(self.grad_out(), dtype=np.float64).reshape(-1, 3)
        self.set_grad_in("z", self.ftype(posed_vjp(self.model, self.z, self.vector, g, x=self.x).astype(np.float32)))

    def name(self):
        return "invface posed surface x_R(z)"


class SurfaceFunction:
    """Callable: Dr.Jit Float parameters p (K+6,) -> flat Float vertex positions (3V,) m.

    model: a surface model (FaceModel.surface_model(kind)); the gradient flows to p."""

    def __init__(self, model):
        self.model = model

    def __call__(self, p):
        return dr.custom(_SurfaceOp, self.model, p)


class PosedSurfaceFunction:
    """Callable: Dr.Jit Float fit vector z = (p, rotation, translation) (``FitVector``) ->
    flat Float posed positions x_R = R(rotation) x(p) + translation (3V,) m.

    The pose is applied in float64 numpy inside the operation, so the positions are those
    of ``model.pose.posed_surface`` to float32 rounding; the reverse pass is one adjoint product
    (``model.pose.posed_vjp``: the surface model's ``surface_vjp`` once). exact: z as float64
    numpy, for the surface model to be evaluated there rather than at z's float32 values (the
    optimiser's point, exactly); ``last`` keeps the float64 positions of the last call."""

    def __init__(self, model, vector):
        self.model, self.vector = model, vector
        self.last = None                # the last posed positions (V, 3), float64

    def __call__(self, z, exact=None):
        return dr.custom(_PosedSurfaceOp, self, z, exact)
