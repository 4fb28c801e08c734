"""Differentiable renderer benchmark: seconds per forward and forward+backward, and gradient noise.

    python bench/render.py [--sizes 360x270 720x540] [--settings 4:0.25 ...] [--seeds 8]
                           [--compare-prb]

The scene is the built-in head (default resolution) under a 9-coefficient SH light with a
smooth albedo. The loss is the masked L2 difference to a target image rendered with the head
moved (rotation 0.02 rad, translation 2 mm) and the light changed, so the gradient has
interior (shading, barycentric) and silhouette (visibility) parts.

Gradient noise: for each quantity (vertex positions x, SH gamma, albedo c), the mean over
seeds of |g_seed - g_mean| / |g_mean| (Euclidean norms over all entries).
``--compare-prb`` times the design measured in issue 5 (mesh as an ``area`` emitter with a
``mesh_attribute`` radiance, Mitsuba's ``prb_projective``, max_depth=1, through mi.render).
"""
from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np

import invface
from invface.render import shading
from invface.render.camera import Camera
from invface.render.renderer import FaceRenderer, write_ply


def scene_inputs(model):
    V = model.neutral
    gamma = shading.constant_light([0.75, 0.7, 0.65])
    gamma[1] = [0.25, 0.25, 0.22]    # from above
    gamma[2] = [0.45, 0.42, 0.4]     # from the front
    gamma[3] = [0.3, 0.25, 0.2]      # from the actor's left
    gamma[6] = [-0.05, -0.05, -0.05]
    albedo = np.clip(np.array([0.78, 0.56, 0.46]) + 0.15 * np.sin(40 * V[:, 1:2]) * np.array(
        [0.5, 1.0, 1.0]) + 0.1 * np.cos(35 * V[:, 0:1]), 0.05, 1)
    return gamma, albedo


def loss_and_grads(r, x, gamma, albedo, target, seed):
    import drjit as dr
    mi = r.mi
    xd, gd, cd = mi.Float(x.ravel().astype(np.float32)), mi.Float(gamma.ravel().astype(np.float32)), \
        mi.Float(albedo.ravel().astype(np.float32))
    dr.enable_grad(xd, gd, cd)
    img = r.render(xd, gd, cd, seed=seed)
    diff = img - target
    loss = dr.sum(dr.square(diff.array)) / dr.width(diff.array)
    dr.backward(loss)
    out = [np.array(dr.grad(a), dtype=np.float64) for a in (xd, gd, cd)]
    dr.sync_thread()
    return out


def measure(model, size, spp, sil, seeds, repeats=3):
    import drjit as dr
    w, h = size
    cam = Camera.front_view(w, h)
    gamma, albedo = scene_inputs(model)
    x = model.neutral
    r_t = FaceRenderer(model.triangles, cam, spp=16, silhouette_spp=0)
    g2 = gamma * 1.05
    g2[3] *= 1.5
    target = r_t.image(x, g2, albedo, rotation=[0, 0.02, 0], translation=[0.002, 0, 0])
    mi = r_t.mi
    T = mi.TensorXf(target)
    r = FaceRenderer(model.triangles, cam, spp=spp, silhouette_spp=sil)
    r.image(x, gamma, albedo)                       # compile
    fwd = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        r.image(x, gamma, albedo)
        fwd.append(time.perf_counter() - t0)
    loss_and_grads(r, x, gamma, albedo, T, 0)    # compile
    both, grads = [], []
    for s in range(max(seeds, repeats)):
        t0 = time.perf_counter()
        g = loss_and_grads(r, x, gamma, albedo, T, s)
        both.append(time.perf_counter() - t0)
        grads.append(g)
    noise = []
    B = model.blendshapes.reshape(len(model.blendshapes), -1)
    for k in range(4):
        G = np.array([g[k] if k < 3 else B @ g[0] for g in grads[:seeds]])
        mean = G.mean(0)
        noise.append(float(np.mean(np.linalg.norm(G - mean, axis=1)) / np.linalg.norm(mean)))
    dr.sync_thread()
    return min(fwd), float(np.median(both)), noise


