"""A fitted take as a USD stage (Pixar's ``usd-core``): the face as an animated mesh, the solved
camera, and the ARKit controls as animated attributes, for usdview, Houdini, Maya, Blender,
Unreal and Omniverse.

The stage (``write_usd``):

    /Capture                  Xform, the default prim; the stage is +Y up in centimetres (USD's
                              fallback unit, metersPerUnit 0.01, so lens values are in mm)
    /Capture/Face             Mesh: the fitted skin, its points sampled per frame in the model's
                              world frame (the head's pose applied); triangles, no subdivision
                              Float attributes arkit:<name> (the 52 ARKit controls, [0, 1]) and
                              invface:headRotation (Euler XYZ rad), invface:headTranslation (m),
                              invface:eyeYawPitch (left yaw, pitch, right yaw, pitch rad), per frame
    /Capture/Camera           Camera: the plate's solved camera (focal length and apertures in
                              mm, tenths of the stage unit, on a 36 mm film back; the principal
                              point as aperture offsets)

Time codes are the take's frame numbers at ``timeCodesPerSecond`` = the clip's rate; a frame
with no sample (a flagged frame) is interpolated by USD from its neighbours. OpenCV's camera
(x right, y down, looking down +z) is USD's (x right, y up, looking down -z) turned half a
turn about x.
"""
from __future__ import annotations

import numpy as np

from ..errors import ConfigError
from .atomic import atomic_path

FILM_BACK_MM = 36.0
UNITS_PER_M = 100.0            # the stage in centimetres
INSTALL = "pip install usd-core"


def _pxr():
    try:
        from pxr import Gf, Sdf, Usd, UsdGeom, Vt
    except ImportError:
        raise ConfigError(f"USD export needs Pixar's USD Python bindings: {INSTALL}") from None
    return Gf, Sdf, Usd, UsdGeom, Vt


def camera_to_world(camera):
    """(4, 4) column-vector matrix: USD's camera frame to the stage (the model's world frame in
    cm) for an OpenCV camera x_cam = R x + t (x in m)."""
    M = np.eye(4)
    M[:3, :3] = camera["R"].T @ np.diag([1.0, -1.0, -1.0])
    M[:3, 3] = -camera["R"].T @ camera["t"] * UNITS_PER_M
    return M


def lens(camera):
    """{focalLength, horizontalAperture, verticalAperture, horizontalApertureOffset,
    verticalApertureOffset} mm of a pinhole K (3,3) on a width x height px image, the film
    back FILM_BACK_MM wide (pixel centres in OpenCV's convention: (0, 0) is the first pixel's).
    The offsets move the film window: a principal point right of the image centre is a window
    moved left, one below the centre a window moved up (v grows down, USD's y up)."""
    K, w, h = camera["K"], camera["width"], camera["height"]
    mm = FILM_BACK_MM / w                                      # mm per pixel across
    focal = K[0, 0] * mm
    v_mm = focal / K[1, 1]                                     # mm per pixel down (non-square pixels)
    return {"focalLength": focal, "horizontalAperture": FILM_BACK_MM, "verticalAperture": h * v_mm,
            "horizontalApertureOffset": -(K[0, 2] - (w - 1) / 2) * mm,
            "verticalApertureOffset": (K[1, 2] - (h - 1) / 2) * v_mm}


def _matrix(Gf, M):
    return Gf.Matrix4d(*np.asarray(M, float).T.ravel().tolist())   # USD's matrices act on row vectors


def write_usd(path, data):
    """Write the take's stage to ``path`` (.usd, .usda or .usdc) atomically. data: {"fps": float,
    "triangles": (F, 3) int, "camera": {"K" (3,3), "R" (3,3), "t" (3,), "width", "height"},
    "frames": [{"frame": int, "points": (V, 3) m posed, "arkit": {name: value},
    "rotation" (3,) rad, "translation" (3,) m, "eyes" (4,) rad}]} (frames in time order).
    Returns the Path."""
    Gf, Sdf, Usd, UsdGeom, Vt = _pxr()
    frames = list(data["frames"])
    if not frames:
        raise ConfigError(f"{path}: no frames to write")
    tri = np.asarray(data["triangles"], np.int32)
    with atomic_path(path) as tmp:
        stage = Usd.Stage.CreateNew(str(tmp))
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
        UsdGeom.SetStageMetersPerUnit(stage, 1.0 / UNITS_PER_M)
        stage.SetTimeCodesPerSecond(float(data.get("fps") or 24.0))
        stage.SetFramesPerSecond(float(data.get("fps") or 24.0))
        stage.SetStartTimeCode(float(frames[0]["frame"]))
        stage.SetEndTimeCode(float(frames[-1]["frame"]))
        root = UsdGeom.Xform.Define(stage, "/Capture")
        stage.SetDefaultPrim(root.GetPrim())
        _face(stage, frames, tri, Gf, Sdf, UsdGeom, Vt)
        _camera(stage, data["camera"], Gf, UsdGeom)
        stage.GetRootLayer().Save()
    from pathlib import Path
    return Path(path)


def _face(stage, frames, tri, Gf, Sdf, UsdGeom, Vt):
    mesh = UsdGeom.Mesh.Define(stage, "/Capture/Face")
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(tri)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray(tri.ravel().tolist()))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateOrientationAttr(UsdGeom.Tokens.rightHanded)
    points, extent = mesh.CreatePointsAttr(), mesh.CreateExtentAttr()
    prim = mesh.GetPrim()
    names = sorted({k for f in frames for k in f.get("arkit", {})})
    arkit = {n: prim.CreateAttribute(f"arkit:{n}", Sdf.ValueTypeNames.Float) for n in names}
    head_r = prim.CreateAttribute("invface:headRotation", Sdf.ValueTypeNames.Float3)
    head_t = prim.CreateAttribute("invface:headTranslation", Sdf.ValueTypeNames.Float3)
    eyes = prim.CreateAttribute("invface:eyeYawPitch", Sdf.ValueTypeNames.FloatArray)
    for f in frames:
        t = float(f["frame"])
        x = (np.asarray(f["points"], float) * UNITS_PER_M).astype(np.float32)
        points.Set(Vt.Vec3fArray.FromNumpy(x), t)
        extent.Set(Vt.Vec3fArray([Gf.Vec3f(*x.min(0).tolist()), Gf.Vec3f(*x.max(0).tolist())]), t)
        for n, a in arkit.items():
            a.Set(float(f.get("arkit", {}).get(n, 0.0)), t)
        head_r.Set(Gf.Vec3f(*np.asarray(f.get("rotation", np.zeros(3)), float).tolist()), t)
        head_t.Set(Gf.Vec3f(*np.asarray(f.get("translation", np.zeros(3)), float).tolist()), t)    # m
        eyes.Set(Vt.FloatArray(np.asarray(f.get("eyes", np.zeros(4)), float).tolist()), t)


def _camera(stage, camera, Gf, UsdGeom):
    cam = {k: (np.asarray(v, float) if k in ("K", "R", "t") else v) for k, v in camera.items()}
    usd = UsdGeom.Camera.Define(stage, "/Capture/Camera")
    usd.AddTransformOp().Set(_matrix(Gf, camera_to_world(cam)))
    for k, v in lens(cam).items():
        usd.GetPrim().GetAttribute(k).Set(float(v))
    usd.CreateClippingRangeAttr(Gf.Vec2f(0.01, 100.0))
    usd.CreateProjectionAttr(UsdGeom.Tokens.perspective)
