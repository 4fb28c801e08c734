"""Video files out: MP4 written frame by frame to a temporary file and renamed when whole."""
from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

from ..errors import InvfaceError
from .atomic import atomic_path


class VideoWriter:
    """Write display-encoded RGB frames (H, W, 3) uint8 to an MP4 (OpenCV, 'mp4v'), atomically.

        with VideoWriter("out/overlay.mp4", fps=24) as video:
            for frame in frames:
                video.write(frame)

    The frame size is taken from the first frame; every later frame must match. The file
    appears only when the block ends without an exception and at least one frame was written;
    an encoder that cannot open, or a frame of another size, raises InvfaceError naming the file."""

    def __init__(self, path, fps=24.0):
        self.path = Path(path)
        self.fps = float(fps or 24.0)
        self.frames = 0
        self._writer = None
        self._size = None
        self._stack = contextlib.ExitStack()

    def __enter__(self):
        self._tmp = self._stack.enter_context(atomic_path(self.path))
        return self

    def write(self, rgb):
        """Append one frame (H, W, 3) uint8, sRGB."""
        import cv2
        img = np.ascontiguousarray(np.asarray(rgb, np.uint8)[..., ::-1])
        size = (img.shape[1], img.shape[0])
        if self._writer is None:
            self._writer = cv2.VideoWriter(str(self._tmp), cv2.VideoWriter_fourcc(*"mp4v"), self.fps, size)
            if not self._writer.isOpened():
                raise InvfaceError(f"{self.path}: OpenCV cannot write MP4 video here")
            self._size = size
        elif size != self._size:
            raise InvfaceError(f"{self.path}: frame {self.frames} is {size[0]}x{size[1]} px, the video "
                               f"{self._size[0]}x{self._size[1]}")
        self._writer.write(img)
        self.frames += 1

    def __exit__(self, kind, error, tb):
        if self._writer is not None:
            self._writer.release()
        if error is None and (self.frames == 0 or self._tmp.stat().st_size == 0):
            error = InvfaceError(f"{self.path}: no video was written ({self.frames} frames)")
            self._stack.__exit__(type(error), error, None)
            raise error
        return self._stack.__exit__(kind, error, tb)
