"""A fitted take as USD (Pixar's ``usd-core``), for usdview, Houdini, Maya, Blender, Unreal and
Omniverse: ``write_usd``, the face as an animated mesh (a point cache: exactly the fit, either
kind), and ``write_usd_rig``, the actor's blendshape rig in UsdSkel animated by the fit's
controls (an animator's rig: re-timed, edited, retargeted by the blendshapes' ARKit names).

The point cache's stage (``write_usd``):

    /Capture                  Xform, the default prim; the stage is +Y up in centimetres (USD's
                              fallback unit, metersPerUnit 0.01, so lens values are in mm)
    /Capture/Face             Mesh: the fitted skin, its points sampled per frame in the model's
                              world frame (the head's pose applied); triangles, no subdivision
                              Float attributes arkit:<name> (the 52 ARKit controls, [0, 1]) and
                              invface:headRotation (Euler XYZ rad), invface:headTranslation (m),
                              invface:eyeYawPitch (left yaw, pitch, right yaw, pitch rad), and for
                              the simulation kind invface:muscle:<name> (each muscle's
                              activation, [0, 1]), per frame
    /Capture/Camera           Camera: the plate's solved camera (focal length and apertures in
                              mm, tenths of the stage unit, on a 36 mm film back; the principal
                              point as aperture offsets)
    /Capture/Plate            Mesh: a card behind the face that fills the camera's view, textured
                              with the (undistorted) plate of each frame through a
                              UsdPreviewSurface (its file input sampled per frame), so that
                              looking through the camera shows the face over the plate; the
                              plate files' own paths are in its customData (invface:plates)

Time codes are the take's frame numbers at ``timeCodesPerSecond`` = the clip's rate; a frame
with no sample (a flagged frame) is interpolated by USD from its neighbours. OpenCV's camera
(x right, y down, looking down +z) is USD's (x right, y up, looking down -z) turned half a
turn about x.
"""
from __future__ import annotations

