"""Run inside Blender's Python (``bpy``) by ``bench/blender_client.py``: import a take's USD,
compare the face mesh with the fit's surface, and render one frame through the solved camera.

    python _blender_inner.py USD EXPECTED.npz OUT.png OUT.json

EXPECTED.npz holds "points" (V, 3) m (the fit's posed surface, the model's +Y-up frame),
"frame" (the time code), "width" and "height" (the plate's pixels).
"""
import json
import sys

import bpy
import numpy as np


def main(usd, expected, png, report):
    want = np.load(expected)
    bpy.ops.wm.read_factory_settings(use_empty=True)
    bpy.ops.wm.usd_import(filepath=usd)
    scene = bpy.context.scene
    scene.frame_set(int(want["frame"]))
    meshes = [o for o in scene.objects if o.type == "MESH"]
    face = next(o for o in meshes if o.name.startswith("Face"))
    depsgraph = bpy.context.evaluated_depsgraph_get()
    evaluated = face.evaluated_get(depsgraph)
    mesh = evaluated.to_mesh()
    co = np.empty(len(mesh.vertices) * 3)
    mesh.vertices.foreach_get("co", co)
    world = np.array(evaluated.matrix_world)
    pts = (np.c_[co.reshape(-1, 3), np.ones(len(mesh.vertices))] @ world.T)[:, :3]
    truth = np.asarray(want["points"], float)
    # Blender is +Z up: the importer turns USD's +Y-up stage a quarter turn about X, and takes
    # metersPerUnit into metres
    truth_blender = np.c_[truth[:, 0], -truth[:, 2], truth[:, 1]]
    err = np.linalg.norm(pts - truth_blender, axis=1) if len(pts) == len(truth) else np.array([np.inf])
    cams = [o for o in scene.objects if o.type == "CAMERA"]
    scene.camera = cams[0]
    scene.render.engine = "CYCLES"
    scene.cycles.device = "CPU"
    scene.cycles.samples = 16
    scene.render.resolution_x, scene.render.resolution_y = int(want["width"]), int(want["height"])
    scene.render.resolution_percentage = 100
    scene.render.filepath = png
    scene.view_settings.view_transform = "Standard"        # the plate as it is, no tone mapping
    world_ = bpy.data.worlds.new("light") if scene.world is None else scene.world
    scene.world = world_
    world_.use_nodes = True
    world_.node_tree.nodes["Background"].inputs[1].default_value = 1.0
    bpy.ops.render.render(write_still=True)
    out = {"blender": bpy.app.version_string, "objects": sorted(o.name for o in scene.objects),
           "vertices": len(mesh.vertices), "expected_vertices": int(len(truth)),
           "median_m": float(np.median(err)), "max_m": float(err.max()),
           "camera": {"lens_mm": cams[0].data.lens, "sensor_mm": cams[0].data.sensor_width,
                      "shift": [cams[0].data.shift_x, cams[0].data.shift_y]},
           "frame_range": [scene.frame_start, scene.frame_end]}
    evaluated.to_mesh_clear()
    with open(report, "w") as f:
        json.dump(out, f, indent=1)


if __name__ == "__main__":
    args = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
    main(*args)
