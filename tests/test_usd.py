"""The USD take (io.usd, ``invface export --format usd``): read back with Pixar's own USD library,
its mesh, time samples and attributes, and the solved camera through USD's own camera math
(GfCamera's frustum), against invface's projection."""
import json

import numpy as np
import pytest

pxr = pytest.importorskip("pxr")

import invface  # noqa: E402
from invface.model.arkit import ARKIT_NAMES  # noqa: E402
from invface.render.camera import Camera  # noqa: E402


def _validation_errors(stage):
    """The messages of USD's own validators (UsdValidation: the core, UsdGeom, UsdSkel ... ones
    registered in this build) on a stage."""
    from pxr import UsdValidation
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    return [e.GetMessage() for e in UsdValidation.ValidationContext(validators).Validate(stage)]


def _camera():
    cam = Camera.front_view(640, 480)
    cam.K[0, 2] += 21.0                         # principal point off centre
    cam.K[1, 2] -= 13.0
    cam.K[1, 1] *= 1.02                         # non-square pixels
    return cam


def _controls(model, i):
    return model.parameters({"jawOpen": 0.2 * i, "eyeLookOutLeft": 0.1 * i, "jaw": [0.1 * i, 0, 0, 0, 0, 0]})


def _with_controls(run, model):
    """Each frame's fit.json given the weights and jaw its surface was made with, as a fit writes them."""
    for i in range(3):
        d = run / f"f{i}" / "blendshape"
        rec = json.loads((d / "fit.json").read_text())
        p = _controls(model, i)
        rec.update(weights=dict(zip(model.blendshape_names, p[:-6].tolist())), jaw=p[-6:].tolist())
        (d / "fit.json").write_text(json.dumps(rec))


def _clip(tmp_path, model):
    """A sequence folder of three frames (the middle one flagged) with fit.json and fit.npz."""
    cam, run = _camera(), tmp_path / "clip"
    run.mkdir()
    (run / "run.json").write_text(json.dumps({"frames": ["f0", "f1", "f2"], "fps": 25.0}))
    surfaces = []
    for i in range(3):
        p = _controls(model, i)
        rot, tr = np.array([0.02 * i, -0.1, 0.0]), np.array([0.001 * i, 0.0, 0.0])
        xr = model.surface_model("blendshape").surface(p) @ invface.model.rig.euler_xyz(rot).T + tr
        surfaces.append(xr)
        d = run / f"f{i}" / "blendshape"
        d.mkdir(parents=True)
        arkit = dict.fromkeys(ARKIT_NAMES, 0.0) | {"jawOpen": 0.2 * i}
        d.joinpath("fit.json").write_text(json.dumps({
            "frame": 10 + i, "arkit": arkit, "rotation": rot.tolist(), "translation": tr.tolist(),
            "eyes": {"L": {"yaw": 0.05 * i, "pitch": 0.0}, "R": {"yaw": 0.05 * i, "pitch": 0.01}},
            "activations": {"zygomaticus_major_L": 0.1 * i},
            "flagged": "curves jumped" if i == 1 else ""}))
        plate = np.full((cam.height, cam.width, 3), 0.1 * (i + 1), np.float32)
        np.savez(d / "fit.npz", surface=xr, triangles=model.triangles, camera=np.array(json.dumps(cam.to_dict())),
                 plate=plate)
    return run, cam, surfaces


