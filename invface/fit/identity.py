"""The actor's identity from one plate's curves: a smooth correction of the model's neutral.

A model built from another face (the template, or an actor scanned once) leaves a fixed gap to
the person in a clip: lid and lip shapes the controls cannot make, since the blendshapes and
muscles change an expression, not a face. On a real phone clip the curve RMS sat at 3.0 px on
every frame, flat over time (bench/RESULTS.md, issue 28). Paper 000 starts from an actor
model built from a scan of that actor (paper 001); from video alone, the neutral-looking frame
the calibration is made on (Eq. 14) stands in for the scan. With that frame's controls and pose
from Eq. 15 held, the neutral moves by a displacement field d (V,3) m minimising

    sum_i r_i(d)^2 + mu * int |Delta d|^2 dA + eps * int |d|^2 dA

r_i: Eq. 15's signed pixel distances of the model curves' vertices to the plate curves;
Delta: the surface's finite-volume Laplacian (``morph.surface.fv_laplacian``), so the field is
smooth over ``IDENTITY_LENGTH`` and cannot copy the frame's pixel noise into the face; the
small eps term keeps the field near zero where no curve is (the depth along the view is only
known through the smoothness). Gauss-Newton on the foot points, each step one sparse solve.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from ..errors import InvfaceError
from ..model.rig import euler_xyz
from .curves import CurveObjective, rms_px
from .pose import pose_points

IDENTITY_LENGTH = 0.007     # m: the smoothness scale of the identity field (a third of an eye's width;
                            # on the real clip 0.012 left 2.05 px on frames not fitted, 0.007 1.9 px)
IDENTITY_ANCHOR = 0.06      # m: beyond this from the curves the field fades to zero
IDENTITY_MAX_MM = 12.0      # a larger correction is not an identity: not applied (wrong frame or curves)


@dataclass
class IdentityFit:
    """displacement (V,3) m of the neutral; rms_before / rms_after px on the fitting frame;
    max_mm: the largest vertex displacement."""
    displacement: np.ndarray
    rms_before: float
    rms_after: float
    max_mm: float

    def describe(self):
        return (f"identity from the curves: curve RMS {self.rms_before:.2f} -> {self.rms_after:.2f} px on the "
                f"fitting frame, neutral moved up to {self.max_mm:.1f} mm")


def _operators(model):
    from ..morph.surface import fv_laplacian
    A, area = fv_laplacian(model.neutral, model.triangles)
    Minv = sp.diags(1.0 / np.maximum(area, 1e-30))
    return (A @ Minv @ A).tocsr(), sp.diags(area)


def fit_identity(model, camera, curves, p, rotation, translation, iterations=6, length=IDENTITY_LENGTH):
    """Smooth neutral correction (IdentityFit) so that the model at controls p (P,), posed by
    rotation (3,) rad and translation (3,) m, meets the plate curves {name: (n,2) px} seen by
    ``camera``. The weight mu of the bi-Laplacian is set so that a correction of width
    ``length`` (m) costs as much as a pixel at each of the vertices of a curve across it:
    mu = (k length)^2 n_per_length, with k the camera's px per metre at the face."""
    obj = CurveObjective(model, model.surface_model("blendshape"), camera, curves, 0.0)
    if not obj.curves:
        raise InvfaceError("identity: none of the plate curves is a model curve")
    x = model.surface_model("blendshape").surface(np.asarray(p, float))
    R = euler_xyz(np.asarray(rotation, float))
    V = len(x)
    K, M = _operators(model)
    depth = float(np.median((pose_points(x, rotation, translation) @ camera.R.T + camera.t)[:, 2]))
    k = float(camera.K[0, 0]) / max(depth, 1e-6)                       # px per metre at the face
    spacing = float(np.median([np.linalg.norm(np.diff(x[v], axis=0), axis=1).mean() for v in obj.vertices.values()]))
    mu = (k * length) ** 2 * (length / spacing)
    eps = mu / IDENTITY_ANCHOR ** 4
    reg = sp.kron(mu * K + eps * M, sp.eye(3)).tocsr()
    d = np.zeros((V, 3))

    def data(d):
        xr = pose_points(x + d, rotation, translation)
        rows, g, blocks = [], np.zeros((V, 3)), []
        for vid, r, dr_dx in obj._signed(xr):
            a = dr_dx @ R                         # d r / d d_i (n, 3): the correction is posed with the head
            np.add.at(g, vid, r[:, None] * a)
            rows.append(r)
            blocks.append((vid, a))
        return np.concatenate(rows), g, blocks

    r0, g, blocks = data(d)
    r = r0
    for _ in range(iterations):
        vid = np.concatenate([v for v, _ in blocks])
        a = np.concatenate([a for _, a in blocks])                          # (n, 3)
        rows = 3 * vid[:, None, None] + np.arange(3)[None, :, None]          # (n, 3, 1)
        cols = 3 * vid[:, None, None] + np.arange(3)[None, None, :]          # (n, 1, 3)
        rows, cols = np.broadcast_arrays(rows, cols)
        H = reg + sp.coo_matrix((np.einsum("ns,nt->nst", a, a).ravel(), (rows.ravel(), cols.ravel())),
                                shape=(3 * V, 3 * V)).tocsr()
        step = spsolve(H.tocsc(), -(reg @ d.ravel() + g.ravel())).reshape(V, 3)
        d = d + step
        r, g, blocks = data(d)
        if np.abs(step).max() < 1e-6:
            break
    rms = lambda r: rms_px({"all": r})         # noqa: E731
    return IdentityFit(d, rms(r0), rms(r), float(np.linalg.norm(d, axis=1).max() * 1e3))
