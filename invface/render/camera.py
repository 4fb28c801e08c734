"""Pinhole cameras in OpenCV convention, their JSON files, and their Mitsuba sensors.

A ``Camera`` holds intrinsics K (3,3) in pixels, OpenCV distortion coefficients
(k1, k2, p1, p2[, k3[, ...]]), extrinsics R (3,3), t (3,) m mapping model/world points to the
camera frame (x_cam = R X + t; x right, y down, z forward) and the image size in pixels.
Pixel coordinates follow OpenCV: the centre of the top-left pixel is (0, 0).

JSON camera file::

    {"width": 720, "height": 540,
     "K": [[fx, 0, cx], [0, fy, cy], [0, 0, 1]],
     "dist": [k1, k2, p1, p2, k3],                 # optional, default no distortion
     "R": [[...], [...], [...]] or "rvec": [...],  # optional extrinsics (Rodrigues rvec ok)
     "t": [tx, ty, tz]}                            # metres; default: the front view

Without extrinsics the camera is the default front view: on the model's +Z axis looking at
the face (``front_view``).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import CameraError

FRONT_EYE = (0.0, 0.03, 0.62)       # m, the default front view (matches the previews)
FRONT_TARGET = (0.0, 0.03, 0.0)


def _look_at(eye, target, up=(0.0, 1.0, 0.0)):
    """OpenCV extrinsics (R, t) of a camera at ``eye`` looking at ``target``."""
    eye, target, up = (np.asarray(a, float) for a in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    return R, -R @ eye


@dataclass
class Camera:
    """Pinhole camera: K (3,3) px, dist (n,), R (3,3), t (3,) m, width/height px."""

    K: np.ndarray
    width: int
    height: int
    dist: np.ndarray = field(default_factory=lambda: np.zeros(5))
    R: np.ndarray = field(default_factory=lambda: _look_at(FRONT_EYE, FRONT_TARGET)[0])
    t: np.ndarray = field(default_factory=lambda: _look_at(FRONT_EYE, FRONT_TARGET)[1])

    # ------------------------------------------------------------------ construction
    @classmethod
    def front_view(cls, width=720, height=540, fov_deg=30.0, eye=FRONT_EYE, target=FRONT_TARGET):
        """The default camera: horizontal field of view ``fov_deg``, centred principal point."""
        f = 0.5 * width / np.tan(np.radians(fov_deg) / 2)
        K = np.array([[f, 0, (width - 1) / 2], [0, f, (height - 1) / 2], [0, 0, 1.0]])
        R, t = _look_at(eye, target)
        return cls(K=K, width=int(width), height=int(height), R=R, t=t)

    @classmethod
    def load(cls, path):
        """Read a JSON camera file; a missing or malformed field raises CameraError naming it."""
        from ..io.jsonfile import read_object
        return cls.from_dict(read_object(path, CameraError, "camera file"), source=str(path))

    @classmethod
    def from_dict(cls, data, source="camera"):
        """A Camera from its JSON fields (``to_dict``); a missing or malformed field raises
        CameraError naming ``source`` and the field."""
        from ..io.schema import Fields
        f = Fields(data, source, CameraError, "fields: width, height, K, optional dist, R or rvec, t")
        w, h = (f.number(k, integer=True, low=1) for k in ("width", "height"))
        K = f.array("K", (3, 3))
        if K[0, 0] <= 0 or K[1, 1] <= 0 or abs(K[2, 2] - 1) > 1e-9:
            f.fail("K", "must have positive focal lengths and K[2][2] = 1")
        dist = f.array("dist", default=np.zeros(5)).ravel()
        if dist.size not in (4, 5, 8, 12, 14):
            f.fail("dist", f"needs 4, 5, 8, 12 or 14 OpenCV coefficients, got {dist.size}")
        cam = cls.front_view(w, h)
        cam.K, cam.dist = K, dist
        if "R" in f or "rvec" in f or "t" in f:
            if "R" in f:
                R = f.array("R", (3, 3))
            else:
                import cv2
                R = cv2.Rodrigues(f.array("rvec", (3,)).reshape(3, 1))[0]
            if abs(np.linalg.det(R) - 1) > 1e-4 or np.abs(R @ R.T - np.eye(3)).max() > 1e-4:
                f.fail("R", "is not a rotation matrix")
            cam.R, cam.t = R, f.array("t", (3,))
        return cam

    def to_dict(self):
        return {"width": int(self.width), "height": int(self.height), "K": self.K.tolist(),
                "dist": np.asarray(self.dist).tolist(), "R": self.R.tolist(), "t": self.t.tolist()}

    def save(self, path):
        """Write the JSON camera file atomically."""
        from ..io.jsonfile import write_object
        write_object(path, self.to_dict())

    # ------------------------------------------------------------------ geometry
    @property
    def size(self):
        return int(self.width), int(self.height)

    @property
    def focal(self):
        """The focal length (px) the renderer uses; square pixels are required."""
        fx, fy = self.K[0, 0], self.K[1, 1]
        if abs(fx - fy) > 0.01 * max(fx, fy):
            raise CameraError(f"focal lengths fx={fx:.1f}, fy={fy:.1f} px differ by more than 1%: "
                              "non-square pixels are not supported; resample the plate")
        return 0.5 * (fx + fy)

    @property
    def undistorted(self):
        """The same camera without lens distortion (the camera of an undistorted plate)."""
        return Camera(K=self.K.copy(), width=self.width, height=self.height,
                      dist=np.zeros(5), R=self.R.copy(), t=self.t.copy())

    def pyramid_level(self, level):
        """The undistorted camera of level ``level`` of the image's Gaussian pyramid (OpenCV's
        ``pyrDown`` applied ``level`` times): pixel j of each level lies on pixel 2j of the one
        above, so the focal length and principal point halve and the size is ceil(size / 2)."""
        K, w, h = self.K.copy(), int(self.width), int(self.height)
        for _ in range(int(level)):
            K[:2] *= 0.5
            w, h = (w + 1) // 2, (h + 1) // 2
        return Camera(K=K, width=w, height=h, dist=np.zeros(5), R=self.R.copy(), t=self.t.copy())

    @property
    def center(self):
        """Camera centre in world coordinates (3,) m."""
        return -self.R.T @ self.t

    def project(self, points):
        """Pixel coordinates (N, 2) of world points (N, 3) m (pinhole, distortion ignored:
        plates are undistorted before fitting) and their depth (N,) m."""
        pc = np.asarray(points, float) @ self.R.T + self.t
        z = pc[:, 2]
        uv = pc @ self.K.T
        return uv[:, :2] / z[:, None], z

    def sensor_dict(self, spp=4, filter="box", sampler="independent", crop=None):
        """Mitsuba ``perspective`` sensor dict with this camera's pose, focal and centre;
        crop (x0, y0, width, height) px renders only that window of the film."""
        from .variant import mitsuba
        mi = mitsuba()
        w, h = self.size
        f = self.focal
        # Mitsuba's camera frame is OpenCV's turned half a turn about z (x left, y up)
        to_world = np.eye(4)
        to_world[:3, :3] = self.R.T @ np.diag([-1.0, -1.0, 1.0])
        to_world[:3, 3] = self.center
        cx, cy = self.K[0, 2] + 0.5, self.K[1, 2] + 0.5      # film coordinates of the centre
        return {
            "type": "perspective",
            "fov_axis": "x",
            "fov": float(np.degrees(2 * np.arctan(0.5 * w / f))),
            # Mitsuba measures the offset of the film centre from the principal point
            "principal_point_offset_x": float((0.5 * w - cx) / w),
            "principal_point_offset_y": float((0.5 * h - cy) / h),
            "near_clip": 0.01, "far_clip": 100.0,
            "to_world": mi.ScalarTransform4f(to_world.tolist()),
            "sampler": {"type": sampler, "sample_count": int(spp)},
            "film": {"type": "hdrfilm", "width": w, "height": h, "pixel_format": "rgba",
                     "rfilter": {"type": filter}, "sample_border": True,
                     **({} if crop is None else dict(zip(("crop_offset_x", "crop_offset_y", "crop_width",
                                                           "crop_height"), (int(c) for c in crop))))},
        }