def test_a_take_reads_back_in_usd_and_its_camera_projects_as_ours(tmp_path, small_expressive_model):
    from pxr import Usd, UsdGeom
    m = small_expressive_model
    run, cam, surfaces = _clip(tmp_path, m)
    paths = invface.export(run, formats="usd")
    assert [p.name for p in paths] == ["face_blendshape.usd"]
    stage = Usd.Stage.Open(str(paths[0]))
    assert UsdGeom.GetStageUpAxis(stage) == "Y" and UsdGeom.GetStageMetersPerUnit(stage) == pytest.approx(0.01)
    assert _validation_errors(stage) == []
    assert stage.GetTimeCodesPerSecond() == 25.0 and (stage.GetStartTimeCode(), stage.GetEndTimeCode()) == (10, 12)
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Capture/Face"))
    pts = mesh.GetPointsAttr()
    assert pts.GetTimeSamples() == [10.0, 12.0]                     # the flagged frame is left to USD
    for t, x in ((10, surfaces[0]), (12, surfaces[2])):
        np.testing.assert_allclose(np.array(pts.Get(t)) / 100.0, x, atol=1e-6)
    halfway = np.array(pts.Get(11)) / 100.0                          # interpolated, not the flagged fit
    np.testing.assert_allclose(halfway, 0.5 * (surfaces[0] + surfaces[2]), atol=1e-6)
    idx = np.array(mesh.GetFaceVertexIndicesAttr().Get()).reshape(-1, 3)
    assert np.array_equal(idx, m.triangles) and set(mesh.GetFaceVertexCountsAttr().Get()) == {3}
    prim = mesh.GetPrim()
    assert prim.GetAttribute("arkit:jawOpen").Get(12) == pytest.approx(0.4)
    assert len([a for a in prim.GetAttributes() if a.GetName().startswith("arkit:")]) == 52
    assert list(prim.GetAttribute("invface:eyeYawPitch").Get(12)) == pytest.approx([0.1, 0.0, 0.1, 0.01])
    assert prim.GetAttribute("invface:muscle:zygomaticus_major_L").Get(12) == pytest.approx(0.2)
    # the camera: USD's own view and projection matrices put the mesh where ours does
    gf = UsdGeom.Camera(stage.GetPrimAtPath("/Capture/Camera")).GetCamera(10)
    V, P = np.array(gf.frustum.ComputeViewMatrix()), np.array(gf.frustum.ComputeProjectionMatrix())
    h = np.c_[np.array(pts.Get(10)), np.ones(len(surfaces[0]))] @ V @ P
    ndc = h[:, :2] / h[:, 3:4]
    uv = np.c_[(ndc[:, 0] + 1) / 2 * cam.width - 0.5, (1 - ndc[:, 1]) / 2 * cam.height - 0.5]
    np.testing.assert_allclose(uv, cam.project(surfaces[0])[0], atol=1e-3)
    # the plate card: behind the face, filling the view, its texture each frame's plate
    card = np.array(UsdGeom.Mesh(stage.GetPrimAtPath("/Capture/Plate")).GetPointsAttr().Get())
    hc = np.c_[card, np.ones(4)] @ V @ P
    corners = np.c_[(hc[:, 0] / hc[:, 3] + 1) / 2 * cam.width - 0.5, (1 - hc[:, 1] / hc[:, 3]) / 2 * cam.height - 0.5]
    np.testing.assert_allclose(corners, [[-0.5, -0.5], [639.5, -0.5], [639.5, 479.5], [-0.5, 479.5]], atol=1e-2)
    view_depth = lambda x: -(np.c_[x, np.ones(len(x))] @ V)[:, 2]
    assert view_depth(card).min() > view_depth(np.array(pts.Get(10))).max()
    assert gf.clippingRange.max > view_depth(card).max()
    texture = stage.GetPrimAtPath("/Capture/PlateMaterial/Texture").GetAttribute("inputs:file")
    assert [texture.Get(t).path for t in (10, 12)] == ["./plates/f0.jpg", "./plates/f2.jpg"]
    assert texture.Get(12).resolvedPath == str(run / "plates" / "f2.jpg")
    from invface.io.images import load_image
    assert load_image(run / "plates" / "f2.jpg").rgb.mean() == pytest.approx(0.3, abs=0.01)


def test_usd_as_text(tmp_path, small_expressive_model):
    """``--usd-ascii``: the take and the rig as .usda, text that USD reads back the same."""
    from pxr import Usd, UsdGeom
    m = small_expressive_model
    run, _, surfaces = _clip(tmp_path, m)
    _with_controls(run, m)
    paths = invface.export(run, formats=("usd", "usdskel"), model=m, usd_ascii=True)
    assert [p.name for p in paths] == ["face_blendshape.usda", "rig_blendshape.usda"]
    assert paths[0].read_text().startswith("#usda 1.0")
    stage = Usd.Stage.Open(str(paths[0]))
    pts = UsdGeom.Mesh(stage.GetPrimAtPath("/Capture/Face")).GetPointsAttr()
    np.testing.assert_allclose(np.array(pts.Get(12)) / 100.0, surfaces[2], atol=1e-6)


def test_export_refuses_an_unknown_format(tmp_path):
    from invface.errors import InvfaceError
    (tmp_path / "blendshape").mkdir()
    (tmp_path / "blendshape" / "fit.json").write_text("{}")
    with pytest.raises(InvfaceError, match="export format 'fbx': use csv, usd"):
        invface.export(tmp_path, formats="fbx")


