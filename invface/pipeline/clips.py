"""Frame sources of a plate sequence: a video file, a folder of images or one image.

    clip = open_clip("take3.mp4", frames="0:72:2")
    for frame in clip.frames():              # in order, decoded once
        frame.index, frame.name, frame.time, frame.plate, frame.digest

A video is decoded with OpenCV's ``VideoCapture`` (FFmpeg inside the opencv wheel, already a
dependency): frames are read in order from the first selected one, so a chunk of a clip
costs one seek. Frame ``i`` of ``CLIP.mp4`` is named ``CLIP.frame_00000i``; its sidecars sit
beside the video under that name (``CLIP.frame_00000i.curves.json``, ``.truth.json``), and
the camera of the whole clip is ``CLIP.json`` (else the front view at the frame size). A
frame's ``digest`` (SHA-1 of its pixels and camera) is what a resumed run compares to decide
that a frame was fitted from the same input.
"""
from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InvfaceError

VIDEO_SUFFIXES = (".mp4", ".mov", ".avi", ".mkv", ".m4v", ".webm")
IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".exr")


def parse_frames(spec, count):
    """Frame indices selected by "START:STOP[:STEP]" (Python slice rules; either end may be
    empty, negative counts from the end) or a single index, out of ``count`` frames."""
    if spec is None or spec == "":
        return list(range(count))
    try:
        parts = [int(s) if s.strip() else None for s in str(spec).split(":")]
    except ValueError:
        parts = []
    if not 1 <= len(parts) <= 3 or (len(parts) > 1 and parts[2:] == [0]):
        raise InvfaceError(f"--frames {spec}: give START:STOP[:STEP] (e.g. 0:72:2) or one frame index")
    if len(parts) == 1:
        i = parts[0] + count if parts[0] < 0 else parts[0]
        sel = [i] if 0 <= i < count else []
    else:
        sel = list(range(count))[slice(*parts)]
    if not sel:
        raise InvfaceError(f"--frames {spec}: selects no frame of the {count} there are")
    return sel


@dataclass
class Frame:
    """One frame of a clip: its index in the source, name, time (s), the Plate (linear,
    undistorted) and the digest of its pixels and camera."""

    index: int
    name: str
    time: float
    plate: object
    digest: str


