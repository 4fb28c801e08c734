"""Quick shaded previews of meshes with Mitsuba 3 (no gradients; for looking at models).

Each mesh is drawn with per-vertex colours under a sky light plus a key light. Used by
``invface build-model --preview`` and the report pages.
"""
from __future__ import annotations

import numpy as np

from .variant import mitsuba


def look_at_camera(eye, target, up=(0.0, 1.0, 0.0), fov=30.0, width=512, height=512, spp=16):
    """A Mitsuba perspective sensor dict. eye/target in metres, fov in degrees (x)."""
    mi = mitsuba()
    return {
        "type": "perspective",
        "fov": float(fov),
        "to_world": mi.ScalarTransform4f().look_at(origin=list(map(float, eye)),
                                                   target=list(map(float, target)),
                                                   up=list(map(float, up))),
        "sampler": {"type": "independent", "sample_count": int(spp)},
        "film": {"type": "hdrfilm", "width": int(width), "height": int(height),
                 "rfilter": {"type": "gaussian"}, "pixel_format": "rgba"},
    }


def _mesh(name, vertices, faces, colors):
    mi = mitsuba()
    v = np.ascontiguousarray(vertices, dtype=np.float32)
    f = np.ascontiguousarray(faces, dtype=np.uint32)
    m = mi.Mesh(name, vertex_count=len(v), face_count=len(f), has_vertex_normals=False,
                has_vertex_texcoords=False)
    params = mi.traverse(m)
    params["vertex_positions"] = mi.Float(v.ravel())
    params["faces"] = mi.UInt(f.ravel())
    params.update()
    c = np.broadcast_to(np.asarray(colors, np.float32), (len(v), 3))
    m.add_attribute("vertex_color", 3, mi.Float(np.ascontiguousarray(c).ravel()))
    bsdf = mi.load_dict({"type": "twosided", "bsdf": {
        "type": "diffuse", "reflectance": {"type": "mesh_attribute", "name": "vertex_color"}}})
    m.set_bsdf(bsdf)
    return m


def render_meshes(meshes, camera, key_dir=(-0.5, 0.6, 1.0)):
    """Render ``meshes`` = list of (vertices (V,3), faces (F,3), colors (3,) or (V,3)).

    Returns an (H, W, 4) float32 linear RGBA image (alpha = coverage).
    """
    mi = mitsuba()
    scene = {"type": "scene",
             "integrator": {"type": "direct"},
             "sensor": camera,
             "sky": {"type": "constant", "radiance": {"type": "rgb", "value": 0.35}},
             "key": {"type": "directional", "direction": [-float(x) for x in key_dir],
                     "irradiance": {"type": "rgb", "value": 2.2}}}
    for i, (v, f, c) in enumerate(meshes):
        if len(f) == 0:
            continue
        scene[f"mesh{i}"] = _mesh(f"mesh{i}", v, f, c)
    img = mi.render(mi.load_dict(scene), seed=0)
    return np.array(img, dtype=np.float32)


def to_srgb8(img):
    """Linear RGBA float image -> sRGB uint8 RGB on a white background."""
    rgb = np.clip(img[..., :3], 0, 1)
    a = np.clip(img[..., 3:4], 0, 1) if img.shape[-1] == 4 else 1.0
    srgb = np.where(rgb <= 0.0031308, 12.92 * rgb, 1.055 * np.power(rgb, 1 / 2.4) - 0.055)
    out = srgb * a + (1 - a) * 1.0
    return (np.clip(out, 0, 1) * 255 + 0.5).astype(np.uint8)
