"""The plate workflow as functions that take data and return results (paper 000, Eq. 14-16):
find a plate's curves, pose the head from them, calibrate light and albedo, fit one frame
with one or both model kinds, fit a sequence, score against a known truth.

    curves, source = find_curves(model, plate)
    pose = pose_from_curves(model, plate, curves)
    calib = calibrate_plate(model, plate, pose.rotation, pose.translation, shape=pose.shape)
    frame = fit_frame(model, plate, calib.calibration, curves, kinds=("blendshape", "simulation"))
    frame.save("out/")                     # <kind>/fit.json, fit.npz and index.html

Progress goes to a ``progress`` callback as dicts (the CLI turns them into bars): a fit's
iteration log entries with "kind" and "stage" added, or {"message": text} for a step.
Nothing here prints.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InvfaceError, SimulationError
from ..fit.curves import rms_px
from ..fit.lambdas import EQ14_LAMBDA, EQ16_TEMPORAL, curve_lambda, face_scale

KINDS = ("blendshape", "simulation")
DETECTOR = "landmark detector"


def _say(progress, **event):
    if progress is not None:
        progress(event)


def model_kinds(kinds):
    """A tuple of model kinds from "blendshape", "simulation", "both" or a sequence of them."""
    if isinstance(kinds, str):
        kinds = KINDS if kinds == "both" else (kinds,)
    kinds = tuple(kinds)
    bad = [k for k in kinds if k not in KINDS]
    if bad or not kinds:
        raise InvfaceError(f"unknown model kind {bad or kinds}: use 'blendshape', 'simulation' or 'both'")
    return kinds


def as_plate(plate, camera=None, colorspace=None):
    """A ``render.plates.Plate`` from a Plate or an image path (camera, colorspace: see
    ``load_plate``)."""
    from ..render.plates import Plate, load_plate
    return plate if isinstance(plate, Plate) else load_plate(plate, camera=camera, colorspace=colorspace)


def plate_frames(source):
    """Plate paths: [source] for an image file, its images in name order for a folder (a
    video's frames: ``pipeline.clips.open_clip``)."""
    from .clips import Clip
    clip = Clip(source)
    if clip.kind == "video":
        raise InvfaceError(f"{source}: a video has no plate files; open it with pipeline.clips.open_clip")
    return [clip.paths[i] for i in clip.indices]


def peer_comparison(fitted, peer):
    """fit.json's "peer_arkit": the detector's own ARKit scores (MediaPipe's, ``peer``
    {name: [0, 1]}), the fit's values minus them per control (``fitted``: fit.json's "arkit"),
    and their mean absolute difference over the controls both name."""
    both = sorted(set(fitted) & set(peer))
    diff = {k: round(float(fitted[k]) - float(peer[k]), 6) for k in both}
    return {"scores": dict(peer), "fitted_minus_peer": diff,
            "mean_abs_difference": round(float(np.mean(np.abs(list(diff.values())))), 6) if diff else None}


WORKING_SIZE = 1024      # px: the longest side a plate is fitted at (``working_plate``)


def working_plate(plate, curves, crop=False):
    """Bring a plate longer than WORKING_SIZE px to a working size, in place: with ``crop``
    (a single plate), first to the face (a square 1.6 times the curves' extent, inside the
    plate), then, if still larger, down to WORKING_SIZE (``render.plates.crop_plate``: the
    camera follows, so the fit is the same 3D one). Without ``crop`` (a sequence, whose frames
    must share one camera) the whole plate is only reduced. Returns the curves {name: (n, 2)}
    in the working plate's pixels; ``plate.crop`` says how they map back."""
    from ..render.plates import crop_plate, to_crop_pixels
    w, h = plate.camera.size
    if plate.crop is not None or max(w, h) <= WORKING_SIZE:
        return curves
    x0, y0, x1, y1 = 0, 0, w, h
    if crop:
        pts = np.concatenate([np.asarray(v, float) for v in curves.values()])
        centre, half = (pts.min(0) + pts.max(0)) / 2, max(0.8 * float((pts.max(0) - pts.min(0)).max()), 32.0)
        x0, y0 = (max(int(np.floor(c - half)), 0) for c in centre)
        x1, y1 = min(int(np.ceil(centre[0] + half)), w), min(int(np.ceil(centre[1] + half)), h)
    scale = min(1.0, WORKING_SIZE / max(x1 - x0, y1 - y0))
    plate.__dict__.update(vars(crop_plate(plate, (x0, y0, x1, y1), scale)))
    return {k: to_crop_pixels(v, plate.crop) for k, v in curves.items()}


def describe_crop(crop):
    """One line for the report: where a plate's working pixels come from."""
    (x0, y0), (sx, _), (w, h) = crop["origin"], crop["scale"], crop["size"]
    return (f"The plate ({w}x{h} px) is fitted at a working size: from pixel ({x0}, {y0}), scaled by {sx:.3f}; "
            "the camera is moved and scaled with it, and curve errors are in the working pixels "
            f"(x {1 / sx:.2f} for the plate's own)")


def find_curves(model, plate, curves=None, detector=None, face=0, crop=False):
    """The plate's curves and where they came from: ``curves`` ({name: (n, 2) px}, or a curve
    file), else PLATE.curves.json beside the plate, else the landmark detector (whose face
    oval then becomes the plate's mask when it has none; ``detector(image_srgb, name)`` ->
    (478, 2) px replaces the single-image one, e.g. a ``fit.landmarks.LandmarkTracker`` in
    a sequence, and its attribute ``scores``, if any, the peer's ARKit scores that the plate
    keeps as ``peer_arkit``, as the single-image detector's; face: which face the detector
    fits, 0 the first found, the whole frame first, then crops around face proposals, largest
    first: ``fit.landmarks.detect_landmarks``).
    Curves mostly outside the plate are an InvfaceError
    (``fit.curves.check_curves``). A plate longer than WORKING_SIZE is then brought to its
    working size in place (``working_plate``, to the face with ``crop``); curves given as a
    dict are in the pixels of the plate as passed, curves read from a file in the file's. Returns ({name: (n, 2) px in the plate's
    working pixels}, source)."""
    from ..fit.curves import check_curves, read_curves
    from ..fit.landmarks import curves_from_landmarks, detect_face, face_mask
    from ..io.images import linear_to_srgb
    from ..render.plates import to_crop_pixels
    size = tuple(plate.crop["size"]) if plate.crop else plate.camera.size
    if isinstance(curves, dict):
        found, source = {k: np.asarray(v, float) for k, v in curves.items()}, "given"
    else:
        path = Path(plate.path) if plate.path else None
        if curves is None and path is not None:
            side = path.with_name(path.stem + ".curves.json")
            if side.is_file():
                curves = side
        if curves is not None:
            found, source = read_curves(curves, model, image_size=size), str(curves)
        else:
            image, name = linear_to_srgb(plate.image), str(path or "plate")
            if detector:
                points, plate.peer_arkit = detector(image, name=name), dict(getattr(detector, "scores", {}))
            else:
                points, plate.peer_arkit = detect_face(image, name=name, face=face)
            if plate.mask is None:
                plate.mask = face_mask(points, *plate.image.shape[:2])
            found, source = curves_from_landmarks(points), DETECTOR
    if plate.crop and source not in (DETECTOR, "given"):    # a file's curves on a plate already at its working size
        found = {k: to_crop_pixels(v, plate.crop) for k, v in found.items()}
    check_curves(found, plate.camera.size, source)          # curves off the plate: an error
    return working_plate(plate, found, crop), source


@dataclass
class PoseEstimate:
    """Pose and expression from a plate's curves (Eq. 15, blendshape rig): controls p (K+6,),
    rotation (3,) rad, translation (3,) m, the unposed surface (V, 3) m they make, the curve
    RMS in px, the curves' count and source, lambda_1 used, the fit's vector layout."""

    p: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    shape: np.ndarray
    rms_px: float
    curves: int
    source: str
    lam: float
    vector: object

    def describe(self, top=4):
        w = sorted(self.vector.weights_dict(self.p).items(), key=lambda kv: -kv[1])[:top]
        return (f"pose from {self.curves} curves ({self.source}): {self.rms_px:.2f} px RMS, rotation "
                f"{np.round(self.rotation, 3).tolist()} rad, translation {np.round(self.translation, 3).tolist()} m; "
                "expression " + ", ".join(f"{k} {v:.2f}" for k, v in w))


def pose_from_curves(model, plate, curves, lam=None, source="given"):
    """Pose and expression of a plate of unknown pose (a photo) from its curves (Eq. 15 with
    the blendshape rig; lambda_1 from ``curve_lambda``). Returns a PoseEstimate."""
    from ..fit.curves import fit_curves
    from ..model.controls import FitVector
    lam = curve_lambda(curves, lam)
    cf = fit_curves(model, plate.camera, curves, kind="blendshape", lam=lam)
    return PoseEstimate(p=cf.p, rotation=cf.rotation, translation=cf.translation,
                        shape=model.surface_model("blendshape").surface(cf.p), rms_px=cf.rms_px,
                        curves=len(curves), source=source, lam=lam, vector=FitVector.of(model))


@dataclass
class PlateCalibration:
    """Eq. 14 on one plate: the ``Calibration`` (gamma, albedo, pose), the unposed surface it
    was solved on (V, 3) m, the plate, the model's triangles, seconds, and the pose estimate
    when the pose came from the curves. ``save(path)`` writes the .npz and PATH_compare.png."""

    calibration: object
    shape: np.ndarray
    plate: object
    triangles: np.ndarray
    seconds: float
    pose: PoseEstimate | None = None
    parts: object = None            # the model's InnerParts and their unposed positions (P,3)
    parts_x: np.ndarray | None = None

    @property
    def gamma(self):
        return self.calibration.gamma

    @property
    def albedo(self):
        return self.calibration.albedo

    @property
    def rms(self):
        return self.calibration.history[-1]["rms"]

    def save(self, path):
        """Write the calibration (.npz) and PATH_compare.png (plate | render | 4x difference);
        returns both paths."""
        from ..fit.calibrate import comparison_image
        from ..io.images import write_image
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        self.calibration.save(path)
        compare = write_image(path.with_name(path.stem + "_compare.png"),
                              comparison_image(self.triangles, self.shape, self.calibration, self.plate.image,
                                               parts=self.parts, parts_x=self.parts_x))
        return path, compare

    def describe(self):
        c = self.calibration
        return (f"calibrated in {len(c.history)} iterations, {self.seconds:.1f} s: pixel RMS {self.rms:.4f} "
                f"(linear; {self.relative_rms:.2f} of the plate's mean), light DC {c.gamma[0].round(3).tolist()}")

    @property
    def relative_rms(self):
        """The pixel RMS over the plate's mean value (inside its mask)."""
        img = self.plate.image if self.plate.mask is None else self.plate.image[np.asarray(self.plate.mask, bool)]
        return self.rms / max(float(np.mean(img)), 1e-6)

    #: pixel RMS over the mean plate value inside the mask above which a calibration is
    #: flagged (measured: the sample neutral plate 0.025, the five real photos of
    #: ../shared/data/real 0.17-0.22, a uniform-noise image 0.57)
    MAX_RELATIVE_RMS = 0.45

    def warnings(self):
        """Why this calibration may not be a face's: its light is black, or its residual is far
        above a face's (relative pixel RMS above ``MAX_RELATIVE_RMS``). A list of strings."""
        name = Path(self.plate.path).name if self.plate.path else "plate"
        out = []
        if float(np.max(self.gamma[0])) <= 1e-3:
            out.append(f"{name}: the calibrated light is black (DC {self.gamma[0].round(4).tolist()}): "
                       "no lit face was found at the given pose")
        rel = self.relative_rms
        if rel > self.MAX_RELATIVE_RMS:
            out.append(f"{name}: the calibration's pixel RMS is {rel:.2f} of the plate's mean value (a face's is "
                       f"below {self.MAX_RELATIVE_RMS}): the head is probably not where the pose puts it, or "
                       "the plate shows no face")
        return out


def calibrate_plate(model, plate, rotation=None, translation=None, shape=None, lam=EQ14_LAMBDA, max_iter=30,
                    pose=None, progress=None, robust=0):
    """Eq. 14 on a loaded plate: SH light and per-vertex albedo with the head at the given
    pose (rotation (3,) rad, translation (3,) m; default identity) and the unposed surface
    ``shape`` (V, 3) m (default the neutral). progress: each iteration's log entry; robust:
    reweighted solves for a plate with something over the face (``fit.calibrate.calibrate``).
    Returns a PlateCalibration."""
    from ..fit.calibrate import calibrate
    from ..fit.plate import check_plate
    check_plate(plate.image, plate.path)
    t0 = time.perf_counter()
    shape = model.neutral if shape is None else np.asarray(shape, float)
    parts_x = model.parts_positions(None if pose is None else pose.p)
    cal = calibrate(model.triangles, shape, plate.image, plate.camera, rotation, translation, lam=lam,
                    mask=plate.mask, max_iter=max_iter, progress=progress, parts=model.parts, parts_x=parts_x,
                    robust=robust)
    cal.plate = plate.path
    return PlateCalibration(cal, shape, plate, np.asarray(model.triangles), time.perf_counter() - t0, pose,
                            model.parts, parts_x)


def auto_calibrate(model, plate, curves, source="given", lam_curves=None, lam=None, max_iter=30, progress=None,
                   robust=0):
    """Calibrate a plate of unknown pose on itself: pose and expression from its curves
    (Eq. 15), then Eq. 14 on that shape, lambda scaled with the face's size (``face_scale``)
    unless given. Returns a PlateCalibration (its ``pose`` set)."""
    pose = pose_from_curves(model, plate, curves, lam_curves, source=source)
    _say(progress, message=pose.describe())
    lam = EQ14_LAMBDA * face_scale(curves)[0] if lam is None else lam
    return calibrate_plate(model, plate, pose.rotation, pose.translation, pose.shape, lam, max_iter, pose=pose,
                           progress=progress, robust=robust)


def score_against_truth(model, fit, truth_path, camera=None):
    """A fit's error against a synthetic plate's ground truth (``PLATE.truth.json``):
    ({file, made_by, median_mm, max_mm, shape_median_mm, shape_max_mm, and with the plate's
    camera depth_median_mm, in_plane_median_mm}, posed per-vertex error (V,) m). Posed: what
    the camera sees, including the monocular depth error; depth and in-plane: the posed
    error along and across the camera rays; shape: both surfaces unposed."""
    from ..fit.plate import depth_errors, read_truth, vertex_errors
    truth_surface, truth = read_truth(truth_path, model)
    posed, shape = vertex_errors(model, fit, truth_surface, truth)
    score = {"file": str(truth_path), "made_by": truth["kind"], "median_mm": float(np.median(posed) * 1000),
             "max_mm": float(posed.max() * 1000), "shape_median_mm": float(np.median(shape) * 1000),
             "shape_max_mm": float(shape.max() * 1000)}
    if camera is not None:
        depth, across = depth_errors(fit.surface, truth_surface, camera)
        score.update(depth_median_mm=float(np.median(depth) * 1000),
                     in_plane_median_mm=float(np.median(across) * 1000))
    return score, posed


def truth_beside(plate):
    """PLATE.truth.json beside the plate, or None."""
    if not plate.path:
        return None
    path = Path(plate.path)
    side = path.with_name(path.stem + ".truth.json")
    return side if side.is_file() else None


@dataclass
class FrameFit:
    """One plate fitted with one or more model kinds: ``fits`` {kind: fit.plate.PlateFit},
    ``truth`` {kind: score} where the plate has a ground truth, ``failed`` {kind: reason}
    for kinds that could not finish (the simulation did not reach an equilibrium), the
    model, the plate, its curves and their source, and the options used. ``save(folder)`` writes what ``invface
    fit-plate`` writes: <kind>/fit.json, <kind>/fit.npz and the report index.html."""

    model: object
    plate: object
    curves: dict
    source: str
    fits: dict = field(default_factory=dict)
    failed: dict = field(default_factory=dict)
    truth: dict = field(default_factory=dict)
    vertex_error: dict = field(default_factory=dict)
    options: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    warnings: list = field(default_factory=list)
    record: dict = field(default_factory=dict)     # {kind: extra fit.json keys} (a sequence's)
    title: str | None = None
    written: dict = field(default_factory=dict, repr=False)    # (folder, kind) -> failures then

    def __getitem__(self, kind):
        return self.fits[kind]

    @property
    def name(self):
        return Path(self.plate.path).name if self.plate.path else "plate"

    def extra(self, kind):
        """What fit.json records beside the fit's own summary."""
        extra = {"curves_from": self.source, **self.options, "notes": list(self.notes)}
        if self.source == DETECTOR:
            extra["notes"].insert(0, "Curves from the automatic landmark detector (MediaPipe Face Landmarker); "
                                     "its face oval masks the shading term.")
        extra["notes"] += [f"The {k} model's fit did not finish: {why}" for k, why in self.failed.items()]
        extra["notes"] += [f"Warning: {w}" for w in self.warnings]
        extra["warnings"] = list(self.warnings)
        if self.plate.peer_arkit:
            extra["peer_arkit"] = peer_comparison(self.fits[kind].summary()["arkit"], self.plate.peer_arkit) \
                if kind in self.fits else {"scores": self.plate.peer_arkit}
        if kind in self.truth:
            extra["truth"] = self.truth[kind]
        extra.update(self.record.get(kind, {}))
        return extra

    def failure(self):
        """One line: the plate and why each kind that failed did not finish."""
        return f"{self.name}: no model kind finished: " + "; ".join(f"{k}: {why}" for k, why in self.failed.items())

    def describe(self, kind):
        """One line on the kind's fit."""
        fit = self.fits[kind]
        worst = max(fit.residual_px, key=lambda k: rms_px({k: fit.residual_px[k]}), default=None)
        line = (f"{self.name} {kind}: {fit.seconds['total']:.1f} s, curves {fit.curve_rms_px:.2f} px RMS"
                + (f" (worst {worst} {rms_px({worst: fit.residual_px[worst]}):.2f})" if worst else "") + ", "
                f"image RMS {fit.image_rms:.4f}"
                + (f" (mouth {fit.image_rms_by_region['mouth']:.4f})" if "mouth" in fit.image_rms_by_region else "")
                + f", {fit.nonzero_weights} non-zero weights, "
                f"lip volume {100 * fit.lip_volume_change:+.2f} %")
        if kind in self.truth:
            t = self.truth[kind]
            line += (f"; vertex error vs truth: median {t['median_mm']:.3f} mm posed"
                     + (f" ({t['depth_median_mm']:.3f} depth, {t['in_plane_median_mm']:.3f} in plane)"
                        if "depth_median_mm" in t else "") + f", {t['shape_median_mm']:.3f} mm shape")
        return line

    def save_kind(self, folder, kind):
        """Write <folder>/<kind>/fit.json and fit.npz (each atomically)."""
        from ..fit.plate import write_plate_fit
        path = write_plate_fit(Path(folder) / kind, self.model, self.fits[kind], self.plate, self.curves,
                               extra=self.extra(kind), vertex_error=self.vertex_error.get(kind))
        self.written[str(Path(folder)), kind] = len(self.failed)
        return path

    def save(self, folder, quick=False):
        """Write every kind's files (those not written there yet, or written before another
        kind failed: their notes name it) and the report (``quick``: a sequence frame's page,
        ``report.fit.write_report``); returns the report page's path. An InvfaceError naming
        the reasons when no kind finished."""
        from ..report.fit import write_report
        if not self.fits:
            raise InvfaceError(self.failure())
        for kind in self.fits:
            if self.written.get((str(Path(folder)), kind)) != len(self.failed):
                self.save_kind(folder, kind)
        return write_report(folder, title=self.title or f"invface plate fit: {self.name}", quick=quick)


def fit_frame(model, plate, calibration, curves=None, kinds=("blendshape",), starts=None, guesses=None,
              iterations=25, shading=True, lam_curves=None, solver="dogleg", notes=(), title=None, progress=None,
              on_kind=None, source=None, camera=None, detector=None, temporal=0.0, temporal_shading=EQ16_TEMPORAL,
              face=0, crop=False):
    """Fit one plate with each model kind (paper 000, Eq. 15 then 16). plate: a Plate or a path;
    calibration: a Calibration or PlateCalibration of this model and camera set-up; curves:
    see ``find_curves`` (source: where given curves came from, for the report); starts:
    {kind: PlateFit} of the previous frame (warm start); guesses: {kind: z (size,)} where a
    kind's fit starts instead (``frames.predict``);
    lam_curves: lambda_1 of Eq. 15 (default: scaled with the face, ``curve_lambda``);
    on_kind(frame, kind): called as each kind finishes (to write it at once); camera: for a
    plate path (see ``render.plates.load_plate``); detector, face, crop: see ``find_curves``; temporal: the
    weight of the temporal term to the ``starts`` (``fit.curves.fit_curves``; px^2 per
    scale unit^2, scaled here with the face like lambda_1); temporal_shading: the shading
    stages' share of it (``fit.plate.fit_plate``). A kind whose simulation cannot reach an
    equilibrium is recorded in ``FrameFit.failed`` and the other kinds go on. Returns a
    FrameFit."""
    from ..fit.curves import check_curves
    from ..fit.plate import fit_plate
    plate = as_plate(plate, camera)
    checked, calibration = calibration, getattr(calibration, "calibration", calibration)
    curves, found = find_curves(model, plate, curves, detector, face, crop)
    source = source or found
    if plate.crop:
        notes = [*notes, describe_crop(plate.crop)]
    lam = curve_lambda(curves, lam_curves)
    frame = FrameFit(model=model, plate=plate, curves=curves, source=source, notes=list(notes), title=title,
                     options={"curve_lambda": lam, "solver": solver, "temporal": temporal,
                              "temporal_shading": temporal_shading, "face": face if found == DETECTOR else None},
                     warnings=check_curves(curves, plate.camera.size, source)
                     + (checked.warnings() if isinstance(checked, PlateCalibration) else []))
    truth = truth_beside(plate)
    for kind in model_kinds(kinds):
        def log(h, kind=kind):
            _say(progress, **dict(h, kind=kind, frame=frame.name))
        try:
            fit = fit_plate(model, plate, calibration, curves, kind=kind, start=(starts or {}).get(kind),
                            guess=(guesses or {}).get(kind),
                            shading=shading, max_iter_shading=iterations, lam_curves=lam, solver=solver,
                            temporal=temporal * face_scale(curves)[0], temporal_shading=temporal_shading,
                            progress=log)
        except SimulationError as e:
            # the other kinds still finish and are written; the report says why this one is missing
            frame.failed[kind] = str(e)
            continue
        frame.fits[kind] = fit
        if truth is not None:
            frame.truth[kind], frame.vertex_error[kind] = score_against_truth(model, fit, truth, plate.camera)
        if on_kind is not None:
            on_kind(frame, kind)
    return frame