def test_the_rig_evaluated_by_usdskel_is_the_fitted_surface(tmp_path, small_expressive_model):
    """``--format usdskel``: USD's own skinning (UsdSkel.BakeSkinning: the blendshapes, then the
    head and jaw joints' linear blend skinning) reproduces the blendshape rig's posed surface of
    every exported frame, jaw open, head turned, within 1e-3 mm; the blendshapes carry the
    model's names (ARKit's)."""
    from pxr import Gf, Usd, UsdGeom, UsdSkel
    m = small_expressive_model
    run, _, surfaces = _clip(tmp_path, m)
    _with_controls(run, m)
    path = invface.export(run, formats="usdskel", model=m)[0]
    assert path.name == "rig_blendshape.usd"
    stage = Usd.Stage.Open(str(path))
    assert _validation_errors(stage) == []
    binding = UsdSkel.BindingAPI(stage.GetPrimAtPath("/Capture/Rig/Face"))
    assert list(binding.GetBlendShapesAttr().Get()) == list(m.blendshape_names)
    assert UsdSkel.BakeSkinning(UsdSkel.Root(stage.GetPrimAtPath("/Capture/Rig")), Gf.Interval(10, 12))
    pts = UsdGeom.Mesh(stage.GetPrimAtPath("/Capture/Rig/Face")).GetPointsAttr()
    for t, x in ((10, surfaces[0]), (12, surfaces[2])):
        np.testing.assert_allclose(np.array(pts.Get(t)) / 100.0, x, atol=1e-6)
    with pytest.raises(invface.errors.InvfaceError, match="pass the model the run was fitted with"):
        invface.export(run, formats="usdskel", model=invface.template.build(resolution=0.25, expressions=False))


def test_the_gltf_rig_read_by_pygltflib_and_skinned_by_the_spec_is_the_fitted_surface(tmp_path, small_expressive_model):
    """``--format gltf``: rig_<kind>.glb read back with pygltflib (not the writer's code) and
    evaluated as glTF 2.0 says (morph targets, then joint matrices = global node transform x
    inverse bind matrix, skin weights) at each frame's keyframe gives the blendshape rig's posed
    surface; the targets carry the model's names."""
    pygltflib = pytest.importorskip("pygltflib")
    from scipy.spatial.transform import Rotation
    m = small_expressive_model
    run, _, surfaces = _clip(tmp_path, m)
    _with_controls(run, m)
    path = invface.export(run, formats="gltf", model=m)[0]
    assert path.name == "rig_blendshape.glb"
    g = pygltflib.GLTF2().load(str(path))
    blob = g.binary_blob()

    def read(i):
        acc = g.accessors[i]
        view = g.bufferViews[acc.bufferView]
        dtype = {5126: np.float32, 5123: np.uint16, 5125: np.uint32}[acc.componentType]
        width = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}[acc.type]
        a = np.frombuffer(blob, dtype, acc.count * width, view.byteOffset + (acc.byteOffset or 0))
        return a.reshape(acc.count, width) if width > 1 else a

    prim = g.meshes[0].primitives[0]
    assert g.meshes[0].extras["targetNames"] == list(m.blendshape_names)
    n, joints, weights = read(prim.attributes.POSITION), read(prim.attributes.JOINTS_0), read(prim.attributes.WEIGHTS_0)
    deltas = np.array([read(t["POSITION"]) for t in prim.targets])
    assert np.array_equal(read(prim.indices).reshape(-1, 3), m.triangles)
    anim = g.animations[0]
    times = read(anim.samplers[0].input)
    assert times.tolist() == pytest.approx([10 / 25, 12 / 25])          # the flagged frame is left out
    track = {(c.target.node, c.target.path): read(anim.samplers[c.sampler].output) for c in anim.channels}
    inverse_bind = read(g.skins[0].inverseBindMatrices).reshape(-1, 4, 4).transpose(0, 2, 1)

    def trs(t, q):
        M = np.eye(4)
        M[:3, :3], M[:3, 3] = Rotation.from_quat(q).as_matrix(), t
        return M

    for k, x in ((0, surfaces[0]), (1, surfaces[2])):
        w = track[(2, "weights")].reshape(len(times), -1)[k]
        pre = n + np.tensordot(w, deltas, 1)
        root = trs(track[(0, "translation")][k], track[(0, "rotation")][k])
        jaw = root @ trs(track[(1, "translation")][k], track[(1, "rotation")][k])
        mats = np.array([root, jaw]) @ inverse_bind
        M = np.einsum("vj,vjab->vab", weights, mats[joints])
        skinned = np.einsum("vab,vb->va", M[:, :3, :3], pre) + M[:, :3, 3]
        np.testing.assert_allclose(skinned, x, atol=2e-6)
