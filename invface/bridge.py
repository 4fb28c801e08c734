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


class SurfaceFunction:
    """Callable: Dr.Jit Float parameters p (K+6,) -> flat Float vertex positions (3V,) m.

    model: a surface model (FaceModel.surface_model(kind)); the gradient flows to p."""

    def __init__(self, model):
        self.model = model

    def __call__(self, p):
        return dr.custom(_SurfaceOp, self.model, p)

