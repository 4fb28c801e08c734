"""Generate the built-in anatomical head deterministically, and cache it."""
from __future__ import annotations

import hashlib
import os
import time
from pathlib import Path

import numpy as np

from ..errors import ConfigError, MeshError
from ..mesh.tets import harmonic, laplacian, orient, quality_summary
from ..model.facemodel import FaceModel
from . import grid
from .eyelids import lid_inner_radii, on_eyeball, open_lids
from .features import find_features
from .muscles import build_muscles
from .parts import template_parts
from .shape import JAW_PIVOT, MOUTH_Y, tissue_depth
from .skull import skull_meshes
from .shell import embed_fine, layer_radii, prism_tets
from .surfaces import build_grids

GENERATOR_VERSION = "7"     # 2: the inner parts; 3: the skull; 4: the ARKit shapes; 5: tongueOut; 6: the jaw line;
                            # 7: the canthi under the pupils
# Quality bounds every generated mesh must meet (checked at build time and in the tests).
MIN_DIHEDRAL_DEG = 1.0
MIN_RADIUS_RATIO = 0.005
_DEPTH_RANGE = (0.003, 0.035)


def depth_of(p):
    """Soft-tissue depth (m) along the ray at skin points p (..., 3), clamped to a sane range."""
    return np.clip(tissue_depth(p), *_DEPTH_RANGE)


def sizes(resolution):
    """Grid and layer counts for a resolution factor (1 = default, ~35k tets; tets ~ linear)."""
    if not (0.05 <= resolution <= 100):
        raise ConfigError(f"template resolution must be in [0.05, 100], got {resolution}")
    layers = max(2, int(round(3 * resolution ** (1 / 3))))
    scale = resolution * 3 / layers
    n_alpha = int(round(48 * np.sqrt(scale))) | 1
    n_beta = int(round(41 * np.sqrt(scale))) + 1
    factor = max(1, int(np.ceil(3 / np.sqrt(scale))))
    return n_alpha, n_beta, layers, factor


def _regions(P):
    """Classify inner-surface points P (n,3): 0 cranium, 1 jaw, 2 free (lip and cheek mucosa,
    the band along the occlusal line where the mouth opens, and the lids' inner surface on the
    eyeballs, which slides on them)."""
    x, y, z = P[:, 0], P[:, 1], P[:, 2]
    # below the occlusal plane (mouth line tilted up towards the condyles) moves with the jaw
    occl = MOUTH_Y + (0.113 - z) * (JAW_PIVOT[1] - MOUTH_Y) / (0.113 - JAW_PIVOT[2])
    jaw = (y < occl) & (y > -0.105) & (z > -0.005)
    lips = ((x / 0.056) ** 2 + ((y - MOUTH_Y) / 0.017) ** 2 < 1) & (z > 0.02)
    band = (np.abs(y - occl) < 0.007) & (z > 0.0)
    return np.where(lips | band | on_eyeball(P), 2, np.where(jaw, 1, 0))


def _lid_sides(skin):
    """The left eye's slit points (s,3) and the ids of the upper and lower lids' slit
    vertices of both eyes on a SkinGrid (the arguments of ``eyelids.open_lids``)."""
    P = skin.positions()
    upper = [skin.slit_vertices(e, "upper")[1:-1] for e in ("eye_L", "eye_R")]
    lower = [skin.slit_vertices(e, "lower")[1:-1] for e in ("eye_L", "eye_R")]
    return P[skin.slit_vertices("eye_L", "upper")], np.concatenate(upper), np.concatenate(lower)


def generate(resolution=1.0, progress=None, expressions=True):
    """Build the template FaceModel. resolution scales the tet count (~35k at 1, ~350k at 10).

    expressions: the ARKit blendshapes (template.arkit_shapes), the kinematic blinks and
    their muscle-track precompute.
    """
    say = progress or (lambda msg: None)
    t0 = time.perf_counter()
    n_alpha, n_beta, n_layers, factor = sizes(resolution)
    say(f"skin grids {n_alpha}x{n_beta} (render x{factor})")
    coarse, fine = build_grids(n_alpha, n_beta, factor)

    say(f"flesh: {n_layers} layers of prisms")
    X, tets, q, lids = _flesh(coarse, n_layers)
    Ns = len(coarse.positions())
    inner = np.arange(n_layers * Ns, (n_layers + 1) * Ns)
    region = _regions(X[inner])
    fixed_cranium = inner[region == 0]
    fixed_jaw = inner[region == 1]

    say("jaw weights (harmonic solve)")
    Lap = laplacian(X, tets)
    fixed = np.concatenate([fixed_cranium, fixed_jaw])
    vw = harmonic(Lap, fixed, np.concatenate([np.zeros(len(fixed_cranium)), np.ones(len(fixed_jaw))]))
    vw = np.clip(vw, 0.0, 1.0)

    say("embedding the render skin")
    Vf_closed = fine.positions()
    Vf = open_lids(Vf_closed, *_lid_sides(fine))
    etet, ew = embed_fine(coarse, fine, factor, X, tets, n_layers, Vf)
    jaw_w = np.clip(np.einsum("vk,vk->v", ew, vw[tets[etet]]), 0.0, 1.0)

    say("muscles")
    muscles = build_muscles(X, tets, depth_of, warp=lambda P: open_lids(P, lids[0], [], []))

    say("landmarks and curves")
    landmarks, curves = find_features(fine, Vf)

    say("skull and mandible (marching cubes)")
    cranium_mesh, jaw_mesh = skull_meshes()
    # the inner parts: the free mucosa's inner layer moved 1 mm inwards places the incisors
    mucosa = X[inner].copy()
    d = mucosa - grid.CENTER
    mucosa -= np.where(region == 2, 0.001, 0.0)[:, None] * d / np.linalg.norm(d, axis=1, keepdims=True)

    model = FaceModel(
        neutral=Vf, triangles=fine.triangles.astype(np.int64), blendshape_names=[],
        blendshapes=np.zeros((0, len(Vf), 3)), jaw_pivot=JAW_PIVOT.copy(), jaw_frame=np.eye(3),
        jaw_weights=jaw_w, rest_positions=X, tets=tets.astype(np.int64),
        fixed_cranium=fixed_cranium.astype(np.int64), fixed_jaw=fixed_jaw.astype(np.int64),
        embed_tets=etet, embed_weights=ew, volume_jaw_weights=vw, muscles=muscles,
        landmarks=landmarks, curves=curves,
        cranium_mesh=cranium_mesh, jaw_mesh=jaw_mesh, parts=template_parts(mucosa),
        meta={"generator": "invface.template", "generator_version": GENERATOR_VERSION,
              "resolution": float(resolution), "layers": n_layers, "grid": [n_alpha, n_beta],
              "render_subdivision": factor, "build_seconds": round(time.perf_counter() - t0, 2),
              "quality": q},
    )
    if expressions:
        _add_expressions(model, Vf_closed, say)
        model.meta["build_seconds"] = round(time.perf_counter() - t0, 2)
    return model


