"""Fitting a film plate: curves (Eq. 15), then shape from shading (Eq. 16); one frame or a
sequence of frames, each warm-started from the previous one.

    fit = fit_plate(model, plate, calibration, curves, kind="simulation")
    write_plate_fit(folder, model, fit, plate)         # fit.json + fit.npz, read by the report

Stages (``PlateFit.history`` logs each):

1. curves, Eq. 15, always with the blendshape rig: it is only the start w^ of Eq. 16, and the
   simulation's curve solve costs twenty times the rig's; with the pose
   found first by a tracking pass (``fit_curves``);
2. shading, Eq. 16, by the dogleg (``fit.shading``) with the blendshape rig;
3. for ``kind="simulation"``: shading again with the muscle simulation, from stage 2's
   solution. The two models share their controls, so the cheap one does the long walk
   (stage 2 stops early, at a 2% decrease) and the simulation, whose evaluation costs a
   Newton solve and for accepted steps its tangents (~2 s on the default head, on top of
   the ~1 s render), the last steps. Its stage stops by the rig's final stage's rule (a step
   that lowers the cost by less than 0.5 %): on a real photo the image term keeps a high
   floor (the photo is not a render of the model), so a looser rule stops the simulation
   after one step, still on the rig's curve answer (bench/RESULTS.md).

The calibration (gamma, albedo) comes from Eq. 14 on a neutral plate of the same actor and
camera set-up.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass, field

import numpy as np

from ..errors import ImageError, InvfaceError, SimulationError
from ..model.controls import FitVector
from ..model.gaze import Eyes
from .curves import IRIS_CURVES, CurveObjective, curve_points, fit_curves, projection_jacobian, rms_px
from .lambdas import EQ15_LAMBDA_1, EQ16_TEMPORAL
from ..model.pose import pose_points, posed_parts, posed_surface, unpose_points
from .results import NamedControls, write_fit_files
from .shading import fit_shading


# the first trust radii (``FitVector.scales()`` units) of the coarse blendshape stage and of
# the simulation stage: on real photos their first steps are trusted and reach the trust
# boundary at smaller radii, so a larger first radius saves steps; the last stage of the
# blendshape kind keeps 1 (bench/RESULTS.md)
COARSE_RADIUS = 4.0
SIMULATION_RADIUS = 4.0


@dataclass
class PlateFit(NamedControls):
    """Result of one plate: parameters p (K+6,), pose, posed surface (V, 3) m, the render
    (H, W, 3) linear, per-curve pixel residuals, the image RMS (linear) over the plate and in
    the regions its curves bound (mouth, its opening, the eyes), the log of both stages,
    seconds per stage."""

    kind: str
    vector: FitVector
    p: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    surface: np.ndarray
    render: np.ndarray
    residual_px: dict
    image_rms: float
    history: list = field(default_factory=list)
    seconds: dict = field(default_factory=dict)
    activations: dict = field(default_factory=dict)
    lip_volume_change: float = 0.0
    status: str = ""
    image_rms_by_region: dict = field(default_factory=dict)    # ``fit.regions.region_rms``
    iris_px: dict = field(default_factory=dict)     # {iris curve: (1,) px, model pupil to plate iris}
    curve_p: np.ndarray = None                      # the curve stage's controls (K+6,): Eq. 16's w^
    work: dict = field(default_factory=dict)        # ``_work``: accepted steps by stage, the simulation's solves

    @property
    def curve_rms_px(self):
        return rms_px(self.residual_px)

    @property
    def nonzero_weights(self):
        return int(np.sum(self.p[self.vector.weights] > 1e-2))

    def summary(self):
        """JSON-ready dict of the result (weights by name, jaw, pose, activations, errors)."""
        return {"kind": self.kind, "status": self.status, **self.vector.to_dict(self.z),
                "nonzero_weights": self.nonzero_weights,
                "activations": {k: round(v, 6) for k, v in self.activations.items()},
                "active_muscles": int(sum(v > 1e-2 for v in self.activations.values())),
                "curve_rms_px": self.curve_rms_px,
                "curve_rms_px_by_curve": {k: rms_px({k: v}) for k, v in sorted(self.residual_px.items())},
                "iris_px": {k: float(v[0]) for k, v in sorted(self.iris_px.items())},
                "image_rms": self.image_rms, "image_rms_by_region": self.image_rms_by_region,
                "lip_volume_change": self.lip_volume_change, "seconds": self.seconds, "work": self.work,
                "history": self.history}


def check_plate(plate, path=""):
    """Reject a plate with nothing to fit: non-finite, black or flat (no face)."""
    img = np.asarray(plate, np.float32)
    name = path or "plate"
    if not np.all(np.isfinite(img)):
        raise ImageError(f"{name}: non-finite pixel values")
    if float(img.max()) < 1e-3:
        raise ImageError(f"{name}: the plate is black (max {float(img.max()):.2g}): no face to fit")
    if float(img.std()) < 1e-3:
        raise ImageError(f"{name}: the plate is one flat colour: no face to fit")


def fit_plate(model, plate, calibration, curves, kind="blendshape", start=None, guess=None, shading=True,
              max_iter_curves=200, max_iter_shading=25, spp=8,
              lam_curves=EQ15_LAMBDA_1, solver="dogleg", temporal=0.0, temporal_shading=EQ16_TEMPORAL,
              progress=None):
    """Fit one plate. plate: ``render.plates.Plate`` (linear, undistorted; its mask, if any,
    restricts the shading term); calibration: ``fit.calibrate.Calibration`` (gamma, albedo);
    curves: {name: (n, 2) px} plate curves; kind: "blendshape" or "simulation"; start: the
    previous frame's PlateFit (sequence mode: its controls and pose start this frame; without
    one the calibration's pose starts it, and the curve stage's pose pass holds the head's
    translation near it: ``fit.curves.pose_anchor``; a start that is a PlateFit also carries
    its shading correction over: the shading stages start from this frame's curve answer plus
    the start's move from its own, within the controls' box); guess: the fit vector z (size,)
    the curve stage starts from instead of the start's (a sequence's prediction), the
    temporal term still pulling towards the start;
    lam_curves: lambda_1 of Eq. 15 (px^2 per unit weight^2); solver: "dogleg" or "lbfgs" for
    the shading stages (``fit.shading.fit_shading``); temporal: with a ``start``, the weight of
    the temporal term of the curve stage (``fit_curves``); the shading stages take it times
    temporal_shading (linear light per px^2). Returns a PlateFit."""
    if kind not in ("blendshape", "simulation"):
        raise InvfaceError(f"unknown model kind '{kind}': use 'blendshape' or 'simulation'")
    check_plate(plate.image, plate.path)
    if calibration.albedo.shape != model.neutral.shape:
        raise InvfaceError(f"calibration albedo has {len(calibration.albedo)} vertices, the model "
                           f"{len(model.neutral)}: calibrate with this model")
    cam = plate.camera
    say = progress or (lambda h: None)
    t0 = time.perf_counter()
    counts = _solver_counts(model, kind)
    vec = FitVector.of(model)
    previous = None if start is None else vec.pack(start.p, start.rotation, start.translation)
    if guess is not None:
        p0, rot, tr = vec.unpack(guess)
    elif start is not None:
        p0, rot, tr = start.p, start.rotation, start.translation
    else:
        p0, rot, tr = None, calibration.rotation, calibration.translation
    cf = fit_curves(model, cam, curves, kind="blendshape", lam=lam_curves, p0=p0, rotation=rot,
                    translation=tr, max_iter=max_iter_curves, previous=previous, temporal=temporal,
                    anchored=start is None, progress=lambda h: say(dict(h, stage="curves")))
    history = [dict(h, stage="curves") for h in cf.history]
    seconds = {"curves": time.perf_counter() - t0}
    p, rot, tr, status = cf.p, cf.rotation, cf.translation, f"curves: {cf.status}"
    if getattr(start, "curve_p", None) is not None:
        lo, hi = vec.bounds()
        p = np.clip(cf.p + start.p - start.curve_p, lo[vec.controls], hi[vec.controls])
    for stage, skind, ftol, level, iters, radius in _shading_stages(kind, max_iter_shading) if shading else []:
        t1 = time.perf_counter()
        shade = dict(kind=skind, curves=curves, mask=plate.mask, max_iter=iters, spp=spp,
                     ftol=ftol, solver=solver, previous=previous, temporal=temporal_shading * temporal, level=level,
                     radius=radius, lam_curves=lam_curves,
                     progress=lambda h: say(dict(h, stage=stage)))
        try:
            sf = fit_shading(model, cam, plate.image, calibration.gamma, calibration.albedo, cf.p, rot, tr,
                             p0=p, **shade)
        except SimulationError:
            if p is cf.p:
                raise
            # the simulation cannot reach the blendshape stage's solution: start from the curves'
            status += f"; {stage}: the simulation failed at the blendshape solution, started from the curves'"
            sf = fit_shading(model, cam, plate.image, calibration.gamma, calibration.albedo, cf.p,
                             cf.rotation, cf.translation, p0=cf.p, **shade)
        history += [dict(h, stage=stage) for h in sf.history]
        seconds[stage] = time.perf_counter() - t1
        p, rot, tr = sf.p, sf.rotation, sf.translation
        status += f"; {stage}: {sf.status}"
    return _plate_fit(model, kind, plate, calibration, curves, p, rot, tr, spp,
                      dict(history=history, seconds=seconds, status=status,
                           work=_work(model, kind, history, counts), curve_p=cf.p), t0)


def _solver_counts(model, kind):
    """{"solves", "newton_iterations"} the simulation has done so far ({} for the rig)."""
    counts = getattr(model.surface_model(kind), "counts", None) if kind == "simulation" else None
    return dict(counts or {})


def accepted_steps(history):
    """{stage: accepted steps} of a fit's history (``PlateFit.history`` or fit.json's), in
    stage order."""
    steps = {}
    for h in history:
        steps[h["stage"]] = steps.get(h["stage"], 0) + bool(h.get("accepted"))
    return steps


def _work(model, kind, history, before):
    """What a fit did: {"steps": ``accepted_steps``} and, for the simulation, the quasistatic
    solves and Newton iterations it took (``before``: ``_solver_counts`` at its start)."""
    after = _solver_counts(model, kind)
    return {"steps": accepted_steps(history), **{k: v - before.get(k, 0) for k, v in after.items()}}


def _shading_stages(kind, n):
    """The shading stages of ``kind``'s fit, coarse to fine, with ``n`` iterations at most:
    (name, model kind, ftol, pyramid level, iterations, trust radius). The blendshape model
    first fits the pyramid's lower levels (the render at half resolution, a quarter of the
    pixels to differentiate), then the kind fits the whole pyramid. For the simulation the
    blendshape steps only have to bring the head near: at most 6, as a blendshape optimum is
    a poor start for it (the same weights mean other shapes; from there the open-mouth
    plate's simulation stage stalls at once)."""
    final_ftol = 5e-3           # both kinds' last stage: a fair comparison, see the module doc
    if kind == "blendshape":
        return [("shading-coarse", "blendshape", 2e-2, 1, n, COARSE_RADIUS),
                ("shading", "blendshape", final_ftol, 0, n, 1.0)]
    return [("shading-coarse", "blendshape", 2e-2, 1, min(6, n), COARSE_RADIUS),
            ("shading-simulation", "simulation", final_ftol, 0, n, SIMULATION_RADIUS)]


def _plate_fit(model, kind, plate, calibration, curves, p, rot, tr, spp, record, t0):
    """The PlateFit at the fitted controls ``p`` and pose: the posed surface, its render over
    the plate, the curve residuals (px), the image RMS (over the mask and by region), the
    simulation's activations and the lips' volume change; ``record``: the stages' history,
    seconds and status; t0: the fit's start (``time.perf_counter``)."""
    cam = plate.camera
    sm, vec = model.surface_model(kind), FitVector.of(model)
    _, xr = posed_surface(sm, vec.pack(p, rot, tr), vec)
    from ..measure.volume import lip_volume_change
    from ..render.renderer import FaceRenderer
    render = FaceRenderer(model.triangles, cam, spp=spp, backplate=plate.image, parts=model.parts).image(
        xr, calibration.gamma, calibration.albedo, parts_x=posed_parts(model, vec.pack(p, rot, tr), vec))[..., :3]
    inside = slice(None) if plate.mask is None else np.asarray(plate.mask, bool)
    final = CurveObjective(model, sm, cam, curves, 0.0)
    residual = {k: np.linalg.norm(v, axis=1) for k, v in final.residuals(xr).items()}
    acts, X = {}, None
    if kind == "simulation":
        res = sm.result_at(p)
        acts = {m.name: float(v) for m, v in zip(model.muscles, res.tracks.activations)}
        X = res.X
    seconds = dict(record["seconds"], total=time.perf_counter() - t0)
    from .regions import region_rms
    return PlateFit(kind=kind, vector=vec, p=p, rotation=rot, translation=tr, surface=xr, render=render,
                    residual_px=residual, image_rms=float(np.sqrt(np.mean((render - plate.image)[inside] ** 2))),
                    history=record["history"], seconds=seconds, activations=acts,
                    lip_volume_change=lip_volume_change(model, p, X), status=record["status"],
                    image_rms_by_region=region_rms(render, plate.image, curves),
                    iris_px=final.iris_px(vec.pack(p, rot, tr), xr), work=record.get("work", {}),
                    curve_p=record.get("curve_p"))


def write_plate_fit(folder, model, fit, plate, curves, extra=None, vertex_error=None):
    """Write ``fit.json`` (summary) and ``fit.npz`` (plate, render, posed surface, curves,
    camera, and the per-vertex error (V,) m against a truth when given) into ``folder``
    atomically; the report (``invface.report.fit``) reads them."""
    summary = dict(fit.summary(), plate=str(plate.path), **(extra or {}))
    if getattr(plate, "colorspace", ""):
        summary["plate_colorspace"] = plate.colorspace
    if getattr(plate, "crop", None):
        summary["plate_crop"] = plate.crop
    eyes = Eyes(model)
    names = sorted(n for n in curves if n in model.curves or (len(eyes.sides) == 2 and n in IRIS_CURVES))
    arrays = {"plate": plate.image.astype(np.float32), "render": fit.render.astype(np.float32),
              "surface": fit.surface, "triangles": np.asarray(model.triangles),
              "neutral": model.neutral, "p": fit.p,
              "camera": np.array(json.dumps(plate.camera.to_dict())),
              "curve_names": np.array(names)}
    if vertex_error is not None:
        arrays["vertex_error"] = np.asarray(vertex_error, float)
    if plate.mask is not None:
        arrays["mask"] = np.asarray(plate.mask, bool)
    for i, n in enumerate(names):
        arrays[f"curve_{i}"] = np.asarray(curves[n], float)
        arrays[f"model_curve_{i}"] = projection_jacobian(plate.camera, model_curve(model, eyes, n, fit))[0]
    return write_fit_files(folder, summary, arrays)


def model_curve(model, eyes, name, fit):
    """(n, 3) m posed: the model's curve ``name`` on the fit's surface, or for an iris curve
    (``IRIS_CURVES``) the eye's limbus (``eyes``: the model's ``gaze.Eyes``), closed, at the
    fit's gaze and pose."""
    if name not in IRIS_CURVES:
        return curve_points(model, name, fit.surface)
    ring = eyes.iris_ring(fit.p)[IRIS_CURVES.index(name)]
    return pose_points(np.concatenate([ring, ring[:1]]), fit.rotation, fit.translation)


def read_truth(path, model):
    """Ground truth of a synthetic plate (``<plate>.truth.json``, written by
    ``fit.samples.write_sample_plates``): the posed surface (V, 3) made by the model kind
    it names, and the dict."""
    from ..io.jsonfile import read_object
    from ..io.schema import Fields
    t = read_object(path, what="ground-truth file")
    f = Fields(t, path, listing="fields: kind, weights, jaw, rotation, translation")
    kind = f.text("kind", choices=("blendshape", "simulation"))
    w = f.mapping("weights")
    controls = {"weights": {k: w.number(k) for k in w.data}, "jaw": f.array("jaw", (6,), default=np.zeros(6)),
                "rotation": f.array("rotation", (3,)), "translation": f.array("translation", (3,))}
    vec = FitVector.of(model)
    z = vec.from_dict(controls, what=str(path))
    return posed_surface(model.surface_model(kind), z, vec)[1], t


def vertex_errors(model, fit, truth_surface, truth):
    """Per-vertex distances (V,) m to the truth: posed (what the camera sees, including the
    depth error of the monocular pose) and shape only (both surfaces unposed: the shape the
    controls make)."""
    posed = np.linalg.norm(fit.surface - truth_surface, axis=1)
    shape = np.linalg.norm(unpose_points(fit.surface, fit.rotation, fit.translation)
                           - unpose_points(truth_surface, truth["rotation"], truth["translation"]), axis=1)
    return posed, shape


def depth_errors(surface, truth_surface, camera):
    """The posed error split along the camera rays (V,) m, the depth a single view hardly
    sees, and across them (V,) m, in the image plane: for each vertex the component of
    surface - truth_surface along the ray from the camera centre to the truth vertex."""
    d = np.asarray(surface, float) - truth_surface
    ray = truth_surface - camera.center
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    along = np.einsum("vi,vi->v", d, ray)
    return np.abs(along), np.linalg.norm(d - along[:, None] * ray, axis=1)
