"""The session layer: the workflow as plain functions that take data and return result
objects, each with ``save`` writing what the CLI writes. The CLI parses, prints and sets
exit codes on top of it; benches, tests and scripts call this layer, never ``invface.cli``.

    import invface
    head = invface.build_model().model                          # the built-in template
    calib = invface.calibrate("plates/neutral.png", model=head)  # Eq. 14, pose from curves
    fit = invface.fit_plate("plates/smile_simulation.png", calib, model=head, kinds="both")
    fit.save("out")
    fit["simulation"].weights, fit["simulation"].activations, fit.truth

It sits above ``fit`` and ``report`` (a fit writes results that the report reads; the
session writes both).
"""
from __future__ import annotations

from pathlib import Path

from ..errors import ConfigError
from ..fit.lambdas import EQ14_LAMBDA
from .models import ModelBuild, build_model, load_model
from .plates import (FrameFit, PlateCalibration, PoseEstimate, as_plate, auto_calibrate, calibrate_plate,
                     curve_lambda, find_curves, fit_frame, model_kinds, plate_frames, pose_from_curves,
                     score_against_truth)
from .clips import Clip, open_clip
from .outputs import export
from .sequence import fit_sequence
from .scans import ScanResult, fit_scan
from .simulate import Simulation, simulate


def calibrate(plate, model=None, pose="auto", curves=None, camera=None, lam=None, max_iter=30, progress=None,
              colorspace=None):
    """Lighting and albedo on a plate (Eq. 14). plate: a path or Plate; model: a FaceModel,
    bundle path or None (the template); pose: "auto" (pose and expression from the plate's
    curves, Eq. 15, and lambda scaled with the face's size) or (rotation (3,) rad,
    translation (3,) m) for the neutral; curves: see ``find_curves``; colorspace: the plate
    file's colour space (``io.colorspaces``; None: its format's default). Returns a
    PlateCalibration (``save(path)``: the .npz and PATH_compare.png)."""
    model = load_model(model)
    plate = as_plate(plate, camera, colorspace)
    if isinstance(pose, str):
        if pose != "auto":
            raise ConfigError(f"pose must be 'auto' or (rotation, translation), not {pose!r}")
        found, source = find_curves(model, plate, curves, crop=True)
        return auto_calibrate(model, plate, found, source, lam=lam, max_iter=max_iter, progress=progress)
    rotation, translation = pose
    return calibrate_plate(model, plate, rotation, translation, lam=EQ14_LAMBDA if lam is None else lam,
                           max_iter=max_iter, progress=progress)


def fit_plate(plate, calibration=None, model=None, kinds=("blendshape",), curves=None, camera=None,
              progress=None, colorspace=None, **options):
    """Fit controls and pose to a plate (Eq. 15-16) with one or both model kinds ("both").
    calibration: a PlateCalibration, Calibration or .npz path, or None to calibrate on the
    plate itself (``calibrate(pose="auto")``); colorspace: the plate file's colour space
    (``io.colorspaces``; None: its format's default); other options as ``fit_frame`` (iterations,
    shading, lam_curves, solver, starts). Returns a FrameFit: ``fit[kind]`` is the kind's
    PlateFit (weights, jaw, rotation, translation, activations, curve_rms_px, seconds),
    ``fit.truth`` the errors against a ground truth beside the plate, ``fit.save(dir)``."""
    from ..fit.calibrate import Calibration
    model = load_model(model)
    plate = as_plate(plate, camera, colorspace)
    found, source = find_curves(model, plate, curves, crop=True)
    if calibration is None:
        calibration = auto_calibrate(model, plate, found, source, progress=progress)
    elif isinstance(calibration, (str, Path)):
        calibration = Calibration.load(calibration, vertex_count=len(model.neutral))
    return fit_frame(model, plate, calibration, found, kinds=model_kinds(kinds), progress=progress, source=source,
                     **options)


__all__ = ["Clip", "open_clip", "ModelBuild", "build_model", "load_model", "FrameFit", "PlateCalibration", "PoseEstimate",
           "as_plate", "auto_calibrate", "calibrate", "calibrate_plate", "curve_lambda", "find_curves",
           "fit_frame", "fit_plate", "fit_sequence", "model_kinds", "plate_frames", "pose_from_curves",
           "score_against_truth", "ScanResult", "fit_scan", "Simulation", "simulate", "export"]

from .._lazy import submodules as _submodules  # noqa: E402

__getattr__ = _submodules(__name__, __path__)
