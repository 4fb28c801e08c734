"""The analytic image Jacobian (render.jacobian): visibility held fixed, one ray cast whatever
the number of controls. Checked against Dr.Jit's forward-mode columns and finite differences of
the render off the silhouettes and occlusion edges, its shading derivative against finite
differences of the vertex radiance, and its cost: no render pass per control."""
import drjit as dr
import numpy as np
import pytest

from invface.fit.samples import skin_albedo, studio_light
from invface.fit.shading import _forward_mode
from invface.model.controls import FitVector
from invface.model.pose import posed_jacobian, posed_parts
from invface.render.camera import Camera
from invface.render.jacobian import RasterJacobian
from invface.render.renderer import FaceRenderer
from invface.render.shading import vertex_radiance

COLUMNS = ("mouthSmileLeft", "browInnerUp", "jawOpen", "jaw_rx", "rotation_y", "translation_x")


@pytest.fixture(scope="module")
def scene(small_expressive_model):
    m = small_expressive_model
    cam = Camera.front_view(240, 180, eye=(0.0, 0.0, 0.62), target=(0.0, 0.0, 0.0))
    vec = FitVector.of(m)
    p = m.parameters({"weights": {"mouthSmileLeft": 0.5, "browInnerUp": 0.4}, "jaw": [0.08, 0, 0, 0, 0, 0]})
    z = vec.pack(p, np.array([0.05, -0.15, 0.02]), np.array([0.002, -0.001, 0.01]))
    xr, J = posed_jacobian(m.surface_model("blendshape"), z, vec)
    cols = [vec.names.index(n) for n in COLUMNS]
    return m, cam, xr, J[cols], posed_parts(m, z, vec), studio_light(), skin_albedo(m)


def _forward(m, cam, xr, J, parts, gamma, albedo, spp):
    """Dr.Jit's forward-mode derivative images (n, h, w, 3) of the render along J (n, V, 3)."""
    r = FaceRenderer(m.triangles, cam, spp=spp, silhouette_spp=0.5, parts=m.parts)
    mi = r.mi
    out = np.zeros((len(J), cam.height, cam.width, 3), np.float32)
    with _forward_mode(dr):
        x = mi.Float(xr.astype(np.float32).ravel())
        dr.enable_grad(x)
        img = r.render(x, gamma, albedo, parts_x=parts)
        for k in range(len(J)):
            dr.set_grad(x, mi.Float(J[k].astype(np.float32).ravel()))
            dr.enqueue(dr.ADMode.Forward, x)
            dr.traverse(dr.ADMode.Forward, flags=dr.ADFlag.ClearInterior)
            out[k] = np.array(dr.grad(img), np.float32)[..., :3]
            dr.clear_grad(img)
    return out, r


def test_analytic_columns_match_forward_mode_off_the_edges(scene):
    """Per column, the relative L2 difference from Dr.Jit's forward mode (512 spp, converged to
    about 0.4 %) over the face pixels outside the 2-px band is within 2 % (measured 0.6-1.5 %
    on the 35 columns at 360x270, the lids' 7-8 % aside: their derivative lies at the lid
    margins, in the band); the band is under a third of the face here (a small face)."""
    m, cam, xr, J, parts, gamma, albedo = scene
    ref, r = _forward(m, cam, xr, J, parts, gamma, albedo, spp=512)
    lin = RasterJacobian(r, samples=8).linearise(xr, gamma, albedo, parts_x=parts)
    out = lin.apply(np.moveaxis(J, 0, 2)).reshape(cam.height, cam.width, 3, -1)
    keep = lin.face & ~lin.band
    assert keep.sum() > 0.6 * lin.face.sum() and lin.face.sum() > 5000
    for k, name in enumerate(COLUMNS):
        a, b = out[..., k][keep], ref[k][keep]
        err = np.linalg.norm(a - b) / np.linalg.norm(b)
        print(name, round(float(err), 4))
        assert err < 0.02, (name, err)


def test_analytic_columns_match_finite_differences_of_the_render(scene):
    """Central differences of the fixed-seed render (64 spp, 0.2 mm of motion at most) along each
    column, outside the band, against the analytic column: relative L2 within 4 % over all but
    the 0.5 % of pixels that differ most (where one of the render's jittered samples crosses an
    edge between the two renders, a single pixel can hold half of the squared difference)."""
    m, cam, xr, J, parts, gamma, albedo = scene
    r = FaceRenderer(m.triangles, cam, spp=64, silhouette_spp=0.5, parts=m.parts)
    lin = RasterJacobian(r, samples=8).linearise(xr, gamma, albedo, parts_x=parts)
    out = lin.apply(np.moveaxis(J, 0, 2)).reshape(cam.height, cam.width, 3, -1)
    keep = lin.face & ~lin.band
    for k, name in enumerate(COLUMNS):
        h = 2e-4 / max(np.abs(J[k]).max(), 1e-12)
        fd = (r.image(xr + h * J[k], gamma, albedo, parts_x=parts)[..., :3]
              - r.image(xr - h * J[k], gamma, albedo, parts_x=parts)[..., :3]) / (2 * h)
        diff = np.linalg.norm(out[..., k][keep] - fd[keep], axis=1)
        trim = diff <= np.quantile(diff, 0.995)
        err = np.linalg.norm(diff[trim]) / np.linalg.norm(fd[keep][trim])
        print(name, round(float(err), 4))
        assert err < 0.04, (name, err)


