"""Video files out: MP4 written frame by frame to a temporary file and renamed when whole.

The frames are encoded as H.264 (libx264, yuv420p, +faststart), which every browser plays,
by the ffmpeg that ``imageio-ffmpeg`` ships; without it OpenCV writes MPEG-4 Part 2 ('mp4v'),
which players read and browsers do not.
"""
from __future__ import annotations

import contextlib
from pathlib import Path

import numpy as np

from ..errors import InvfaceError
from .atomic import atomic_path


def _h264(path, size, fps):
    """A started imageio-ffmpeg H.264 writer of frames of ``size`` (W, H), both even, or None
    when imageio-ffmpeg is not installed."""
    try:
        import imageio_ffmpeg
    except ImportError:
        return None
    gen = imageio_ffmpeg.write_frames(str(path), size, fps=fps, codec="libx264", pix_fmt_out="yuv420p",
                                      quality=None, macro_block_size=1, ffmpeg_log_level="error",
                                      output_params=["-crf", "18", "-preset", "veryfast", "-movflags", "+faststart",
                                                     "-f", "mp4"])
    gen.send(None)
    return gen


class VideoWriter:
    """Write display-encoded RGB frames (H, W, 3) uint8 to an MP4 (H.264, else OpenCV's 'mp4v'),
    atomically.

        with VideoWriter("out/overlay.mp4", fps=24) as video:
            for frame in frames:
                video.write(frame)

    The frame size is taken from the first frame (padded to even sides for H.264, by repeating
    the last row or column); every later frame must match. The file appears only when the block
    ends without an exception and at least one frame was written; an encoder that cannot open,
    or a frame of another size, raises InvfaceError naming the file. ``codec``: "h264" or
    "mp4v", the one used."""

    def __init__(self, path, fps=24.0):
        self.path = Path(path)
        self.fps = float(fps or 24.0)
        self.frames = 0
        self.codec = None
        self._writer = None
        self._h264 = None
        self._size = None
        self._stack = contextlib.ExitStack()

    def __enter__(self):
        self._tmp = self._stack.enter_context(atomic_path(self.path))
        return self

    def write(self, rgb):
        """Append one frame (H, W, 3) uint8, sRGB."""
        import cv2
        img = np.asarray(rgb, np.uint8)
        size = (img.shape[1], img.shape[0])
        if self._size is None:
            self._size = size
            even = (size[0] + size[0] % 2, size[1] + size[1] % 2)
            self._h264 = _h264(self._tmp, even, self.fps)
            if self._h264 is None:
                self._writer = cv2.VideoWriter(str(self._tmp), cv2.VideoWriter_fourcc(*"mp4v"), self.fps, size)
                if not self._writer.isOpened():
                    raise InvfaceError(f"{self.path}: OpenCV cannot write MP4 video here")
            self.codec = "mp4v" if self._h264 is None else "h264"
        elif size != self._size:
            raise InvfaceError(f"{self.path}: frame {self.frames} is {size[0]}x{size[1]} px, the video "
                               f"{self._size[0]}x{self._size[1]}")
        if self._h264 is not None:
            padded = np.pad(img, ((0, size[1] % 2), (0, size[0] % 2), (0, 0)), mode="edge")
            self._h264.send(np.ascontiguousarray(padded))
        else:
            self._writer.write(np.ascontiguousarray(img[..., ::-1]))
        self.frames += 1

    def __exit__(self, kind, error, tb):
        if self._writer is not None:
            self._writer.release()
        failed = None
        if self._h264 is not None:
            try:
                self._h264.close()           # ffmpeg finishes the file
            except Exception as e:  # noqa: BLE001 - imageio-ffmpeg raises plain errors for ffmpeg's
                failed = InvfaceError(f"{self.path}: ffmpeg could not finish the video ({e})")
        if failed is None and (self.frames == 0 or self._tmp.stat().st_size == 0):
            failed = InvfaceError(f"{self.path}: no video was written ({self.frames} frames)")
        if error is None and failed is not None:
            self._stack.__exit__(type(failed), failed, None)
            raise failed
        return self._stack.__exit__(kind, error, tb)
