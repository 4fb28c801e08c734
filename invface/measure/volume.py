"""Volume change of the flesh around the lips, for comparing the two model kinds.

Blendshapes do not preserve volume; the simulation's flesh is quasi-incompressible (paper
000, Sec. 4 and its lip-volume comparison). The lip region is the orbicularis oris muscle's
tets. For the simulation the deformed tet mesh is the solve's X; for the blendshape model
it is the rig's volumetric extension, the Poisson displacement fields of Eq. 11 (the
muscle-track precompute, ``model.track_displacements``) blended with the same weights and
skinned with the volumetric jaw weights: the volume the blendshape deformation implies.
"""
from __future__ import annotations

import numpy as np

from ..errors import InvfaceError
from ..model.controls import FitVector
from ..model.rig import skin

LIP_MUSCLE = "orbicularis_oris"


def tet_volumes(X, tets):
    """Signed volumes (T,) m^3 of tets (T, 4) at positions X (N, 3)."""
    a, b, c, d = (X[tets[:, k]] for k in range(4))
    return np.einsum("ij,ij->i", np.cross(b - a, c - a), d - a) / 6.0


def blendshape_volume(model, p):
    """Tet positions (N, 3) that the blendshape rig implies for parameters p (K+6,)."""
    vec = FitVector.of(model)
    dX = model.track_displacements
    if dX is None or np.shape(dX) != (vec.K, len(model.rest_positions), 3):
        from ..sim.poisson import track_displacements
        dX = track_displacements(model)
    p = np.asarray(p, float)
    X = model.rest_positions + np.tensordot(p[vec.weights], dX, axes=(0, 0))
    return skin(X, model.volume_jaw_weights, model.jaw_matrix(p[vec.jaw]))


def lip_volume_change(model, p, X=None):
    """Relative volume change (fraction) of the lip muscle's tets for parameters p; X (N, 3)
    is the deformed tet mesh (the simulation's), or None for the blendshape model's."""
    if LIP_MUSCLE not in model.muscle_names:
        raise InvfaceError(f"the model has no '{LIP_MUSCLE}' muscle to measure the lip volume")
    tets = model.tets[model.muscle(LIP_MUSCLE).tets]
    X = blendshape_volume(model, p) if X is None else X
    v0 = tet_volumes(model.rest_positions, tets).sum()
    return float(tet_volumes(X, tets).sum() / v0 - 1.0)
