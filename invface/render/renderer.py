"""The differentiable image model F(x_R(w), gamma, c) of paper 000, Sec. 8.3, in Mitsuba 3.

    r = FaceRenderer(model.triangles, Camera.front_view(720, 540))
    img = r.image(x, gamma, albedo, rotation, translation)       # numpy (H, W, 4), linear

    # differentiable: Dr.Jit inputs in, attached TensorXf (H, W, 4) out
    x = bridge.SurfaceFunction(model.surface_model("simulation"))(p)
    img = r.render(x, gamma, albedo, rotation, translation)
    dr.backward(loss(img))          # gradients reach p, gamma, albedo, rotation, translation

Design (measured in bench/render.py, figures in bench/RESULTS.md): shading = albedo x SH
irradiance / pi is computed per vertex in Dr.Jit (``shading.vertex_radiance_dr``) from the
posed vertices x_R = R(theta) x + t, stored in the mesh's ``vertex_color`` attribute and shown
by the ``invface_vertex`` projective-sampling integrator (``integrator.py``). The scene is
built once per renderer; each call only updates the traversed parameters, so Dr.Jit reuses
its compiled kernels. Channel 3 is alpha (coverage), a mask for losses; the background is 0
(or the backplate, when one is given).
Alpha carries no silhouette derivative: losses compare the RGB channels and use alpha only as
a (constant) weight.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import ConfigError
from ..io.atomic import write_text
from ..io.meshes import write_ply
from .camera import Camera
from .integrator import NAME, ATTRIBUTE, register
from .shading import pose_dr, vertex_radiance_dr
from .variant import mitsuba


SCENE_TEMPLATE = Path(__file__).resolve().parents[2] / "scenes" / "face.xml"


class FaceRenderer:
    """Renders one triangle mesh (fixed topology) through one camera.

    triangles (F, 3) int; camera: ``Camera``; spp: interior samples per pixel (multi-jittered);
    silhouette_spp: silhouette (visibility-gradient) samples per pixel, may be fractional;
    seed: the fixed sample seed (the same inputs give the same image). The defaults (8, 0.5)
    keep the gradient's noise on the controls small at a plate's size (bench/render.py).
    backplate: an optional linear image (H, W, 3) shown behind the face (the plate itself),
    so that silhouette derivatives see the plate's background rather than black: rays that
    miss the face look the plate up (bilinearly) at their own pixel position.
    crop: (x0, y0, width, height) px: render only that window of the camera's image (the
    returned images are that size; the pixels keep the full image's rays).
    parts: the model's ``InnerParts`` (eyes, teeth, tongue, mouth lining) or None: a second
    mesh with its own fixed albedo under the same light and pose, placed by each call's
    ``parts_x`` (default: at rest). It carries no gradient: the image's derivatives reach the
    skin (its silhouettes against the parts included) but not the parts' positions."""

    def __init__(self, triangles, camera: Camera, spp=8, silhouette_spp=0.5, seed=0, backplate=None,
                 crop=None, parts=None):
        if spp < 1:
            raise ConfigError(f"spp must be >= 1, got {spp}")
        if silhouette_spp < 0:
            raise ConfigError(f"silhouette_spp must be >= 0, got {silhouette_spp}")
        mi = self.mi = mitsuba()
        import drjit as dr
        self.dr = dr
        register()
        self.camera = camera
        self.spp, self.silhouette_spp, self.seed = int(spp), float(silhouette_spp), int(seed)
        tri = np.ascontiguousarray(triangles, np.uint32)
        self.vertex_count = int(tri.max()) + 1
        mesh = mi.Mesh("face", self.vertex_count, len(tri), has_vertex_normals=False)
        params = mi.traverse(mesh)
        params["faces"] = mi.UInt(tri.ravel())
        params.update()
        mesh.add_attribute(ATTRIBUTE, 3, dr.zeros(mi.Float, 3 * self.vertex_count))
        self.faces = mi.UInt(tri.ravel())
        scene = {"type": "scene", "integrator": {"type": NAME, "sppi": 0},
                 "sensor": camera.sensor_dict(spp=self.spp, sampler="multijitter", crop=crop), "face": mesh}
        keep = ["face.vertex_positions", f"face.{ATTRIBUTE}"]
        self.parts = parts
        if parts is not None:
            P = len(parts.vertices)
            pm = mi.Mesh("parts", P, len(parts.triangles), has_vertex_normals=False)
            pp = mi.traverse(pm)
            self.parts_faces = mi.UInt(np.ascontiguousarray(parts.triangles, np.uint32).ravel())
            pp["faces"] = self.parts_faces
            pp["vertex_positions"] = mi.Float(np.asarray(parts.vertices, np.float32).ravel())
            pp.update()
            pm.add_attribute(ATTRIBUTE, 3, dr.zeros(mi.Float, 3 * P))
            self.parts_albedo = mi.Float(np.asarray(parts.albedo, np.float32).ravel())
            scene["parts"] = pm
            keep += ["parts.vertex_positions", f"parts.{ATTRIBUTE}"]
        self.scene = mi.load_dict(scene)
        self.face_shape = self.scene.shapes()[[s.id() for s in self.scene.shapes()].index("face")]
        self.params = mi.traverse(self.scene)
        self.params.keep(keep)
        self.sensor = self.scene.sensors()[0]
        self.integrator = self.scene.integrator()
        if backplate is not None:
            self._backplate(np.asarray(backplate, np.float32))

    def _backplate(self, image):
        """Hand the plate to the integrator as a bilinear texture looked up where camera rays
        miss the face: each such ray sees the plate at its own pixel position."""
        mi, cam = self.mi, self.camera
        h, w = image.shape[:2]
        if image.ndim != 3 or image.shape[2] != 3 or (w, h) != cam.size:
            raise ConfigError(f"backplate is {w}x{h} px, the camera is {cam.width}x{cam.height}")
        texture = mi.Texture2f(mi.TensorXf(np.ascontiguousarray(image, np.float32)),
                               filter_mode=self.dr.FilterMode.Linear, wrap_mode=self.dr.WrapMode.Clamp)
        # world direction -> camera frame -> pixels (centres at integers) -> texture [0, 1]^2
        to_texture = np.array([[1 / w, 0, 0.5 / w], [0, 1 / h, 0.5 / h], [0, 0, 1]]) @ cam.K @ cam.R
        self.integrator.set_backplate(texture, to_texture.astype(np.float32).tolist())

    def _as_float(self, a, n, name):
        if isinstance(a, np.ndarray) or isinstance(a, (list, tuple)):
            a = np.asarray(a, np.float32).ravel()
            if a.size != n or not np.all(np.isfinite(a)):
                raise ConfigError(f"{name}: expected {n} finite values, got {a.size}")
            return self.mi.Float(a)
        if self.dr.width(a) != n:
            raise ConfigError(f"{name}: expected {n} values, got {self.dr.width(a)}")
        return a

    def _pose(self, x, rotation, translation):
        if rotation is None and translation is None:
            return x
        rot = self._as_float(np.zeros(3) if rotation is None else rotation, 3, "rotation")
        tr = self._as_float(np.zeros(3) if translation is None else translation, 3, "translation")
        return pose_dr(x, rot, tr)

    def vertex_radiance(self, x, gamma, albedo, rotation=None, translation=None):
        """Posed positions (3V,) and per-vertex radiance (3V,) as Dr.Jit Floats."""
        V = self.vertex_count
        x = self._pose(self._as_float(x, 3 * V, "vertex positions"), rotation, translation)
        gamma = self._as_float(gamma, 27, "SH lighting gamma (9x3)")
        albedo = self._as_float(albedo, 3 * V, "albedo")
        return x, vertex_radiance_dr(x, self.faces, gamma, albedo)

    def _place_parts(self, parts_x, gamma, rotation, translation):
        """Put the parts at ``parts_x`` (P,3) m (None: at rest), posed and lit like the skin."""
        if self.parts is None:
            return
        dr = self.dr
        with dr.suspend_grad():
            P = len(self.parts.vertices)
            px = self.parts.vertices if parts_x is None else parts_x
            px = self._pose(self._as_float(np.asarray(px, np.float32), 3 * P, "parts' positions"),
                            None if rotation is None else dr.detach(self._as_float(rotation, 3, "rotation")),
                            None if translation is None else dr.detach(self._as_float(translation, 3, "translation")))
            gamma = dr.detach(self._as_float(gamma, 27, "SH lighting gamma (9x3)"))
            self.params["parts.vertex_positions"] = px
            self.params[f"parts.{ATTRIBUTE}"] = vertex_radiance_dr(px, self.parts_faces, gamma, self.parts_albedo)

    def place(self, x, parts_x=None, rotation=None, translation=None):
        """Put the skin at posed positions x (V,3) float32 m and the inner parts at parts_x
        (their pose rotation, translation), for ray queries on the scene (no shading)."""
        self.params["face.vertex_positions"] = self.mi.Float(np.asarray(x, np.float32).ravel())
        self._place_parts(parts_x, np.zeros(27), rotation, translation)
        self.params.update()

    def render(self, x, gamma, albedo, rotation=None, translation=None, seed=None, spp=None, parts_x=None):
        """TensorXf (H, W, 4): linear RGB + alpha, attached to every Dr.Jit input with grad.

        x: vertex positions (3V,) or (V,3) m; gamma: (9,3) or (27,); albedo (V,3) or (3V,);
        rotation (3,) rad Euler XYZ and translation (3,) m: the rigid head pose; parts_x
        (P,3) m: the inner parts' positions in x's frame (``FaceModel.parts_positions``;
        default at rest), posed like x."""
        xr, rad = self.vertex_radiance(x, gamma, albedo, rotation, translation)
        self.params["face.vertex_positions"] = xr
        self.params[f"face.{ATTRIBUTE}"] = rad
        self._place_parts(parts_x, gamma, rotation, translation)
        self.params.update()
        mi, dr = self.mi, self.dr
        seed = dr.opaque(mi.UInt32, self.seed if seed is None else int(seed))
        # visibility derivatives are only needed when the geometry carries gradients
        edges = self.silhouette_spp if dr.grad_enabled(xr) else 0.0
        return self.integrator.render_attached(self.scene, self.sensor, seed,
                                               self.spp if spp is None else int(spp), edges)

    def coverage(self, x, rotation=None, translation=None, samples=3, parts_x=None):
        """The linear image operator of the current geometry: image = W @ vertex radiance.

        Casts ``samples`` x ``samples`` rays per pixel (fixed stratified positions) through
        the posed mesh with Mitsuba and interpolates barycentrically, as the renderer does.
        Returns (pixels (M,) flat indices row*W+col of the pixels whose every ray hits the
        face's skin first (not the background, not an eye or the mouth behind it), W scipy
        CSR (M, V) of barycentric weights / samples^2)."""
        import scipy.sparse as sp
        mi, dr = self.mi, self.dr
        with dr.suspend_grad():
            xr = self.vertex_radiance(np.asarray(x, np.float32), np.zeros(27),
                                      np.zeros((self.vertex_count, 3)), rotation, translation)[0]
            self.params["face.vertex_positions"] = xr
            self._place_parts(parts_x, np.zeros(27), rotation, translation)
            self.params.update()
            w, h = self.camera.size
            k = int(samples)
            off = (np.arange(k) + 0.5) / k
            py, px = np.divmod(np.arange(w * h), w)
            sx = (px[:, None, None] + off[None, None, :]).repeat(k, 1).reshape(-1) / w
            sy = (py[:, None, None] + off[None, :, None]).repeat(k, 2).reshape(-1) / h
            ray, _ = self.sensor.sample_ray(0.0, 0.0, mi.Point2f(sx.astype(np.float32), sy.astype(np.float32)),
                                            mi.Point2f(0.5))
            pi = self.scene.ray_intersect_preliminary(ray, coherent=True)
            valid = np.array(pi.is_valid() & (pi.shape == mi.ShapePtr(self.face_shape)), bool)
            prim = np.array(pi.prim_index, np.int64)
            uv = np.array(pi.prim_uv, np.float64).T
        full = valid.reshape(-1, k * k).all(1)
        pixels = np.flatnonzero(full)
        sel = np.repeat(full, k * k)
        tri = np.asarray(self.faces).reshape(-1, 3)[prim[sel]]
        b = np.stack([1 - uv[sel, 0] - uv[sel, 1], uv[sel, 0], uv[sel, 1]], 1) / (k * k)
        rows = np.repeat(np.arange(len(pixels)), k * k * 3)
        W = sp.csr_matrix((b.ravel(), (rows, tri.ravel())), shape=(len(pixels), self.vertex_count))
        return pixels, W

    def export_scene(self, folder, x, gamma, albedo, rotation=None, translation=None):
        """Write the current image model as a stand-alone Mitsuba scene: ``face.ply`` (posed
        skin, float per-vertex radiance) and ``face.xml`` from ``scenes/face.xml``. Returns
        the XML path; ``mi.load_file(path)`` renders the same image."""
        from pathlib import Path
        folder = Path(folder)
        folder.mkdir(parents=True, exist_ok=True)
        with self.dr.suspend_grad():
            xr, rad = self.vertex_radiance(np.asarray(x, np.float32), np.asarray(gamma, np.float32),
                                           np.asarray(albedo, np.float32), rotation, translation)
        write_ply(folder / "face.ply", np.array(xr).reshape(-1, 3), np.asarray(self.faces).reshape(-1, 3),
                  np.array(rad).reshape(-1, 3))
        sensor = self.camera.sensor_dict()
        values = {"mesh": "face.ply", "width": str(self.camera.width), "height": str(self.camera.height),
                  "fov": repr(sensor["fov"]), "ppx": repr(sensor["principal_point_offset_x"]),
                  "ppy": repr(sensor["principal_point_offset_y"]), "spp": str(self.spp),
                  "to_world": " ".join(repr(float(v)) for v in
                                       np.array(sensor["to_world"].matrix, np.float64).ravel())}
        if not SCENE_TEMPLATE.is_file():
            raise ConfigError(f"{SCENE_TEMPLATE}: scene template missing; export_scene needs the "
                              "repository's scenes/ folder (install from the source tree)")
        text = SCENE_TEMPLATE.read_text()
        for k in sorted(values, key=len, reverse=True):
            text = text.replace(f"${k}", values[k])
        return write_text(folder / "face.xml", text)

    def image(self, x, gamma, albedo, rotation=None, translation=None, seed=None, spp=None, parts_x=None):
        """numpy (H, W, 4) float32 render (no gradients)."""
        with self.dr.suspend_grad():
            img = self.render(np.asarray(x, np.float32), np.asarray(gamma, np.float32),
                              np.asarray(albedo, np.float32),
                              None if rotation is None else np.asarray(rotation, np.float32),
                              None if translation is None else np.asarray(translation, np.float32),
                              seed=seed, spp=spp, parts_x=parts_x)
        return np.array(img, dtype=np.float32)
