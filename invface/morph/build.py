"""Build a simulatable FaceModel for a new actor by morphing the template (paper 001).

Pipeline: clean the scan, spikes and stray pieces removed (target.py) -> orientation,
symmetry and rigid alignment to the template (orient.py), the unit decided from the face
(units.py), what is not head cropped and a scalp hidden by hair or a crown left out (crop.py,
scalp.py); inner lips and lids behind the openings left out (openings.py) ->
fixed-stencil curvature and landmarks (curvature.py, landmarks.py) -> feature curves
(curves.py) -> surface Poisson morph, snapping, inverted-triangle relaxation, completion of
what the scan lacks from the template carried by the face's similarity (surface.py) ->
volumetric morph of flesh, bones, muscles, relaxation of bad tets (volume.py) -> blendshapes
(imported from the actor's files with the jaw's rotation split out of the jaw shapes
(jaw.py), or the template's expressions re-simulated on the new anatomy, or copied) ->
muscle-track precompute (paper 000 Eq. 10-11).

The new model keeps the template's topology (surface, tets, muscles, landmark and curve ids),
so everything built for the template (rig, simulation, fitting, reports) works on it; its
``scan_transform`` maps the input scan's coordinates into the model frame.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from ..errors import ConfigError, MeshError
from ..mesh.closest import barycentric_points, closest_points
from ..mesh.embedding import MLS
from ..io.meshes import read_mesh
from ..mesh.tets import locate_near, quality_summary
from ..model.facemodel import FaceModel
from ..model.arkit import arkit_name
from .blendshapes import read_blendshapes, recognised
from .jaw import split_jaw
from .curves import curve_set
from .crop import crop_to_head
from .landmarks import FALLBACK, ear_boxes, find_landmarks, template_landmarks
from .openings import (ACROSS, MAX_INNER_FRACTION, closed_seams, inner_surfaces, lid_pairs, map_openings,
                       opening_centres)
from .surface import SurfacePoisson, morph_surface
from .target import MIN_TRIANGLES, Target, clean, drop_faces
from .transfer import carry_offsets
from .units import settle_unit
from .volume import carry_bone, carry_fibers, carry_points, carry_similar, inside_fraction, morph_volume

EXPRESSIONS = ("simulate", "copy", "none")


@dataclass
class MorphResult:
    """What the build found and did, for reports and previews (model-frame coordinates)."""
    target: Target
    aligned: np.ndarray                     # (n,3) target vertices in the model frame
    landmarks: dict                         # name -> (3,) on the target
    template_landmarks: dict                # name -> (3,) on the template
    curves: dict                            # (from, to) -> (S,3) on the target
    template_curves: dict
    surface: object                         # SurfaceMorph
    seconds: dict = field(default_factory=dict)
    stats: dict = field(default_factory=dict)


def _transfer(values, surf, Fg, solver):
    """Per-target-vertex values (K,n,3) -> template vertices (K,V,3) through the snap
    correspondence; vertices off the target get the surface Poisson extension."""
    out = np.einsum("vk,Kvkj->Kvj", surf.target_weights, values[:, Fg[surf.target_triangles]])
    if not surf.snapped.all():
        fixed = np.flatnonzero(surf.snapped)
        out = np.array([solver.solve(fixed, d[fixed]) for d in out])
    return out


def carry_anatomy(template, positions, progress=None):
    """The template's flesh, bones, muscles and jaw carried to new skin positions (V,3) m by
    the volume morph (paper 001 sec. 7): (FaceModel without blendshapes, VolumeMorph). The
    skin is embedded by moving least squares. Raises MeshError when the flesh cannot follow."""
    say = progress or (lambda m: None)
    say("volume morph: flesh, bones, muscles")
    q0 = template.meta.get("quality") or quality_summary(template.rest_positions, template.tets)
    vm = morph_volume(template, positions - template.neutral, min_radius_ratio=min(0.005, q0["min_radius_ratio"]),
                      progress=say)
    X0, X1, tets = template.rest_positions, vm.X, template.tets
    muscles = [replace(m, fibers=carry_fibers(X0, X1, tets, m.tets, m.fibers),
                       centerline=carry_points(X0, X1, tets, m.centerline)) for m in template.muscles]
    cranium = (carry_bone(X0, X1, tets, template.cranium_mesh[0]), template.cranium_mesh[1])
    jaw = (carry_bone(X0, X1, tets, template.jaw_mesh[0]), template.jaw_mesh[1])
    pivot = carry_points(X0, X1, tets, template.jaw_pivot)[0]
    parts = template.parts
    if parts is not None:    # each part as one rigid piece, scaled with the flesh around it
        parts = parts.with_vertices(np.concatenate([carry_similar(X0, X1, parts.vertices[parts.part(n)])
                                                    for n in parts.names]))
    et, ew = locate_near(X1, tets, positions, template.embed_tets)   # each skin vertex stays on its side of the lips
    model = FaceModel(
        neutral=positions, triangles=template.triangles, blendshape_names=[],
        blendshapes=np.zeros((0, len(positions), 3)), jaw_pivot=pivot, jaw_frame=template.jaw_frame.copy(),
        jaw_weights=template.jaw_weights.copy(), rest_positions=X1, tets=tets,
        fixed_cranium=template.fixed_cranium, fixed_jaw=template.fixed_jaw,
        embed_tets=et, embed_weights=ew, volume_jaw_weights=template.volume_jaw_weights,
        muscles=muscles, landmarks=dict(template.landmarks), curves=dict(template.curves),
        cranium_mesh=cranium, jaw_mesh=jaw, parts=parts, meta={"skin_embedding": dict(MLS)},   # smooth across the tets' faces
    )
    W = model.embedding_matrix()
    say(f"skin embedded: moving least squares over {W.nnz / W.shape[0]:.1f} tet vertices per skin vertex")
    return model, vm


def adapt_identity(model, displacement, progress=None):
    """``model`` with its neutral moved by ``displacement`` (V,3) m, an identity correction
    (``fit.identity``): the anatomy carried along (``carry_anatomy``); the blendshapes, the
    activations that made them, the muscles' activation curves, the jaw split and the scan
    transform kept; the muscle-track precompute (paper 000 Eq. 10-11) redone on the new rest
    state. Returns the new FaceModel."""
    from ..sim.poisson import track_displacements
    new, _ = carry_anatomy(model, model.neutral + np.asarray(displacement, float), progress)
    new.blendshape_names = list(model.blendshape_names)
    new.blendshapes = np.array(model.blendshapes, copy=True)
    new.blendshape_activations = model.blendshape_activations
    new.scan_transform = model.scan_transform
    new.meta = {**model.meta, "skin_embedding": dict(MLS),
                "quality": quality_summary(new.rest_positions, new.tets),
                "identity": {"max_mm": float(np.linalg.norm(displacement, axis=1).max() * 1e3)}}
    if len(new.blendshape_names):
        (progress or (lambda m: None))("muscle-track precompute (paper 000 Eq. 10-11)")
        new.track_displacements = track_displacements(new)
    return new


def fill_from_template(model, template, names):
    """Append to ``model`` (in place) the template's blendshapes for the ARKit controls that an
    imported folder with ARKit-style names (``names``) lacks, carried onto the actor as
    ``expressions="copy"`` carries them, with their paired jaws. Nothing for a folder with no
    ARKit name (FACS units, a studio's own names). Returns the names filled (sorted)."""
    covered = {arkit_name(n) or n for n in names}
    if not any(arkit_name(n) for n in names):
        return []
    missing = [k for k, n in enumerate(template.blendshape_names) if n not in covered]
    if not missing:
        return []
    add = carry_offsets(template.blendshapes[missing], template.neutral, model.neutral,
                        face_vertices(template))[0]
    filled = [template.blendshape_names[k] for k in missing]
    model.blendshape_names = list(model.blendshape_names) + filled
    model.blendshapes = np.concatenate([model.blendshapes, add])
    tjaw = template.meta.get("blendshape_jaw", {})
    model.meta["blendshape_jaw"] = {**model.meta.get("blendshape_jaw", {}),
                                    **{n: list(tjaw.get(n, [0.0] * 6)) for n in filled}}
    model.meta["filled_from_template"] = sorted(filled)
    return sorted(filled)


def face_vertices(model):
    """Skin vertex ids (k,) of the face: between the chin and 2 cm above the eye corners,
    within 1.5 cm outside the outer eye corners, in front of the ears (6 cm behind the nose
    tip). Where the build is measured against the scan: snapped or filled, every vertex."""
    V = model.neutral
    lm = {k: V[v] for k, v in model.landmarks.items()}
    top = max(lm["eye_outer_L"][1], lm["eye_outer_R"][1]) + 0.02
    side = max(abs(lm["eye_outer_L"][0]), abs(lm["eye_outer_R"][0])) + 0.015
    return np.flatnonzero((V[:, 1] > lm["chin"][1]) & (V[:, 1] < top) & (np.abs(V[:, 0]) < side)
                          & (V[:, 2] > lm["nose_tip"][2] - 0.06))


STAGES = ("clean", "orient", "landmarks", "curves", "surface", "volume", "blendshapes", "tracks")


class BuildFailed(MeshError):
    """The builder could not go on: ``stage`` (one of STAGES) and what it had found by then
    (``found``: 'target' (Target), 'aligned' (n,3) model frame, 'landmarks', 'curves'), for
    a preview of why (report.morph.write_failure_preview)."""

    def __init__(self, message, stage, found):
        super().__init__(message)
        self.stage, self.found = stage, found


def build_model(neutral, blendshapes=None, template=None, unit=None, expressions="copy",
                progress=None):
    """Morph the template onto an actor's neutral scan. Returns (FaceModel, MorphResult).

    neutral: path to an OBJ/PLY, or (vertices (n,3), faces (f,3)) in file units.
    blendshapes: folder of OBJ/PLY files sharing the neutral's topology (optional).
    template: the template FaceModel (default: the built-in one at resolution 1).
    unit: 'm', 'cm' or 'mm' (default: found from the face, units.settle_unit).
    expressions (without blendshapes): 'copy' the template's ARKit shapes onto the actor
    (``transfer.carry_offsets``), 'simulate' the template's FACS-style action units
    (``template.expressions.ACTION_UNITS``) on the new anatomy, or 'none'. With blendshapes
    named in ARKit's style, the ARKit controls they lack are filled from the template.
    Raises BuildFailed (a MeshError naming the stage, with what was found) when a stage cannot
    go on.
    """
    if expressions not in EXPRESSIONS:
        raise ConfigError(f"expressions must be one of {', '.join(EXPRESSIONS)}, got '{expressions}'")
    found = {}
    secs = {}
    try:
        return _build(neutral, blendshapes, template, unit, expressions, progress, secs, found)
    except BuildFailed:
        raise
    except MeshError as e:
        stage = STAGES[min(len(secs), len(STAGES) - 1)]
        raise BuildFailed(f"the build stopped in its {stage} stage: {e}", stage, found) from None


def orient_target(target, template, unit=None, say=None):
    """The orient stage of ``build_model`` on a cleaned Target: orientation, symmetry plane,
    alignment to the template and the unit from the face (``units.settle_unit``), the head
    cropped (``crop.crop_to_head``) and the inner lips and lids behind the openings left out.
    Returns (target, alignment: ``al.apply`` maps it into the model frame, scaling, the hidden
    scalp). Raises MeshError when the scan does not align to the template's face."""
    say = say or (lambda m: None)
    say("orientation, symmetry plane, alignment to the template and the unit (from the face)")
    target, al, scaling = settle_unit(target, template, unit, progress=say)
    if al.residual > 0.01:
        raise MeshError(f"{target.name}: after alignment the scan lies {al.residual * 1000:.1f} mm (median) from "
                        "the template's face; it does not look like a face, or too little of one")
    target = replace(target, unit=scaling.unit)
    cropped, hidden = crop_to_head(target, al.apply(target.vertices), template, *scaling.similarity)
    for note in cropped.notes[len(target.notes):]:
        say(note)
    if len(cropped.faces) < MIN_TRIANGLES:
        raise MeshError(f"{target.name}: cropped to the head the template's face was aligned to, {len(cropped.faces)} "
                        f"triangles are left: the alignment took another part of the scan for the face; crop "
                        "the scan to the head and try again")
    target = cropped
    TL = template_landmarks(template)
    inner = inner_surfaces(al.apply(target.vertices), target.faces, opening_centres(TL))
    if inner.mean() > MAX_INNER_FRACTION:
        say(f"{inner.mean():.0%} of the scan is hidden behind its openings: too much to be inner lips and "
            "lids, all kept")
    elif inner.any():
        target = drop_faces(target, inner, f"left out {int(inner.sum())} triangles of the inner lips and lids, "
                                           "hidden behind the lip and lid lines")
        say(target.notes[-1])
    return target, al, scaling, hidden


def _build(neutral, blendshapes, template, unit, expressions, progress, secs, found):
    """build_model's stages; ``secs`` gets each finished stage's seconds and ``found`` what
    was found so far (for a failure's preview)."""
    say = progress or (lambda m: None)
    t = time.perf_counter()

    def lap(name):
        nonlocal t
        now = time.perf_counter()
        secs[name] = round(now - t, 2)
        t = now

    if template is None:
        from ..template import build as build_template
        template = build_template()
    target, names, D = _read_target(neutral, blendshapes, unit, say)
    lap("clean")
    target, al, scaling, hidden = orient_target(target, template, unit, say)
    TL = template_landmarks(template)
    Va, Fg = al.apply(target.vertices), target.faces
    found.update(target=target, aligned=Va)
    lap("orient")
    L, off_scan, fell = _landmarks(Va, Fg, template, say)
    found["landmarks"] = L
    lap("landmarks")
    say("feature curves")
    Cg = curve_set(Va, Fg, L)
    Ct = curve_set(template.neutral, template.triangles, TL)
    left_out = set(off_scan) | set(fell)
    if left_out:
        Ct, Cg = ({k: c for k, c in C.items() if not set(k) & left_out} for C in (Ct, Cg))
    found["curves"] = Cg
    lap("curves")
    surf, Ct, Cg, opened, ears = _surface(template, TL, Va, Fg, L, Ct, Cg, scaling, say)
    lap("surface")
    model, vm = carry_anatomy(template, surf.positions, progress=say)
    lap("volume")
    S = np.diag([target.scale] * 3 + [1.0])
    A = np.eye(4)
    A[:3, :3], A[:3, 3] = al.R, al.t
    model.scan_transform = A @ S
    shapes = (D[:, target.source_ids] * target.scale) @ al.R.T if D is not None else None   # model frame, metres
    kinds, jaw_split = _blendshapes(model, template, names, shapes, surf, Fg, expressions, say)
    lap("blendshapes")
    if len(model.blendshape_names):
        say("muscle-track precompute (paper 000 Eq. 10-11)")
        from ..sim.poisson import track_displacements
        model.track_displacements = track_displacements(model)
        if expressions == "simulate" and blendshapes is None:
            from ..template.expressions import calibrate_activation_curves
            calibrate_activation_curves(model)
    lap("tracks")
    stats = _stats(model, template, target, al, scaling, hidden, Va, Fg, L, TL, surf, vm, off_scan, fell, opened, ears)
    stats.update(blendshapes={n: kinds.get(n) for n in model.blendshape_names} if blendshapes is not None
                 else expressions, jaw_split=jaw_split, filled_from_template=model.meta.get("filled_from_template", []))
    model.meta = {**model.meta, "generator": "invface.morph", "source": str(target.name),
                  "template": {k: template.meta.get(k) for k in ("generator", "generator_version", "resolution")},
                  "quality": stats["quality"], "morph": {**stats, "seconds": secs}}
    result = MorphResult(target, Va, L, TL, Cg, Ct, surf, secs, stats)
    return model, result


def _read_target(neutral, blendshapes, unit, say):
    """The scan (a path or (V, F)) cleaned (``target.clean``), with the folder's blendshapes
    when given: (Target, blendshape names or None, their offsets (n, V_raw, 3) in the scan's
    units or None)."""
    if isinstance(neutral, (str, Path)):
        say(f"reading {neutral}")
        raw_V, raw_F = read_mesh(neutral)
        name = str(neutral)
    else:
        raw_V, raw_F = (np.asarray(a) for a in neutral)
        name = "target"
    names = D = None
    if blendshapes is not None:
        say(f"reading blendshapes from {blendshapes}")
        names, D = read_blendshapes(blendshapes, len(raw_V), np.asarray(raw_V, float))
    target = clean(raw_V, raw_F, name=name, unit=unit, shapes=D)
    say(f"target: {len(target.vertices)} vertices" + (f" ({'; '.join(target.notes)})" if target.notes else ""))
    return target, names, D


def _landmarks(Va, Fg, template, say):
    """``find_landmarks`` on the aligned scan, saying which landmarks are off the scan and
    which rules fell back: (landmarks, off-scan names, {name: rule that fell back})."""
    say("landmarks (fixed-stencil curvature)")
    L, off_scan, fell = find_landmarks(Va, Fg, template)
    if off_scan:
        say(f"partial scan: {', '.join(off_scan)} off the scan (on its edge); their curves are left out and "
            "the head is completed from the template")
    for name, rule in fell.items():
        say(f"warning: landmark {name}: {rule}; it falls back to {FALLBACK}, and its curves are left out")
    return L, off_scan, fell


def _surface(template, TL, Va, Fg, L, Ct, Cg, scaling, say):
    """The template's skin morphed onto the aligned scan (``morph_surface``), its eye and mouth
    openings mapped onto the scan's rims where it has them (the curves across a mapped opening
    left out): (surface, template curves, scan curves, openings mapped, ear boxes)."""
    rid, rpos, opened = map_openings(template.neutral, template.triangles, TL, Va, Fg, L)
    if opened:
        say(f"openings mapped onto the scan's rims: {', '.join(opened)}")
        across = {k for name in opened for k in ACROSS[name]}
        Ct, Cg = ({k: c for k, c in C.items() if k not in across} for C in (Ct, Cg))
    ears = ear_boxes(Va, Fg, L)
    seams = closed_seams(template.neutral, template.triangles, TL, Va, Fg, L, opened, lids=lid_pairs(template.curves))
    As, ts = scaling.similarity
    surf = morph_surface(template.neutral, template.triangles, Va, Fg, Ct, Cg, rims=(rid, rpos), no_snap=ears,
                         seams=seams, carried=template.neutral @ As.T + ts, progress=say)
    return surf, Ct, Cg, opened, ears


def _blendshapes(model, template, names, shapes, surf, Fg, expressions, say):
    """The actor's blendshapes, set on ``model``: the folder's (``shapes``: (n, V_scan, 3) m in
    the model frame, with ``names``) transferred onto the morphed skin with their jaw rotation
    split out and the missing ARKit controls filled from the template; else the template's
    carried (``expressions`` "copy") or simulated on the new anatomy ("simulate"). Returns
    ({name: recognised control}, {name: jaw split}) for the folder's shapes ({} otherwise)."""
    if shapes is not None:
        say("importing the blendshapes")
        solver = SurfacePoisson(template.neutral, template.triangles)
        model.blendshape_names = names
        model.blendshapes, jaws, jaw_split = split_jaw(model, names, _transfer(shapes, surf, Fg, solver), surf.snapped)
        model.meta["blendshape_jaw"] = jaws
        for n, js in jaw_split.items():
            say(f"{n}: jaw rotation {np.degrees(np.linalg.norm(js['jaw'][:3])):.1f} deg split out "
                f"(mean offset {js['mean_before_mm']:.1f} -> {js['mean_after_mm']:.1f} mm)")
        filled = fill_from_template(model, template, names)
        if filled:
            say(f"{len(filled)} ARKit controls the folder lacks filled from the template: {', '.join(filled)}")
        return {n: recognised(n) for n in names}, jaw_split
    if expressions == "copy" and len(template.blendshape_names):
        say("carrying the template's blendshapes onto the actor")
        model.blendshape_names = list(template.blendshape_names)
        model.blendshapes = carry_offsets(template.blendshapes, template.neutral, model.neutral,
                                          face_vertices(template))[0]
        model.blendshape_activations = template.blendshape_activations
        model.meta["blendshape_jaw"] = dict(template.meta.get("blendshape_jaw", {}))
        model.muscles = [replace(m, activation_curve=t.activation_curve) for m, t in zip(model.muscles, template.muscles)]
    elif expressions == "simulate":
        from ..template.expressions import simulate_blendshapes
        simulate_blendshapes(model, progress=say)
    return {}, {}


def _stats(model, template, target, al, scaling, hidden, Va, Fg, L, TL, surf, vm, off_scan, fell, opened, ears):
    """The build's figures for ``ModelBuild.describe`` and the bundle's meta: unit and scale,
    alignment, landmark and surface distances (mm), fallbacks, the tet quality."""
    tri, bw, _ = closest_points(np.array([TL[k] for k in TL]), template.neutral, template.triangles)
    on_model = dict(zip(TL, barycentric_points(model.neutral, template.triangles, tri, bw)))
    dist = closest_points(model.neutral[surf.snapped], Va, Fg)[2]
    face = closest_points(model.neutral[face_vertices(model)], Va, Fg)[2] * 1000
    return {
        "unit": target.unit, "scale": target.scale, "unit_summary": scaling.summary,
        "face_scale": scaling.face_scale, "cleaning": target.notes, "hidden_scalp": hidden,
        "symmetry_error_mm": al.frame.symmetry_error * 1000,
        "alignment_residual_mm": al.residual * 1000, "flipped_residual_mm": al.flipped_residual * 1000,
        "alignment_uncovered_mm": al.uncovered * 1000,
        "landmark_to_morph_mm": {k: float(np.linalg.norm(on_model[k] - L[k]) * 1000) for k in L},
        "surface_to_target_mm": {"mean": float(dist.mean() * 1000), "max": float(dist.max() * 1000)},
        "face_to_scan_mm": {"median": float(np.median(face)), "p95": float(np.percentile(face, 95)),
                            "max": float(face.max())},
        "off_scan_landmarks": list(off_scan),
        "landmark_fallbacks": [{"landmark": k, "rule": r, "fallback": FALLBACK} for k, r in fell.items()],
        "openings_mapped": opened, "ear_boxes": len(ears), "snapped_fraction": float(surf.snapped.mean()),
        "inverted_triangles": surf.inverted,
        "triangle_relax_rounds": surf.relax_rounds, "tet_relaxed_vertices": vm.relaxed_vertices, "inner_pushed": vm.pushed,
        "tet_relax_rounds": vm.relax_rounds, "quality": quality_summary(model.rest_positions, model.tets),
        "centerlines_inside": inside_fraction(model.rest_positions, model.tets,
                                             np.concatenate([m.centerline for m in model.muscles])),
    }
