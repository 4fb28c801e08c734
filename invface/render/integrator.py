"""``invface_vertex``: a projective-sampling integrator that shows a per-vertex radiance.

The face's shading (SH irradiance x albedo) is computed per vertex in Dr.Jit (``shading.py``)
and stored in the mesh attribute ``vertex_color``. This integrator returns that attribute,
barycentrically interpolated at the first hit of each camera ray: one ray per sample, no
emitter or BSDF work. It derives from Mitsuba's ``PSIntegrator``, so image derivatives have
both parts:

- interior: the attribute and the hit's barycentrics are attached to the vertex positions
  and colours (continuous derivative, ``sppc`` samples per pixel);
- silhouettes: Mitsuba's projective sampling of the primarily visible silhouette edges
  (``sppp`` samples per pixel) gives the visibility derivative where the face occludes the
  background or itself (the nose over the cheek).

Indirect visibility does not exist in this image model, so ``sppi`` is always 0 (it would
build a guiding octree on every backward pass).

Compared with Mitsuba's ``prb_projective`` with the mesh as an ``area`` emitter by
``bench/render.py``.
"""
from __future__ import annotations

from .variant import mitsuba

NAME = "invface_vertex"
ATTRIBUTE = "vertex_color"
_REGISTERED = False


def register():
    """Register the integrator plugin with Mitsuba (once per process)."""
    global _REGISTERED
    if _REGISTERED:
        return
    mi = mitsuba()
    import drjit as dr

    class VertexRadianceIntegrator(mi.ad.integrators.common.PSIntegrator):
        def __init__(self, props):
            super().__init__(props)
            self.max_depth = 1
            self.rr_depth = 1
            self.radiative_backprop = False
            self.sppi = 0
            self.backplate = None

        def set_backplate(self, texture, to_pixel):
            """Show ``texture`` (a ``mi.Texture2f`` of the plate) where rays miss the face:
            ``to_pixel`` (3x3, world direction -> homogeneous texture coordinates, K R with
            the image size folded in) finds the plate point behind each ray. None clears it."""
            self.backplate = None if texture is None else (texture, mi.Matrix3f(to_pixel))

        def _background(self, ray, active):
            if self.backplate is None:
                return mi.Spectrum(0.0)
            texture, M = self.backplate
            q = M @ mi.Vector3f(dr.detach(ray.d))
            uv = mi.Point2f(q.x, q.y) / q.z
            return mi.Spectrum(texture.eval(uv, active & (q.z > 0)))

        def _radiance(self, si, active, ray=None):
            L = si.shape.eval_attribute_3(ATTRIBUTE, si, active)
            background = mi.Spectrum(0.0) if ray is None else self._background(ray, ~active)
            return dr.select(active, mi.Spectrum(L), background)

        def sample(self, mode, scene, sampler, ray, depth, δL, state_in, active,
                   project=False, si_shade=None, **kwargs):
            primal = mode == dr.ADMode.Primal
            with dr.resume_grad(when=not primal):
                if si_shade is None:
                    si = scene.ray_intersect(mi.Ray3f(dr.detach(ray)), ray_flags=mi.RayFlags.All,
                                             coherent=True, active=active)
                else:
                    si = si_shade
                valid = mi.Bool(active) & si.is_valid()
                L = self._radiance(si, valid, ray)
            state = [dr.zeros(mi.Ray3f), mi.Bool(False)] if project else L
            return L, valid, [], state

        def sample_radiance_difference(self, scene, ss, curr_depth, sampler, wavelengths, active):
            # background: whatever lies behind the silhouette point (other face parts, the plate)
            ray_bg = ss.spawn_ray(wavelengths)
            L_bg, _, _, _ = self.sample(dr.ADMode.Primal, scene, sampler, ray_bg, curr_depth,
                                        None, None, active, False, None)
            # foreground: the silhouette point itself
            pi = dr.zeros(mi.PreliminaryIntersection3f)
            pi.valid = active
            pi.t = 1
            pi.prim_index = ss.prim_index
            pi.prim_uv = ss.uv
            pi.shape = ss.shape
            si = pi.compute_surface_interaction(mi.Ray3f(ss.p - ss.d, ss.d), mi.RayFlags.All, active)
            L_fg = self._radiance(si, active)
            diff = L_fg - L_bg
            return diff, active & (dr.max(dr.abs(diff)) > 0)

        def sample_importance(self, *args, **kwargs):  # pragma: no cover - sppi is 0
            raise NotImplementedError("invface_vertex has no indirect visibility")

        def render_attached(self, scene, sensor, seed, spp, silhouette_spp):
            """Image (H, W, C) whose value is the primal render and whose derivative (forward
            or reverse, through the scene parameters) includes both interior and silhouette
            terms: one pass, unlike ``mi.render`` which renders the primal again.

            spp: samples per pixel (int) for the interior; silhouette_spp: silhouette samples
            per pixel, may be fractional (0 disables the visibility derivative)."""
            film = sensor.film()
            with dr.suspend_grad():
                sampler, spp = self.prepare(sensor, seed, spp, [])
                ray, weight, pos = self.sample_rays(scene, sensor, sampler)
            with dr.resume_grad():
                L, valid, _, _ = self.sample(dr.ADMode.Backward, scene, sampler, ray, 0, None,
                                             None, mi.Bool(True))
            block = film.create_block()
            block.set_coalesce(block.coalesce() and spp >= 4)
            mi.ad.integrators.common.ADIntegrator._splat_to_block(
                block, film, pos, value=L * weight, weight=1.0,
                alpha=dr.select(valid, mi.Float(1), mi.Float(0)), aovs=[],
                wavelengths=ray.wavelengths)
            film.put_block(block)
            image = film.develop()
            if silhouette_spp > 0 and len(scene.silhouette_shapes()) > 0:
                edge = self._silhouette(scene, sensor, seed, silhouette_spp)
                image = image + (edge - dr.detach(edge))
            return image

        def _silhouette(self, scene, sensor, seed, silhouette_spp):
            """Primarily visible silhouette derivative with a fractional sample budget (the
            body of PSIntegrator.render_primarily_visible_silhouette)."""
            film = sensor.film()
            pixels = dr.prod(film.crop_size() + 2 * film.rfilter().border_size())
            count = max(1, int(round(silhouette_spp * pixels)))
            with dr.suspend_grad():
                self._init_visible_silhouette(scene, sensor)
                sampler = sensor.sampler().clone()
                sampler.set_sample_count(1)
                sampler.set_samples_per_wavefront(1)
                sampler.seed(0xffffffff ^ seed, count)
                film.prepare([])
                centre = sensor.world_transform() @ mi.Point3f(0)
                ss = self.proj_detail.sample_primarily_visible_silhouette(
                    scene, centre, sampler.next_2d(), True)
                active = ss.is_valid() & (ss.pdf > 0)
                J = self.proj_detail.sensor_jacobian(sensor, ss)
                dL, wavelengths = self.proj_detail.eval_primary_silhouette_radiance_difference(
                    scene, sampler, ss, sensor, active=active)
                active &= dr.any(dL != 0)
            si = dr.zeros(mi.SurfaceInteraction3f)
            si.p, si.prim_index, si.uv = ss.p, ss.prim_index, ss.uv
            motion = dr.dot(ss.shape.differential_motion(dr.detach(si), active), ss.n)
            with dr.suspend_grad():
                it = dr.zeros(mi.Interaction3f)
                it.p = ss.p
                ds, _ = sensor.sample_direction(it, mi.Point2f(0))
            block = film.create_block(normalize=True)
            # ds.uv is relative to the film's crop window; the block takes film positions
            block.put(pos=ds.uv + mi.Vector2f(film.crop_offset()), wavelengths=wavelengths,
                      value=dL * motion * dr.rcp(ss.pdf) * J * (pixels / count),
                      weight=0, alpha=1, active=active)
            film.put_block(block)
            return film.develop()

        def _init_visible_silhouette(self, scene, sensor, probes=5):
            """Silhouette-edge distribution for the camera: Mitsuba's candidate edges, each
            weighted by its projected length on the film, and zero when none of ``probes``
            points along it passes the estimator's own visibility test.

            Mitsuba weights edges by their 3D length, so on the head about two thirds of
            the samples landed on hidden edges (the far side of the nose, inside the lips)
            and foreshortened edges were over-sampled; both only add variance. Any weights
            give an unbiased estimate, as the sample pdf divides the result.

            Closed lips and eyelids are pairs of coincident open boundaries. There the image
            has a kink: parting them shows the empty mouth, pressing them together changes
            nothing. Each boundary edge is sampled on its own, which gives the one-sided
            derivative of parting (the relative motion of the two lips)."""
            import numpy as np
            pd = self.proj_detail
            pd.init_primarily_visible_silhouette(scene, sensor)
            centre = sensor.world_transform() @ mi.Point3f(0)
            viewpoint = mi.Point3f(centre)
            for i, shape in enumerate(scene.silhouette_shapes()):
                indices = pd.primary_indices[i]
                n = dr.width(indices)
                if n == 0:
                    continue
                k = probes + 2                 # the probes and both end points
                j = dr.arange(mi.UInt32, n * k)
                edge = dr.gather(mi.UInt32, indices, j // k)
                q = mi.Float(j % k)
                t = dr.select(q < probes, (q + 0.5) / probes, q - probes)
                ss = shape.sample_precomputed_silhouette(viewpoint, edge, t, True)
                probe = mi.SilhouetteSample3f(ss)
                probe.d = -probe.d
                ray = probe.spawn_ray()
                ray.maxt = dr.norm(centre - ray.o) * (1 - mi.math.ShadowEpsilon)
                it = dr.zeros(mi.Interaction3f)
                it.p = ss.p
                ds, _ = sensor.sample_direction(it, mi.Point2f(0))
                seen = ss.is_valid() & ~scene.ray_test(ray) & (ds.pdf != 0)
                seen = np.array(seen, dtype=bool).reshape(n, k)[:, :probes].any(1)
                uv = np.array(ds.uv, dtype=np.float64).T.reshape(n, k, 2)
                weights = np.where(seen, np.linalg.norm(uv[:, -1] - uv[:, -2], axis=1) + 1e-6, 0.0)
                if weights.sum() > 0:
                    pd.primary_distributions[i] = mi.DiscreteDistribution(
                        mi.Float(weights.astype(np.float32)))

        def to_string(self):
            return f"VertexRadianceIntegrator[sppc={self.sppc}, sppp={self.sppp}]"

    mi.register_integrator(NAME, lambda props: VertexRadianceIntegrator(props))
    _REGISTERED = True
