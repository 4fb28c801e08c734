"""FaceModel: everything about one actor (surface rig, anatomy, muscles), one .npz bundle."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InvfaceError
from .bundle import read_bundle, write_bundle
from .controls import Controls
from .muscle import Muscle  # noqa: F401 - FaceModel.muscles holds them; importable from here
from .parts import InnerParts
from .rig import BlendshapeRig, jaw_transform, skin


# kind -> factory(model) of a surface model x(p); a factory may be given as "module:attribute",
# imported on first use, so the model layer names no layer above it (the package's
# __init__ registers the simulation).
_SURFACE_MODELS = {"blendshape": BlendshapeRig}


def register_surface_model(kind, factory):
    """Make ``FaceModel.surface_model(kind)`` build ``factory(model)``: a callable or a
    "package.module:Name" string imported on first use. The surface model has
    parameter_names, surface(p) (V,3) m, surface_jacobian(p) (P,V,3) and surface_vjp(p, gx) (P,)."""
    _SURFACE_MODELS[str(kind)] = factory


def _surface_factory(kind):
    f = _SURFACE_MODELS[kind]
    if isinstance(f, str):
        import importlib
        module, _, name = f.partition(":")
        f = _SURFACE_MODELS[kind] = getattr(importlib.import_module(module), name)
    return f


@dataclass
class FaceModel:
    """An actor's face: hybrid blendshape rig (Eq. 1-2) plus the anatomical model.

    Shapes: V surface vertices, F triangles, K blendshapes, N tet vertices, T tets.
    All positions in metres (+Y up, face along +Z, +X the actor's left).
    """
    neutral: np.ndarray                 # (V,3)
    triangles: np.ndarray               # (F,3)
    blendshape_names: list              # K names (FACS-style)
    blendshapes: np.ndarray             # (K,V,3) deltas
    jaw_pivot: np.ndarray               # (3,)
    jaw_frame: np.ndarray               # (3,3) columns = jaw axes (x = hinge axis)
    jaw_weights: np.ndarray             # (V,) surface skinning weights in [0,1]
    rest_positions: np.ndarray          # (N,3)
    tets: np.ndarray                    # (T,4)
    fixed_cranium: np.ndarray           # tet-vertex ids attached to the cranium
    fixed_jaw: np.ndarray               # tet-vertex ids attached to the jaw
    embed_tets: np.ndarray              # (V,) tet containing each surface vertex
    embed_weights: np.ndarray           # (V,4) barycentric weights
    volume_jaw_weights: np.ndarray      # (N,)
    muscles: list                       # list[Muscle]
    landmarks: dict                     # name -> surface vertex id
    curves: dict                        # name -> (n,) surface vertex ids (polyline)
    cranium_mesh: tuple                 # (vertices (Bc,3), triangles (Fc,3))
    jaw_mesh: tuple                     # (vertices (Bj,3), triangles (Fj,3))
    blendshape_activations: np.ndarray = None   # (K, M) activations that made each shape
    track_displacements: np.ndarray = None      # (K,N,3) Poisson dX_k (paper 000 Eq. 11)
    scan_transform: np.ndarray = None           # (4,4) input scan frame -> model frame (morphed models)
    parts: InnerParts = None                    # eyes, teeth, tongue, mouth lining (rendered, rigid)
    meta: dict = field(default_factory=dict)
    _surface_models: dict = field(default_factory=dict, repr=False, compare=False)
    _embedding: object = field(default=None, repr=False, compare=False)

    # -- public API -------------------------------------------------------------------
    @classmethod
    def load(cls, path) -> "FaceModel":
        """Load and validate a bundle; raises BundleError naming the bad field."""
        return cls(**read_bundle(path))

    def save(self, path) -> None:
        """Write the bundle atomically (temporary file, then rename)."""
        write_bundle(self, path)

    @property
    def muscle_names(self):
        return [m.name for m in self.muscles]

    def muscle(self, name) -> Muscle:
        for m in self.muscles:
            if m.name == name:
                return m
        raise InvfaceError(f"unknown muscle '{name}'; the model has: {', '.join(self.muscle_names)}")

    def jaw_matrix(self, jaw) -> np.ndarray:
        """4x4 jaw transform for jaw parameters (6,)."""
        return jaw_transform(jaw, self.jaw_pivot, self.jaw_frame)

    def parts_positions(self, w=None):
        """Positions (P,3) m of the inner parts (``parts``) before the head pose, for controls
        w (Controls, dict, or a parameter vector p (K+6,)): the upper teeth and eyes stay with
        the cranium, the lower teeth and tongue follow the jaw, the tongue slides out by
        tongueOut (``model.tongue``), and each eyeball turns about its centre by the eyeLook
        controls' gaze (``model.gaze``). None without parts."""
        from .gaze import Eyes
        from .rig import skin
        from .tongue import Tongue
        if self.parts is None:
            return None
        K = len(self.blendshape_names)
        p = w if isinstance(w, np.ndarray) and w.shape == (K + 6,) else self.parameters(w)
        rest = Tongue(self).rest_parts(self.parts.vertices, p)
        return Eyes(self).turn_parts(self.parts, skin(rest, self.parts.jaw_weights, self.jaw_matrix(p[K:])), p)

    def surface(self, w=None, kind="blendshape") -> np.ndarray:
        """Surface vertex positions x(w) (V,3) in metres, before the rigid head pose.

        kind="blendshape": Eq. 1-2, x = T(j)(n + B b).
        kind="simulation": the blendshape-driven muscle simulation (paper 000 Sec. 6),
        warm-started from this model's previous simulation call.
        """
        return self.surface_model(kind).surface(self.parameters(w))

    def parameters(self, w=None) -> np.ndarray:
        """Parameter vector p = (b (K,), jaw (6,)) of controls w (Controls or dict)."""
        c = Controls.coerce(w, self.blendshape_names)
        return np.concatenate([c.weight_vector(self.blendshape_names), c.jaw])

    def __getstate__(self):
        """Pickle the model's data only: the surface models and the embedding are rebuilt on
        first use (a simulation's solver holds native handles that cannot be pickled; a Dask
        worker receives the model this way)."""
        state = dict(self.__dict__)
        state["_surface_models"], state["_embedding"] = {}, None
        return state

    def replace(self, **changes) -> "FaceModel":
        """A copy with the given fields changed (``dataclasses.replace``), its surface models and
        embedding rebuilt on first use from the new data."""
        import dataclasses
        return dataclasses.replace(self, **changes, _surface_models={}, _embedding=None)

    def forget_surface_models(self):
        """Drop the surface models made so far: the next solve starts cold (benches time it)."""
        self._surface_models.clear()

    def surface_model(self, kind="blendshape"):
        """The model x(p) of ``kind`` (created once per FaceModel): parameter_names,
        surface(p), surface_jacobian(p) (P,V,3) and surface_vjp(p, gx) (P,)."""
        if kind not in _SURFACE_MODELS:
            raise InvfaceError(f"unknown surface kind '{kind}': use " + " or ".join(map(repr, _SURFACE_MODELS)))
        if kind not in self._surface_models:
            self._surface_models[kind] = _surface_factory(kind)(self)
        return self._surface_models[kind]

    def embedding_matrix(self):
        """Sparse W (V, N), surface = W @ tet positions (computed once per FaceModel).

        meta["skin_embedding"] names the method: {"method": "moving_least_squares", ...} for
        morphed models (mesh.embedding, made from the barycentric embedding and the rest mesh,
        so the bundle stores only these parameters); absent: barycentric (embed_tets/weights)."""
        if self._embedding is None:
            from ..mesh.embedding import embedding_matrix
            self._embedding = embedding_matrix(self.rest_positions, self.tets, self.neutral, self.embed_tets,
                                               self.embed_weights, self.meta.get("skin_embedding"))
        return self._embedding

    def embedded_surface(self, X) -> np.ndarray:
        """Surface positions (V,3) from tet-mesh positions X (N,3) through the embedding."""
        return self.embedding_matrix() @ X

    def skinned_volume(self, jaw) -> np.ndarray:
        """Rest tet positions moved rigidly by the jaw with volumetric jaw weights (N,3)."""
        return skin(self.rest_positions, self.volume_jaw_weights, self.jaw_matrix(jaw))

    def summary(self) -> dict:
        """Counts and quality figures for printing."""
        from ..mesh.tets import quality_summary
        q = quality_summary(self.rest_positions, self.tets)
        return {"surface_vertices": int(len(self.neutral)), "surface_triangles": int(len(self.triangles)),
                "blendshapes": len(self.blendshape_names), "muscles": len(self.muscles),
                "muscle_tets": int(sum(len(m.tets) for m in self.muscles)),
                "fixed_cranium": int(len(self.fixed_cranium)), "fixed_jaw": int(len(self.fixed_jaw)),
                "landmarks": len(self.landmarks), "curves": len(self.curves),
                "skin_embedding": (self.meta.get("skin_embedding") or {}).get("method", "barycentric"),
                **q}