def measure_prb(model, size, spp, sppp, repeats=3):
    """The issue's reference design: area emitter + mesh_attribute + prb_projective."""
    import drjit as dr
    from invface.render.variant import mitsuba
    mi = mitsuba()
    w, h = size
    cam = Camera.front_view(w, h)
    gamma, albedo = scene_inputs(model)
    V, F = model.neutral.astype(np.float32), model.triangles.astype(np.uint32)
    ply = tempfile.mkstemp(suffix=".ply")[1]       # the attribute has to come from the file
    write_ply(ply, V, F, shading.vertex_radiance(V, F, gamma, albedo))
    scene = mi.load_dict({"type": "scene", "sensor": cam.sensor_dict(spp=spp),
                          "integrator": {"type": "prb_projective", "max_depth": 1, "sppc": spp,
                                         "sppp": sppp, "sppi": 0},
                          "face": {"type": "ply", "filename": ply,
                                   "emitter": {"type": "area", "radiance": {
                                       "type": "mesh_attribute", "name": "vertex_color"}},
                                   "bsdf": {"type": "diffuse", "reflectance": 0.0}}})
    params = mi.traverse(scene)
    fwd, both = [], []
    for i in range(repeats + 1):
        x = mi.Float(params["face.vertex_positions"])
        dr.enable_grad(x)
        params["face.vertex_positions"] = x
        params.update()
        t0 = time.perf_counter()
        img = mi.render(scene, params, seed=0, spp=0)
        dr.eval(img)
        dr.sync_thread()
        t1 = time.perf_counter()
        dr.backward(dr.mean(dr.square(img.array)))
        dr.eval(dr.grad(x))
        dr.sync_thread()
        if i:
            fwd.append(t1 - t0)
            both.append(time.perf_counter() - t0)
    return min(fwd), float(np.median(both))


def silhouette_usefulness(model, size=(360, 270), spp=1):
    """Fraction of silhouette samples that land on a visible edge with a radiance jump, with
    Mitsuba's edge distribution and with ours (``integrator._init_visible_silhouette``)."""
    import drjit as dr
    r = FaceRenderer(model.triangles, Camera.front_view(*size), silhouette_spp=spp)
    gamma, albedo = scene_inputs(model)
    pd = r.integrator.proj_detail
    evaluate = pd.eval_primary_silhouette_radiance_difference
    counts = []

    def counting(scene, sampler, ss, sensor, active=True):
        dL, wl = evaluate(scene, sampler, ss, sensor, active=active)
        counts.append(dr.count(active & dr.any(dL != 0))[0] / dr.width(active))
        return dL, wl
    pd.eval_primary_silhouette_radiance_difference = counting
    out = []
    for ours in (False, True):
        if not ours:
            r.integrator._init_visible_silhouette = lambda scene, sensor: \
                pd.init_primarily_visible_silhouette(scene, sensor)
        else:
            del r.integrator._init_visible_silhouette
        x = r.mi.Float(model.neutral.ravel().astype(np.float32))
        dr.enable_grad(x)
        dr.eval(r.render(x, gamma, albedo))
        out.append(counts[-1])
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--sizes", nargs="+", default=["360x270", "720x540"])
    ap.add_argument("--settings", nargs="+", default=["1:0.25", "4:0.5", "8:0.5", "16:1"],
                    help="spp:silhouette_spp pairs")
    ap.add_argument("--seeds", type=int, default=8)
    ap.add_argument("--compare-prb", action="store_true")
    a = ap.parse_args()
    model = invface.template.build()
    print(f"head: {len(model.neutral)} vertices, {len(model.triangles)} triangles")
    m, o = silhouette_usefulness(model)
    print(f"silhouette samples on visible edges with a radiance jump: Mitsuba's distribution "
          f"{100 * m:.0f} %, visible-edge distribution {100 * o:.0f} %")
    print(f"{'size':>8} {'spp':>4} {'sil spp':>7} {'forward s':>10} {'fwd+bwd s':>10} "
          f"{'noise x':>8} {'noise gamma':>11} {'noise c':>8} {'noise b':>8}")
    for sz in a.sizes:
        size = tuple(int(v) for v in sz.split("x"))
        for st in a.settings:
            spp, sil = st.split(":")
            f, b, n = measure(model, size, int(spp), float(sil), a.seeds)
            print(f"{sz:>8} {spp:>4} {sil:>7} {f:10.3f} {b:10.3f} {100 * n[0]:7.1f}% "
                  f"{100 * n[1]:10.2f}% {100 * n[2]:7.2f}% {100 * n[3]:7.2f}%", flush=True)
        if a.compare_prb:
            f, b = measure_prb(model, size, 16, 4)
            print(f"{sz:>8} prb_projective area emitter (spp 16, sppp 4): forward {f:.3f} s, "
                  f"fwd+bwd {b:.3f} s", flush=True)


if __name__ == "__main__":
    main()