from pathlib import Path

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
    "rotation" (3,) rad, "translation" (3,) m, "eyes" (4,) rad, "activations": {muscle:
    [0, 1]} (the simulation kind)}]} (frames in time order);
    optional "plates": {frame: image path relative to ``path``'s folder} for the card behind
    the face and "plate_sources": [the plate files the fit read]. Returns the Path."""
    Gf, Sdf, Usd, UsdGeom, Vt = _pxr()
    frames = list(data["frames"])
    if not frames:
        raise ConfigError(f"{path}: no frames to write")
    tri = np.asarray(data["triangles"], np.int32)
    with atomic_path(path) as tmp:
        stage = _stage(tmp, frames, data.get("fps"), Usd, UsdGeom)
        _face(stage, frames, tri, Gf, Sdf, UsdGeom, Vt)
        depth = _camera(stage, data["camera"], Gf, UsdGeom, frames[0]["points"])
        if data.get("plates"):
            _plate_card(stage, data["camera"], data["plates"], data.get("plate_sources", []), depth)
        stage.GetRootLayer().Save()
    return Path(path)


def _stage(path, frames, fps, Usd, UsdGeom):
    """A new stage at ``path``: +Y up, in cm, timed by the frames' numbers at ``fps`` (default
    24), with the default prim /Capture."""
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    UsdGeom.SetStageMetersPerUnit(stage, 1.0 / UNITS_PER_M)
    stage.SetTimeCodesPerSecond(float(fps or 24.0))
    stage.SetFramesPerSecond(float(fps or 24.0))
    stage.SetStartTimeCode(float(frames[0]["frame"]))
    stage.SetEndTimeCode(float(frames[-1]["frame"]))
    stage.SetDefaultPrim(UsdGeom.Xform.Define(stage, "/Capture").GetPrim())
    return stage


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
    muscles = sorted({k for f in frames for k in f.get("activations") or {}})
    muscle = {n: prim.CreateAttribute(f"invface:muscle:{n}", Sdf.ValueTypeNames.Float) for n in muscles}
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
        for n, a in muscle.items():
            a.Set(float((f.get("activations") or {}).get(n, 0.0)), t)
        head_r.Set(Gf.Vec3f(*np.asarray(f.get("rotation", np.zeros(3)), float).tolist()), t)
        head_t.Set(Gf.Vec3f(*np.asarray(f.get("translation", np.zeros(3)), float).tolist()), t)    # m
        eyes.Set(Vt.FloatArray(np.asarray(f.get("eyes", np.zeros(4)), float).tolist()), t)


def _camera(stage, camera, Gf, UsdGeom, points=None):
    """The camera prim; its far clipping plane lies beyond the plate card (twice the face's
    farthest depth ``points`` (V, 3) m, when given). Returns that card depth (m)."""
    cam = {k: (np.asarray(v, float) if k in ("K", "R", "t") else v) for k, v in camera.items()}
    usd = UsdGeom.Camera.Define(stage, "/Capture/Camera")
    usd.AddTransformOp().Set(_matrix(Gf, camera_to_world(cam)))
    for k, v in lens(cam).items():
        usd.GetPrim().GetAttribute(k).Set(float(v))
    depth = 1.0
    if points is not None:
        z = (np.asarray(points, float) @ cam["R"].T + cam["t"])[:, 2]
        depth = 2.0 * float(z.max()) if np.all(np.isfinite(z)) and z.max() > 0 else depth
    usd.CreateClippingRangeAttr(Gf.Vec2f(0.01, float(2.0 * depth * UNITS_PER_M)))
    usd.CreateProjectionAttr(UsdGeom.Tokens.perspective)
    return depth


def card_corners(camera, depth):
    """(4, 3) m: the plate's outer pixel corners (top-left, top-right, bottom-right,
    bottom-left) back-projected to ``depth`` in front of the camera, in the world frame."""
    K, w, h = np.asarray(camera["K"], float), camera["width"], camera["height"]
    R, t = np.asarray(camera["R"], float), np.asarray(camera["t"], float)
    uv = np.array([[-0.5, -0.5], [w - 0.5, -0.5], [w - 0.5, h - 0.5], [-0.5, h - 0.5]])
    x = np.c_[(uv[:, 0] - K[0, 2]) / K[0, 0], (uv[:, 1] - K[1, 2]) / K[1, 1], np.ones(4)] * depth
    return (x - t) @ R


def _plate_card(stage, camera, plates, sources, depth):
    """/Capture/Plate: the card at ``depth`` (m) filling the camera's view, textured per frame
    with ``plates`` ({frame: relative image path}) through UsdPreviewSurface (emissive, so that
    no light is needed; its diffuse black)."""
    from pxr import Gf, Sdf, UsdGeom, UsdShade, Vt
    card = UsdGeom.Mesh.Define(stage, "/Capture/Plate")
    x = (card_corners(camera, depth) * UNITS_PER_M).astype(np.float32)
    card.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(x))
    card.CreateFaceVertexCountsAttr(Vt.IntArray([4]))
    card.CreateFaceVertexIndicesAttr(Vt.IntArray([0, 3, 2, 1]))          # facing the camera
    card.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    card.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*x.min(0).tolist()), Gf.Vec3f(*x.max(0).tolist())]))
    st = UsdGeom.PrimvarsAPI(card).CreatePrimvar("st", Sdf.ValueTypeNames.TexCoord2fArray, UsdGeom.Tokens.faceVarying)
    st.Set(Vt.Vec2fArray([Gf.Vec2f(0, 1), Gf.Vec2f(0, 0), Gf.Vec2f(1, 0), Gf.Vec2f(1, 1)]))
    card.GetPrim().SetCustomDataByKey("invface:plates", Vt.StringArray([str(s) for s in sources]))
    material = UsdShade.Material.Define(stage, "/Capture/PlateMaterial")
    surface = UsdShade.Shader.Define(stage, "/Capture/PlateMaterial/Surface")
    surface.CreateIdAttr("UsdPreviewSurface")
    surface.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0, 0, 0))
    reader = UsdShade.Shader.Define(stage, "/Capture/PlateMaterial/UV")
    reader.CreateIdAttr("UsdPrimvarReader_float2")
    reader.CreateInput("varname", Sdf.ValueTypeNames.String).Set("st")
    texture = UsdShade.Shader.Define(stage, "/Capture/PlateMaterial/Texture")
    texture.CreateIdAttr("UsdUVTexture")
    texture.CreateInput("sourceColorSpace", Sdf.ValueTypeNames.Token).Set("sRGB")
    texture.CreateInput("st", Sdf.ValueTypeNames.Float2).ConnectToSource(reader.ConnectableAPI(), "result")
    file = texture.CreateInput("file", Sdf.ValueTypeNames.Asset)
    for i, (frame, image) in enumerate(sorted(plates.items())):
        # "./": anchored to this layer's folder (a bare relative path is a search path in USD)
        asset = Sdf.AssetPath(image if image.startswith(("./", "../", "/")) else "./" + image)
        if i == 0:
            file.Set(asset)              # the default, for readers that take no time samples
        file.Set(asset, float(frame))
    rgb = texture.CreateOutput("rgb", Sdf.ValueTypeNames.Float3)
    surface.CreateInput("emissiveColor", Sdf.ValueTypeNames.Color3f).ConnectToSource(rgb)
    material.CreateSurfaceOutput().ConnectToSource(surface.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(card.GetPrim()).Bind(material)


def write_usd_rig(path, data):
    """Write the take as an animatable USD rig (UsdSkel) to ``path`` atomically: the actor's
    neutral skin bound to a skeleton of two joints, root (the head's pose) and root/jaw (the
    jaw's rigid transform about its pivot), with the model's skinning weights between them, and
    its blendshapes by name (ARKit's, on the built-in head) as UsdSkel BlendShapes; a
    SkelAnimation samples the weights and both joints per frame. USD evaluates it as the
    blendshape rig of paper 000 Eq. 1-2: x = H T(j)(n + B b), linear blend skinning between the
    head and the jaw. data: {"fps", "camera" (as ``write_usd``), "neutral" (V, 3) m, "triangles"
    (F, 3), "names" (K,), "deltas" (K, V, 3) m, "jaw_weights" (V,), "frames": [{"frame",
    "weights" (K,), "jaw_matrix" (4, 4), "head_matrix" (4, 4): the head's pose R(theta) x + t,
    translations in m}]}. Returns the Path."""
    Gf, Sdf, Usd, UsdGeom, Vt = _pxr()
    from pxr import UsdSkel
    frames = list(data["frames"])
    if not frames:
        raise ConfigError(f"{path}: no frames to write")
    with atomic_path(path) as tmp:
        stage = _stage(tmp, frames, data.get("fps"), Usd, UsdGeom)
        UsdSkel.Root.Define(stage, "/Capture/Rig")
        skel = UsdSkel.Skeleton.Define(stage, "/Capture/Rig/Skeleton")
        joints = Vt.TokenArray(["root", "root/jaw"])
        identity = Vt.Matrix4dArray([Gf.Matrix4d(1.0), Gf.Matrix4d(1.0)])
        skel.CreateJointsAttr(joints)
        skel.CreateBindTransformsAttr(identity)
        skel.CreateRestTransformsAttr(identity)
        mesh = _rig_mesh(stage, data, Gf, UsdGeom, Vt, UsdSkel)
        anim = _rig_animation(stage, frames, data["names"], joints, Gf, Vt, UsdSkel)
        UsdSkel.BindingAPI.Apply(skel.GetPrim()).CreateAnimationSourceRel().SetTargets([anim.GetPath()])
        UsdSkel.BindingAPI(mesh.GetPrim()).CreateSkeletonRel().SetTargets([skel.GetPath()])
        _camera(stage, data["camera"], Gf, UsdGeom)
        stage.GetRootLayer().Save()
    return Path(path)


def _rig_mesh(stage, data, Gf, UsdGeom, Vt, UsdSkel):
    """The neutral skin (cm) with its joint weights (root 1 - w, jaw w) and its blendshapes
    (each holding the vertices it moves, offsets in cm)."""
    n = np.asarray(data["neutral"], float) * UNITS_PER_M
    tri = np.asarray(data["triangles"], np.int32)
    mesh = UsdGeom.Mesh.Define(stage, "/Capture/Rig/Face")
    mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(n.astype(np.float32)))
    mesh.CreateFaceVertexCountsAttr(Vt.IntArray([3] * len(tri)))
    mesh.CreateFaceVertexIndicesAttr(Vt.IntArray(tri.ravel().tolist()))
    mesh.CreateSubdivisionSchemeAttr(UsdGeom.Tokens.none)
    mesh.CreateExtentAttr(Vt.Vec3fArray([Gf.Vec3f(*n.min(0).tolist()), Gf.Vec3f(*n.max(0).tolist())]))
    binding = UsdSkel.BindingAPI.Apply(mesh.GetPrim())
    w = np.clip(np.asarray(data["jaw_weights"], float), 0, 1)
    binding.CreateJointIndicesPrimvar(False, 2).Set(Vt.IntArray(np.tile([0, 1], len(w)).tolist()))
    binding.CreateJointWeightsPrimvar(False, 2).Set(Vt.FloatArray(np.stack([1 - w, w], 1).ravel().tolist()))
    binding.CreateGeomBindTransformAttr(Gf.Matrix4d(1.0))
    targets = []
    for name, d in zip(data["names"], np.asarray(data["deltas"], float)):
        moved = np.flatnonzero(np.abs(d).max(1) > 0)
        shape = UsdSkel.BlendShape.Define(stage, mesh.GetPath().AppendChild(name))
        shape.CreateOffsetsAttr(Vt.Vec3fArray.FromNumpy((d[moved] * UNITS_PER_M).astype(np.float32)))
        shape.CreatePointIndicesAttr(Vt.IntArray(moved.tolist()))
        targets.append(shape.GetPath())
    binding.CreateBlendShapesAttr(Vt.TokenArray(list(data["names"])))
    binding.CreateBlendShapeTargetsRel().SetTargets(targets)
    return mesh


def _rig_animation(stage, frames, names, joints, Gf, Vt, UsdSkel):
    """The SkelAnimation: per frame the head's pose (root) and the jaw's transform relative to
    it (translations in cm), and the blendshape weights."""
    anim = UsdSkel.Animation.Define(stage, "/Capture/Rig/Skeleton/Animation")
    anim.CreateJointsAttr(joints)
    anim.CreateBlendShapesAttr(Vt.TokenArray(list(names)))
    weights = anim.CreateBlendShapeWeightsAttr()
    for f in frames:
        t = float(f["frame"])
        H, M = np.array(f["head_matrix"], float), np.array(f["jaw_matrix"], float)
        H[:3, 3] *= UNITS_PER_M
        M[:3, 3] *= UNITS_PER_M
        anim.SetTransforms(Vt.Matrix4dArray([_matrix(Gf, H), _matrix(Gf, M)]), t)
        weights.Set(Vt.FloatArray(np.asarray(f["weights"], float).tolist()), t)
    return anim