class Clip:
    """A sequence of plates: ``source`` (video, folder or image path), ``kind`` ("video",
    "folder" or "image"), the selected frame ``indices`` and their ``names``, ``fps`` (frames
    per second; 0 for images), and the camera (None: each plate's own sidecar or the front
    view). ``frames(start, stop)`` yields Frames of the selection's positions [start, stop)."""

    def __init__(self, source, frames=None, camera=None):
        src = Path(source)
        self.source, self.camera = src, camera
        if src.is_dir():
            self.kind = "folder"
            self.paths = sorted(f for f in src.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES
                                and not f.name.startswith("."))
            if not self.paths:
                raise InvfaceError(f"{src}: no plate images ({', '.join(IMAGE_SUFFIXES)}) in this folder")
            self.fps, count = 0.0, len(self.paths)
        elif src.is_file() and src.suffix.lower() in VIDEO_SUFFIXES:
            import cv2
            self.kind = "video"
            cap = cv2.VideoCapture(str(src))
            ok, first = cap.read() if cap.isOpened() else (False, None)
            count, self.fps = int(cap.get(cv2.CAP_PROP_FRAME_COUNT)), float(cap.get(cv2.CAP_PROP_FPS) or 0)
            cap.release()
            if not ok or count <= 0:
                raise InvfaceError(f"{src}: not a readable video (OpenCV/FFmpeg could not decode a frame)")
            self.fps = self.fps if self.fps > 0 else 24.0
            if camera is None and src.with_suffix(".json").is_file():
                self.camera = src.with_suffix(".json")
        elif src.is_file():
            if src.suffix.lower() not in IMAGE_SUFFIXES:
                raise InvfaceError(f"{src}: not a plate image ({', '.join(IMAGE_SUFFIXES)}) or a video "
                                   f"({', '.join(VIDEO_SUFFIXES)})")
            self.kind, self.paths, self.fps, count = "image", [src], 0.0, 1
        else:
            raise InvfaceError(f"{src}: plate not found")
        self.count = count
        self.indices = parse_frames(frames, count)
        self.names = [self._name(i) for i in self.indices]

    def __len__(self):
        return len(self.indices)

    def _name(self, i):
        if self.kind == "video":
            return f"{self.source.stem}.frame_{i:06d}"
        return self.paths[i].stem

    def time(self, i):
        """Time (s) of source frame i (its index / fps; the position in the selection for
        images)."""
        return i / self.fps if self.fps else float(self.indices.index(i))

    def describe(self):
        what = {"video": f"video, {self.count} frames at {self.fps:g} fps", "folder": f"folder of {self.count} images",
                "image": "one image"}[self.kind]
        return f"{self.source} ({what}): {len(self)} frames selected"

    def frames(self, start=0, stop=None):
        """Yield the Frames at positions [start, stop) of the selection, in order."""
        sel = self.indices[start:stop]
        if not sel:
            return
        if self.kind != "video":
            from ..render.plates import load_plate
            for i in sel:
                plate = load_plate(self.paths[i], camera=self.camera)
                yield Frame(i, self._name(i), self.time(i), plate, digest(plate))
            return
        yield from self._video_frames(sel)

    def _video_frames(self, sel):
        import cv2
        from ..render.camera import Camera
        from ..io.images import srgb_to_linear
        from ..render.plates import Plate, undistort
        cap = cv2.VideoCapture(str(self.source))
        cam = None if self.camera is None or isinstance(self.camera, Camera) else Camera.load(self.camera)
        cam = cam if cam is not None else self.camera
        try:
            pos = sel[0]
            if pos and not (cap.set(cv2.CAP_PROP_POS_FRAMES, pos) and int(cap.get(cv2.CAP_PROP_POS_FRAMES)) == pos):
                cap.release()                  # no exact seek in this file: decode from the start
                cap, pos = cv2.VideoCapture(str(self.source)), 0
            wanted = set(sel)
            while pos <= sel[-1]:
                ok, bgr = cap.read()
                if not ok:
                    raise InvfaceError(f"{self.source}: frame {pos} could not be decoded "
                                       f"(the file says it has {self.count})")
                if pos in wanted:
                    rgb = srgb_to_linear(bgr[..., ::-1].astype(np.float32) / 255.0)
                    h, w = rgb.shape[:2]
                    c = cam if cam is not None else Camera.front_view(w, h)
                    if c.size != (w, h):
                        raise InvfaceError(f"{self.source}: frames are {w}x{h} px but its camera is "
                                           f"{c.width}x{c.height}")
                    image, c2 = undistort(rgb, c)
                    path = self.source.with_name(self._name(pos) + ".png")      # for sidecar lookups
                    plate = Plate(image=image, camera=c2, path=str(path))
                    yield Frame(pos, self._name(pos), self.time(pos), plate, digest(plate))
                pos += 1
        finally:
            cap.release()


def open_clip(source, frames=None, camera=None):
    """A Clip of a video file, a folder of images or one image, with the frames selected by
    ``frames`` ("START:STOP[:STEP]", see ``parse_frames``)."""
    return source if isinstance(source, Clip) else Clip(source, frames, camera)


def digest(plate):
    """SHA-1 (hex, 16 chars) of a plate's pixels (float32) and camera: a frame's identity."""
    h = hashlib.sha1(np.ascontiguousarray(plate.image, np.float32).tobytes())
    h.update(json.dumps(plate.camera.to_dict(), sort_keys=True).encode())
    return h.hexdigest()[:16]
