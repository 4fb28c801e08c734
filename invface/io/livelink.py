"""Live Link Face CSV: the layout Unreal's Live Link Face importer and Blender's face importers read.

One row per frame; the columns, in a recording's order:

    Timecode, BlendShapeCount, the 52 ARKit blendshapes in PascalCase (EyeBlinkLeft ... TongueOut),
    HeadYaw, HeadPitch, HeadRoll, LeftEyeYaw, LeftEyePitch, LeftEyeRoll, RightEyeYaw,
    RightEyePitch, RightEyeRoll

- Timecode: ``HH:MM:SS:FF.mmm`` at the clip's frame rate: FF the frame within the second, .mmm
  the sub-frame remainder in thousandths of a frame (000 for frame-aligned samples).
- BlendShapeCount: 61, the number of value columns after it.
- Blendshape values in [0, 1]; Left and Right are the actor's own, as in ARKit. Some Live Link
  importers mirror left and right because the phone's front camera does (the recording's Left is
  the actor's right when the mirrored preview was kept); invface writes the actor's side, so a
  rig that expects the mirrored convention swaps the Left/Right pairs on import.
- Head rotations in radians, from the fit's head rotation (Euler XYZ, invface's frame: +Y up,
  +Z out of the face): HeadYaw about +Y, HeadPitch about +X, HeadRoll about +Z.
- Eye rotations in radians; a model without gaze controls writes 0.

Readers match columns by name (``read_livelink_csv``), never by position.
"""
from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from ..errors import InvfaceError
from .tables import write_csv

HEAD_COLUMNS = ("HeadYaw", "HeadPitch", "HeadRoll")
EYE_COLUMNS = ("LeftEyeYaw", "LeftEyePitch", "LeftEyeRoll", "RightEyeYaw", "RightEyePitch", "RightEyeRoll")


def pascal(name):
    """ARKit's camelCase name in Live Link Face's PascalCase: eyeBlinkLeft -> EyeBlinkLeft."""
    return name[:1].upper() + name[1:]


def columns(arkit_names):
    """The header of a recording: Timecode, BlendShapeCount, the blendshapes (PascalCase), head
    and eye rotations."""
    return ["Timecode", "BlendShapeCount", *[pascal(n) for n in arkit_names], *HEAD_COLUMNS, *EYE_COLUMNS]


def timecode(frame, fps):
    """``HH:MM:SS:FF.mmm`` of frame index ``frame`` at ``fps`` frames per second."""
    fps = float(fps)
    if not fps > 0:
        raise InvfaceError(f"timecode: the frame rate must be positive, not {fps}")
    whole = int(np.floor(frame + 1e-9))
    sub = int(round((frame - whole) * 1000))
    per_second = int(round(fps))
    seconds, ff = divmod(whole, per_second)
    hh, rest = divmod(seconds, 3600)
    mm, ss = divmod(rest, 60)
    return f"{hh:02d}:{mm:02d}:{ss:02d}:{ff:02d}.{sub:03d}"


def write_livelink_csv(path, frames, arkit_names, fps=24.0):
    """Write a Live Link Face CSV to ``path`` atomically. frames: one dict per row with "frame"
    (the index at ``fps``), "arkit" ({ARKit name: value}), "rotation" (3,) rad (Euler XYZ) and
    optionally "eyes" (6,) rad (left yaw, pitch, roll, right yaw, pitch, roll). Returns the Path."""
    names = list(arkit_names)
    rows = []
    for f in frames:
        rot = np.asarray(f.get("rotation", np.zeros(3)), float)
        eyes = np.asarray(f.get("eyes", np.zeros(6)), float)
        values = [float(f["arkit"].get(n, 0.0)) for n in names]
        head = [rot[1], rot[0], rot[2]]                     # yaw (about +Y), pitch (+X), roll (+Z)
        rows.append([timecode(f.get("frame", 0), fps), len(values) + 9,
                     *(f"{v:.6f}" for v in values + head + list(eyes))])
    return write_csv(path, columns(names), rows, lineterminator="\n")


def read_livelink_csv(path):
    """Rows of a Live Link Face CSV as dicts {column: value}: Timecode a string, every other
    column a float, matched by the header's names."""
    path = Path(path)
    try:
        with open(path, newline="") as fh:
            rows = list(csv.DictReader(fh))
    except OSError as e:
        raise InvfaceError(f"{path}: not a readable CSV file ({e})") from None
    return [{k: (v if k == "Timecode" else float(v)) for k, v in r.items()} for r in rows]
