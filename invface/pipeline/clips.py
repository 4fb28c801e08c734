"""Frame sources of a plate sequence: a video file, a numbered image sequence, a folder of
images or one image.

    clip = open_clip("take3.mp4", frames="0:72:2")
    clip = open_clip("plates/shot.####.dpx", frames="1001-1048", colorspace="ACEScct")
    for frame in clip.frames():              # in order, decoded once
        frame.index, frame.name, frame.time, frame.plate, frame.digest

Frames are selected by position (``START:STOP[:STEP]``, Python's slice, the end left out) or
by the source's own frame numbers (``FIRST-LAST[xSTEP]``, both ends in, as VFX ranges are):
a numbered sequence's numbers (``io.sequences``), a video's frame indices from 0, or the
numbers that end the names of a folder's files. A sequence ``shot.####.dpx`` takes its camera
from ``shot.json`` beside it when there is one.

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
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import InvfaceError
from ..io import colorspaces, sequences
from ..io.images import READ_EXTS

VIDEO_SUFFIXES = (".mp4", ".mov", ".avi", ".mkv", ".m4v", ".webm")
IMAGE_SUFFIXES = tuple(sorted(READ_EXTS))
_RANGE = re.compile(r"^\s*(\d+)\s*-\s*(\d+)\s*(?:x\s*(\d+))?\s*$")


def parse_frames(spec, count, numbers=None):
    """Positions (0..count-1) of the frames selected by "START:STOP[:STEP]" (Python slice
    rules over positions; either end may be empty, negative counts from the end), a single
    position, or "FIRST-LAST[xSTEP]": the frames whose number (``numbers[i]``, default the
    positions) lies in [FIRST, LAST], both ends included, every STEP-th from FIRST."""
    if spec is None or spec == "":
        return list(range(count))
    numbers = list(range(count)) if numbers is None else list(numbers)
    m = _RANGE.match(str(spec))
    if m:
        first, last, step = int(m.group(1)), int(m.group(2)), int(m.group(3) or 1)
        if step < 1 or last < first:
            raise InvfaceError(f"--frames {spec}: FIRST-LAST[xSTEP] needs FIRST <= LAST and STEP >= 1")
        sel = [i for i, n in enumerate(numbers) if first <= n <= last and (n - first) % step == 0]
        if not sel:
            raise InvfaceError(f"--frames {spec}: no frame numbered in {first}-{last} (the source has frames "
                               f"{numbers[0]}-{numbers[-1]})")
        return sel
    try:
        parts = [int(s) if s.strip() else None for s in str(spec).split(":")]
    except ValueError:
        parts = []
    if not 1 <= len(parts) <= 3 or (len(parts) > 1 and parts[2:] == [0]):
        raise InvfaceError(f"--frames {spec}: give START:STOP[:STEP] positions (e.g. 0:72:2), one position, "
                           "or FIRST-LAST[xSTEP] frame numbers (e.g. 1001-1072x2)")
    if len(parts) == 1:
        i = parts[0] + count if parts[0] < 0 else parts[0]
        sel = [i] if 0 <= i < count else []
    else:
        sel = list(range(count))[slice(*parts)]
    if not sel:
        hint = f"; frame numbers {numbers[0]}-{numbers[-1]} are selected with FIRST-LAST" if numbers[:1] != [0] else ""
        raise InvfaceError(f"--frames {spec}: selects no frame of the {count} there are{hint}")
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
    """A sequence of plates: ``source`` (video, sequence pattern, folder or image path),
    ``kind`` ("video", "sequence", "folder" or "image"), the selected frame ``indices``
    (positions in the source) and their ``names``, the source's frame ``numbers``, ``fps``
    (frames per second; 0 for images without a rate in their header), the camera (None:
    each plate's own sidecar or the front view) and the ``colorspace`` its files are read in
    (None: each format's default, ``io.colorspaces.default_for``). ``frames(start, stop)``
    yields Frames of the selection's positions [start, stop)."""

    def __init__(self, source, frames=None, camera=None, colorspace=None):
        src = Path(source)
        self.source, self.camera = src, camera
        self.colorspace = None if not colorspace else colorspaces.resolve(colorspace)
        self.fps = 0.0
        if sequences.is_pattern(src) and not src.exists():
            self.kind = "sequence"
            found = sequences.find_sequence(src)
            self.numbers, self.paths = [n for n, _ in found], [p for _, p in found]
            side = src.with_name(sequences.sequence_stem(src) + ".json")
            if camera is None and side.is_file():
                self.camera = side
            self.fps = _header_fps(self.paths[0])
        elif src.is_dir():
            self.kind = "folder"
            self.paths = sorted(f for f in src.iterdir() if f.suffix.lower() in IMAGE_SUFFIXES
                                and not f.name.startswith("."))
            if not self.paths:
                raise InvfaceError(f"{src}: no plate images ({', '.join(IMAGE_SUFFIXES)}) in this folder")
            self.numbers = sequences.frame_numbers(self.paths) or list(range(len(self.paths)))
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
            self.numbers = list(range(count))
            if camera is None and src.with_suffix(".json").is_file():
                self.camera = src.with_suffix(".json")
        elif src.is_file():
            if src.suffix.lower() not in IMAGE_SUFFIXES:
                raise InvfaceError(f"{src}: not a plate image ({', '.join(IMAGE_SUFFIXES)}), a video "
                                   f"({', '.join(VIDEO_SUFFIXES)}) or a numbered sequence (shot.####.exr)")
            self.kind, self.paths, self.numbers = "image", [src], [0]
        else:
            raise InvfaceError(f"{src}: plate not found")
        self.count = len(self.numbers)
        self.indices = parse_frames(frames, self.count, self.numbers)
        self.names = [self._name(i) for i in self.indices]

    def __len__(self):
        return len(self.indices)

    def _name(self, i):
        if self.kind == "video":
            return f"{self.source.stem}.frame_{i:06d}"
        return self.paths[i].stem

    def time(self, i):
        """Time (s) of source frame i: from its frame number and the rate, or its position
        in the selection when there is no rate."""
        if not self.fps:
            return float(self.indices.index(i))
        return (self.numbers[i] - self.numbers[0]) / self.fps

    def describe(self):
        span = f"frames {self.numbers[0]}-{self.numbers[-1]}"
        what = {"video": f"video, {self.count} frames at {self.fps:g} fps",
                "sequence": f"numbered sequence, {self.count} files, {span}",
                "folder": f"folder of {self.count} images", "image": "one image"}[self.kind]
        space = f", read as {self.colorspace}" if self.colorspace else ""
        return f"{self.source} ({what}{space}): {len(self)} frames selected"

    def frames(self, start=0, stop=None):
        """Yield the Frames at positions [start, stop) of the selection, in order."""
        sel = self.indices[start:stop]
        if not sel:
            return
        if self.kind != "video":
            from ..render.plates import load_plate
            for i in sel:
                plate = load_plate(self.paths[i], camera=self.camera, colorspace=self.colorspace)
                yield Frame(i, self._name(i), self.time(i), plate, digest(plate))
            return
        yield from self._video_frames(sel)

    def _video_frames(self, sel):
        import cv2
        from ..render.camera import Camera
        from ..render.plates import Plate, undistort
        cap = cv2.VideoCapture(str(self.source))
        cam = None if self.camera is None or isinstance(self.camera, Camera) else Camera.load(self.camera)
        cam = cam if cam is not None else self.camera
        space = self.colorspace or colorspaces.SRGB
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
                    rgb = colorspaces.to_linear(bgr[..., ::-1].astype(np.float32) / 255.0, space)
                    h, w = rgb.shape[:2]
                    c = cam if cam is not None else Camera.front_view(w, h)
                    if c.size != (w, h):
                        raise InvfaceError(f"{self.source}: frames are {w}x{h} px but its camera is "
                                           f"{c.width}x{c.height}")
                    image, c2 = undistort(rgb, c)
                    path = self.source.with_name(self._name(pos) + ".png")      # for sidecar lookups
                    plate = Plate(image=image, camera=c2, path=str(path), colorspace=space)
                    yield Frame(pos, self._name(pos), self.time(pos), plate, digest(plate))
                pos += 1
        finally:
            cap.release()


def open_clip(source, frames=None, camera=None, colorspace=None):
    """A Clip of a video file, a numbered sequence, a folder of images or one image, with the
    frames selected by ``frames`` ("START:STOP[:STEP]" or "FIRST-LAST[xSTEP]", see
    ``parse_frames``), read in ``colorspace`` (None: each format's default)."""
    return source if isinstance(source, Clip) else Clip(source, frames, camera, colorspace)


def _header_fps(path):
    """Frames per second from an image's header (EXR ``FramesPerSecond``, DPX
    ``dpx:FrameRate``), or 0 when it gives none."""
    from ..io.images import header
    attrs = header(path)
    rate = attrs.get("FramesPerSecond", attrs.get("dpx:FrameRate", 0))
    try:
        rate = rate[0] / rate[1] if isinstance(rate, (tuple, list)) else float(rate)
    except (TypeError, ValueError, ZeroDivisionError):
        return 0.0
    return rate if np.isfinite(rate) and 0 < rate < 1000 else 0.0


def digest(plate):
    """SHA-1 (hex, 16 chars) of a plate's pixels (float32) and camera: a frame's identity."""
    h = hashlib.sha1(np.ascontiguousarray(plate.image, np.float32).tobytes())
    h.update(json.dumps(plate.camera.to_dict(), sort_keys=True).encode())
    return h.hexdigest()[:16]