def test_vertex_radiance_derivative_matches_finite_differences(scene):
    m, cam, xr, J, parts, gamma, albedo = scene
    r = FaceRenderer(m.triangles, cam, spp=4, parts=m.parts)
    lin = RasterJacobian(r, samples=1).linearise(xr, gamma, albedo, parts_x=parts)
    dC = lin.vertex_radiance_derivative(np.moveaxis(J, 0, 2))
    for k in range(len(J)):
        h = 1e-6 / max(np.abs(J[k]).max(), 1e-12)
        fd = (vertex_radiance(xr + h * J[k], m.triangles, gamma, albedo)
              - vertex_radiance(xr - h * J[k], m.triangles, gamma, albedo)) / (2 * h)
        assert np.abs(dC[:, :, k] - fd).max() <= 1e-5 * np.abs(fd).max() + 1e-9, COLUMNS[k]


def test_the_analytic_jacobian_makes_no_render_per_column(scene, monkeypatch):
    """Its cost does not grow with the controls in render passes: linearising and applying to
    any number of columns never calls the renderer's render, and one ray cast serves all."""
    m, cam, xr, J, parts, gamma, albedo = scene
    r = FaceRenderer(m.triangles, cam, spp=4, parts=m.parts)
    rj = RasterJacobian(r, samples=1)
    calls = []
    monkeypatch.setattr(r, "render", lambda *a, **k: calls.append(1))
    casts = []
    cast = rj._cast
    monkeypatch.setattr(rj, "_cast", lambda *a: casts.append(1) or cast(*a))
    lin = rj.linearise(xr, gamma, albedo, parts_x=parts)
    many = np.concatenate([J] * 12)                                         # 72 columns
    out = lin.apply(np.moveaxis(many, 0, 2))
    assert out.shape == (cam.width * cam.height, 3, len(many))
    assert calls == [] and casts == [1]
    np.testing.assert_allclose(out[..., :len(J)], out[..., len(J):2 * len(J)])


def test_band_edge_term_follows_a_moving_silhouette(scene):
    """With the render's image, a band pixel's derivative is -grad I . du: a sideways shift of
    the head moves its outline, so the band's edge pixels get a derivative (none without the
    image), of the size central differences of the render give there (within 50 %: the image
    gradient spreads the outline's step over two pixels)."""
    m, cam, xr, J, parts, gamma, albedo = scene
    r = FaceRenderer(m.triangles, cam, spp=64, silhouette_spp=0.5, parts=m.parts)
    k = COLUMNS.index("translation_x")
    img = r.image(xr, gamma, albedo, parts_x=parts)[..., :3]
    rj = RasterJacobian(r, samples=2)
    bare = rj.linearise(xr, gamma, albedo, parts_x=parts)
    edged = rj.linearise(xr, gamma, albedo, parts_x=parts, image=img)
    a0 = bare.apply(J[k][:, :, None]).reshape(cam.height, cam.width, 3)
    a1 = edged.apply(J[k][:, :, None]).reshape(cam.height, cam.width, 3)
    band = edged.band & ~edged.face
    assert band.sum() > 100 and np.abs(a0[band]).max() == 0 and np.abs(a1[band]).max() > 0
    h = 2e-4
    fd = (r.image(xr + h * J[k], gamma, albedo, parts_x=parts)[..., :3]
          - r.image(xr - h * J[k], gamma, albedo, parts_x=parts)[..., :3]) / (2 * h)
    assert np.linalg.norm(a1[edged.band]) == pytest.approx(np.linalg.norm(fd[edged.band]), rel=0.5)


def test_hybrid_rows_are_analytic_for_shapes_and_forward_for_jaw_and_pose(scene):
    """The dogleg's default image Jacobian ('hybrid'): the blendshape weights' rows are the
    analytic ones, the jaw's and the head pose's the forward-mode ones, each computed for the
    rows asked (a subset keeps its order)."""
    from invface.fit.shading import ShadingObjective
    m, cam, xr, _, parts, gamma, albedo = scene
    vec = FitVector.of(m)
    plate = np.full((cam.height, cam.width, 3), 0.3, np.float32)
    obj = ShadingObjective(m, m.surface_model("blendshape"), cam, plate, gamma, albedo, np.zeros(vec.P),
                           jacobian="hybrid")
    z = vec.pack(np.zeros(vec.P), np.zeros(3), np.zeros(3))
    xr0, J = posed_jacobian(m.surface_model("blendshape"), z, vec)
    obj._render(xr0)
    index = np.array([0, 5, vec.K, vec.K + 2, vec.size - 1])
    C = obj.image_jacobian(xr0, J[index], index=index)
    np.testing.assert_array_equal(C[:2], obj.analytic_jacobian(xr0, J[index[:2]]))
    fwd = obj.forward_jacobian(xr0, J[index[2:]])          # Dr.Jit's parallel sums: not bit-exact
    np.testing.assert_allclose(C[2:], fwd, rtol=0, atol=1e-5 * np.abs(fwd).max())
    with pytest.raises(Exception, match="jacobian must be"):
        ShadingObjective(m, m.surface_model("blendshape"), cam, plate, gamma, albedo, np.zeros(vec.P), jacobian="x")
