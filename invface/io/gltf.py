"""A fitted take as glTF 2.0 binary (.glb): the actor's blendshape rig with its shapes as morph
targets and the fit as an animation, for Blender, Unreal, Unity, three.js and Godot.

The file (``write_glb``), in glTF's frame (+Y up, metres, the face looking along +Z: invface's
model frame as it is):

- mesh "Face": the neutral skin, its K blendshapes as morph targets (POSITION offsets, named in
  ``mesh.extras.targetNames``, the convention Blender, three.js and Babylon read), skinned to
- skin "Rig": joints "root" (the head's pose) and its child "jaw" (the jaw's rigid transform
  about its pivot), weights 1 - w and w (the model's jaw skinning weights), identity inverse
  bind matrices: glTF's skinning is then paper 000 Eq. 1-2's x = H T(j)(n + B b);
- animation "fit": per frame the morph weights, and both joints' translation and rotation,
  linearly interpolated; the times are the frames' numbers over the rate.

Written with numpy and json alone: one JSON chunk and one binary chunk, each padded to 4 bytes.
"""
from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np

from ..errors import ConfigError
from .atomic import atomic_path

FLOAT, UINT16, UINT32 = 5126, 5123, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963


class _Buffer:
    """The binary chunk and its views and accessors."""

    def __init__(self):
        self.data, self.views, self.accessors = bytearray(), [], []

    def add(self, array, kind, component, target=None, bounds=False):
        a = np.ascontiguousarray(array)
        while len(self.data) % 4:
            self.data.append(0)
        view = {"buffer": 0, "byteOffset": len(self.data), "byteLength": a.nbytes}
        if target is not None:
            view["target"] = target
        self.data += a.tobytes()
        self.views.append(view)
        acc = {"bufferView": len(self.views) - 1, "componentType": component, "count": len(a), "type": kind}
        if bounds:
            acc["min"], acc["max"] = np.atleast_1d(a.min(0)).tolist(), np.atleast_1d(a.max(0)).tolist()
        self.accessors.append(acc)
        return len(self.accessors) - 1


def quaternion(R):
    """(x, y, z, w) of a rotation matrix (3, 3), w >= 0."""
    from scipy.spatial.transform import Rotation
    q = Rotation.from_matrix(np.asarray(R, float)).as_quat()
    return q if q[3] >= 0 else -q


def write_glb(path, data):
    """Write the rig and its take to ``path`` (.glb) atomically. data: as
    ``usd.write_usd_rig``'s ({"fps", "neutral" (V, 3) m, "triangles" (F, 3), "names" (K,),
    "deltas" (K, V, 3) m, "jaw_weights" (V,), "frames": [{"frame", "weights" (K,),
    "jaw_matrix" (4, 4), "head_matrix" (4, 4)}]}; "camera" is not written).
    Returns the Path."""
    frames = list(data["frames"])
    if not frames:
        raise ConfigError(f"{path}: no frames to write")
    buf = _Buffer()
    n = np.asarray(data["neutral"], np.float32)
    tri = np.asarray(data["triangles"], np.uint32)
    w = np.clip(np.asarray(data["jaw_weights"], np.float32), 0, 1)
    attributes = {"POSITION": buf.add(n, "VEC3", FLOAT, ARRAY_BUFFER, bounds=True),
                  # joint 0 wherever a weight is 0, as the glTF validator asks
                  "JOINTS_0": buf.add(np.stack([0 * w, w > 0, 0 * w, 0 * w], 1).astype(np.uint16), "VEC4", UINT16,
                                      ARRAY_BUFFER),
                  "WEIGHTS_0": buf.add(np.stack([1 - w, w, 0 * w, 0 * w], 1), "VEC4", FLOAT, ARRAY_BUFFER)}
    targets = [{"POSITION": buf.add(np.asarray(d, np.float32), "VEC3", FLOAT, ARRAY_BUFFER, bounds=True)}
               for d in data["deltas"]]
    indices = buf.add(tri.ravel(), "SCALAR", UINT32, ELEMENT_ARRAY_BUFFER)
    names = list(data["names"])
    mesh = {"name": "Face", "primitives": [{"attributes": attributes, "indices": indices, "targets": targets}],
            "weights": [0.0] * len(names), "extras": {"targetNames": names}}
    inverse_bind = buf.add(np.tile(np.eye(4, dtype=np.float32).ravel(), (2, 1)), "MAT4", FLOAT)
    animation = _animation(buf, frames, float(data.get("fps") or 24.0))
    gltf = {"asset": {"version": "2.0", "generator": "invface"},
            "scene": 0, "scenes": [{"name": "Capture", "nodes": [0, 2]}],
            "nodes": [{"name": "root", "children": [1]}, {"name": "jaw"},
                      {"name": "Face", "mesh": 0, "skin": 0}],
            "skins": [{"name": "Rig", "joints": [0, 1], "skeleton": 0, "inverseBindMatrices": inverse_bind}],
            "meshes": [mesh], "animations": [animation],
            "accessors": buf.accessors, "bufferViews": buf.views, "buffers": [{"byteLength": len(buf.data)}]}
    with atomic_path(path) as tmp:
        Path(tmp).write_bytes(_container(gltf, bytes(buf.data)))
    return Path(path)


def _animation(buf, frames, fps):
    """The "fit" animation: morph weights and the root's and jaw's translation and rotation."""
    times = buf.add(np.array([float(f["frame"]) / fps for f in frames], np.float32), "SCALAR", FLOAT, bounds=True)
    weights = np.array([np.asarray(f["weights"], np.float32) for f in frames])
    heads = [(np.asarray(f["head_matrix"], float)[:3, 3], np.asarray(f["head_matrix"], float)[:3, :3]) for f in frames]
    jaws = [(np.asarray(f["jaw_matrix"], float)[:3, 3], np.asarray(f["jaw_matrix"], float)[:3, :3]) for f in frames]
    samplers, channels = [], []

    def channel(node, path, output, kind):
        samplers.append({"input": times, "output": buf.add(output, kind, FLOAT), "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": node, "path": path}})

    channel(2, "weights", weights.reshape(-1).astype(np.float32), "SCALAR")
    for node, pose in ((0, heads), (1, jaws)):
        channel(node, "translation", np.array([t for t, _ in pose], np.float32), "VEC3")
        channel(node, "rotation", np.array([quaternion(R) for _, R in pose], np.float32), "VEC4")
    return {"name": "fit", "samplers": samplers, "channels": channels}


def _container(gltf, binary):
    """The .glb bytes: header, JSON chunk (space-padded), BIN chunk (zero-padded)."""
    text = json.dumps(gltf, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    binary += b"\0" * (-len(binary) % 4)
    total = 12 + 8 + len(text) + 8 + len(binary)
    return (struct.pack("<III", 0x46546C67, 2, total) + struct.pack("<II", len(text), 0x4E4F534A) + text
            + struct.pack("<II", len(binary), 0x004E4942) + binary)