def _flesh(coarse, n_layers):
    """The flesh's tets: ``n_layers`` layers of prisms under the coarse skin grid down to the
    depth field, the lids opened, split into tets and checked against the quality bounds.
    Returns (rest positions (N, 3) m, tets (T, 4), quality summary, ``_lid_sides(coarse)``)."""
    ni, nj = coarse.shape
    skin_grid_pts = coarse.positions()[: ni * nj].reshape(ni, nj, 3)
    r_inner = lid_inner_radii(coarse.alpha, coarse.beta, coarse.r, coarse.r - depth_of(skin_grid_pts))
    R = layer_radii(coarse.r, r_inner, n_layers)
    X = np.concatenate([coarse.positions(R[k]) for k in range(n_layers + 1)])
    Ns = len(coarse.positions())
    lids = _lid_sides(coarse)
    X = open_lids(X, *lids, column=np.arange(len(X)) % Ns)
    tets = orient(X, prism_tets(coarse.triangles, Ns, n_layers))
    q = quality_summary(X, tets)
    if q["inverted"] or q["min_dihedral_deg"] < MIN_DIHEDRAL_DEG or q["min_radius_ratio"] < MIN_RADIUS_RATIO:
        raise MeshError(f"generated flesh mesh fails the quality bounds: {q}")
    return X, tets, q, lids


def _add_expressions(model, closed_skin, say):
    """The head's controls: the ARKit blendshapes (``arkit_shapes``), the kinematic blinks
    (from the skin with its lids closed, ``closed_skin`` (V, 3)), their muscle-track
    precompute (Eq. 10-11) and the muscles' activation curves."""
    from ..sim.poisson import track_displacements
    from .arkit_shapes import add_arkit_shapes
    from .expressions import add_blinks, calibrate_activation_curves
    say("ARKit blendshapes (sculpted, carried from ICT-FaceKit)")
    add_arkit_shapes(model)
    add_blinks(model, closed_skin)
    say("muscle-track precompute (Poisson solves, Eq. 10-11)")
    model.track_displacements = track_displacements(model)
    calibrate_activation_curves(model)


def cache_dir() -> Path:
    """User cache directory (INVFACE_CACHE, else XDG_CACHE_HOME/invface, else ~/.cache/invface)."""
    if os.environ.get("INVFACE_CACHE"):
        return Path(os.environ["INVFACE_CACHE"])
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "invface"


def cache_path(resolution=1.0, expressions=True) -> Path:
    """Cache file keyed on generator version and options (and this module's source)."""
    pkg = Path(__file__).parent.parent
    files = sorted(Path(__file__).parent.glob("*.py")) + sorted((pkg / "mesh").glob("*.py"))
    if expressions:     # the blendshapes and track data depend on the simulator and the rig too
        files += sorted((pkg / "sim").glob("*.py")) + [pkg / "model" / "rig.py"]
    files += sorted((Path(__file__).parent / "data").glob("*.npz"))
    src = b"".join(p.read_bytes() for p in files)
    key = hashlib.sha1(src + f"{GENERATOR_VERSION}:{float(resolution):.6g}:{expressions}".encode()).hexdigest()[:12]
    kind = "" if expressions else "-noexpr"
    return cache_dir() / f"template-r{float(resolution):g}{kind}-{key}.npz"


def build(resolution=1.0, force=False, cache=True, progress=None, expressions=True) -> FaceModel:
    """The built-in head as a FaceModel (cached). ``force`` regenerates it.

    expressions=False skips the simulated expression blendshapes (anatomy only, fast).
    """
    path = cache_path(resolution, expressions)
    if cache and path.exists() and not force:
        return FaceModel.load(path)
    model = generate(resolution, progress=progress, expressions=expressions)
    if cache:
        try:
            model.save(path)
        except OSError:
            pass   # a read-only cache is not an error: the model is still returned
    return model
