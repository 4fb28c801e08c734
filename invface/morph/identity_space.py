"""The built-in head's face-shape space: ICT-FaceKit's 20 identity shapes carried onto it.

``template/data/identity_ict.npz`` holds ICT-FaceKit's first 20 identity (PCA) shapes as offsets
of the template's render skin at resolution 1, derived by ``scripts/derive_identity_shapes.py``
(MIT; the licence is ``template/data/LICENSE-ICT-FaceKit.txt``). The space lives with the
builder because it is carried onto a face as the builder carries shapes. They are ICT's components scaled by their
standard deviations: a face of the space is the neutral plus sum_i c_i S_i, c ~ N(0, 1). The
identity fit (``fit.identity``) moves a neutral within this space before its smooth field,
and ``morph.build.adapt_identity`` carries the anatomy (skull, muscles, tets) along.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import BundleError
from ..io.arrays import load_npz
from .transfer import spread

DATA = Path(__file__).parent.parent / "template" / "data" / "identity_ict.npz"


def load(path=DATA):
    """The stored space: {'deltas' (K,V0,3) m, 'neutral' (V0,3) m, 'triangles' (F0,3)} on the
    template's render skin at resolution 1."""
    a = load_npz(path, BundleError, "identity shape file")
    return {"deltas": a["deltas_mm"].astype(float) / 1000.0, "neutral": np.asarray(a["neutral"], float),
            "triangles": np.asarray(a["triangles"], np.int64)}


def identity_shapes(model, path=DATA):
    """The space's shapes (K,V,3) m on ``model``'s neutral, or None where it has no place:
    - a model with the stored skin's topology (the built-in head at resolution 1, or an actor
      morphed from it) takes them vertex for vertex, scaled by the ratio of the faces' sizes
      (as ``morph.transfer.carry_offsets``);
    - the built-in head at another resolution takes them by closest point on the stored skin;
    - any other model (an actor from another template) has no space (None)."""
    from ..template.arkit_shapes import carry
    shapes = load(path)
    X0, X = shapes["neutral"], np.asarray(model.neutral, float)
    if X.shape == X0.shape:
        from .build import face_vertices
        face = face_vertices(model)
        return shapes["deltas"] * (spread(X, face) / spread(X0, face))
    if model.meta.get("generator") == "invface.template":
        return carry(shapes, X, model.triangles)
    return None
