"""Plates: image I/O in linear light, camera files, undistortion, checkerboard calibration."""
import numpy as np
import pytest

from invface.errors import CameraError, ImageError
from invface.render.camera import Camera
from invface.render.plates import load_plate, read_image, undistort, write_image


def _image(h=60, w=80, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(0, 1, (h, w, 3)).astype(np.float32)


def test_exr_round_trip_is_exact(tmp_path):
    img = _image() * 3.0          # linear values above 1 survive
    write_image(tmp_path / "a.exr", img)
    back, alpha = read_image(tmp_path / "a.exr")
    assert alpha is None and np.array_equal(back, img)


@pytest.mark.parametrize("ext,bits,tol", [(".png", 8, 0.5 / 255), (".png", 16, 0.5 / 65535)])
def test_png_round_trip_within_quantisation(tmp_path, ext, bits, tol):
    img = _image()
    write_image(tmp_path / f"a{ext}", img, bits=bits)
    back, _ = read_image(tmp_path / f"a{ext}")
    from invface.render.plates import linear_to_srgb
    # the error is one quantisation step in sRGB, mapped back to linear
    assert np.max(np.abs(linear_to_srgb(back) - linear_to_srgb(img))) <= tol * 1.01


def test_srgb_decoding_of_a_known_value(tmp_path):
    import cv2
    cv2.imwrite(str(tmp_path / "g.png"), np.full((4, 4, 3), 188, np.uint8))
    back, _ = read_image(tmp_path / "g.png")
    np.testing.assert_allclose(back, 0.5029, atol=2e-4)      # sRGB 188/255 -> 0.503 linear


def test_bad_images_raise_clear_errors(tmp_path):
    write_image(tmp_path / "a.png", _image())
    data = (tmp_path / "a.png").read_bytes()
    (tmp_path / "cut.png").write_bytes(data[: len(data) // 2])
    with pytest.raises(ImageError, match="cut.png.*truncated"):
        read_image(tmp_path / "cut.png")
    write_image(tmp_path / "a.jpg", _image())
    data = (tmp_path / "a.jpg").read_bytes()
    (tmp_path / "cut.jpg").write_bytes(data[: len(data) - 40])
    with pytest.raises(ImageError, match="cut.jpg"):
        read_image(tmp_path / "cut.jpg")
    (tmp_path / "junk.png").write_bytes(b"hello")
    with pytest.raises(ImageError, match="junk.png"):
        read_image(tmp_path / "junk.png")
    img = _image()
    img[3, 4, 1] = np.nan
    write_image(tmp_path / "nan.exr", img)
    with pytest.raises(ImageError, match="nan.exr: 1 pixels are not finite"):
        read_image(tmp_path / "nan.exr")
    with pytest.raises(ImageError, match="not found"):
        read_image(tmp_path / "missing.png")


def test_plate_size_must_match_its_camera(tmp_path):
    write_image(tmp_path / "p.png", _image(60, 80))
    Camera.front_view(100, 60).save(tmp_path / "p.json")      # sidecar with the wrong size
    with pytest.raises(CameraError, match="p.png: plate is 80x60 px but its camera is 100x60"):
        load_plate(tmp_path / "p.png")
    Camera.front_view(80, 60).save(tmp_path / "p.json")
    plate = load_plate(tmp_path / "p.png")
    assert plate.image.shape == (60, 80, 3) and plate.camera.size == (80, 60)


def test_undistort_restores_straight_lines():
    import cv2
    w, h = 320, 240
    cam = Camera.front_view(w, h, fov_deg=60)
    cam.dist = np.array([-0.25, 0.08, 0.0, 0.0, 0.0])
    # vertical straight lines, imaged through the distorting lens
    lines_u = np.linspace(20, w - 20, 7)
    ideal = np.zeros((h, w), np.float32)
    for u in lines_u:
        ideal[:, int(round(u))] = 1
    # distorted image: sample the ideal image at the undistorted location of each pixel
    uu, vv = np.meshgrid(np.arange(w, dtype=np.float32), np.arange(h, dtype=np.float32))
    pts = cv2.undistortPoints(np.stack([uu, vv], -1).reshape(-1, 1, 2), cam.K, cam.dist, P=cam.K)
    mx, my = pts.reshape(h, w, 2)[..., 0], pts.reshape(h, w, 2)[..., 1]
    distorted = cv2.remap(ideal, mx, my, cv2.INTER_LINEAR)
    fixed, cam2 = undistort(np.repeat(distorted[..., None], 3, -1), cam)
    assert not np.any(cam2.dist)
    # each vertical line is straight again: its column of maximum response is constant
    for u in lines_u[1:-1]:
        band = fixed[30:h - 30, int(u) - 6:int(u) + 7, 0]
        cols = band.argmax(1) + int(u) - 6
        assert np.ptp(cols) <= 1
        band_d = distorted[30:h - 30, int(u) - 12:int(u) + 13]
        assert np.ptp(band_d.argmax(1)) >= 2 or abs(u - w / 2) < 30   # it was bent before


def test_checkerboard_calibration_recovers_intrinsics(tmp_path):
    import cv2
    from invface.render.checkerboard import board_points, calibrate
    w, h = 640, 480
    K = np.array([[600.0, 0, 322.0], [0, 600.0, 236.0], [0, 0, 1]])
    inner, sq = (7, 5), 0.03
    # a printed board image (8 px per mm), warped into each view by its homography
    ppm = 2000
    board = np.ones((int(6 * sq * ppm) + 1, int(8 * sq * ppm) + 1), np.float32)
    for i in range(8):
        for j in range(6):
            if (i + j) % 2 == 0:
                board[int(j * sq * ppm):int((j + 1) * sq * ppm), int(i * sq * ppm):int((i + 1) * sq * ppm)] = 0
    paths = []
    rng = np.random.default_rng(0)
    for k in range(6):
        rvec = rng.normal(0, 0.25, 3)
        R = cv2.Rodrigues(rvec)[0]
        t = np.array([-0.1, -0.07, 0.5]) + rng.normal(0, 0.03, 3)
        # board pixel (x, y) -> board plane point (x/ppm - sq, y/ppm - sq, 0)
        A = np.array([[1 / ppm, 0, -sq], [0, 1 / ppm, -sq], [0, 0, 1]])
        H = K @ np.column_stack([R[:, 0], R[:, 1], t]) @ A
        img = cv2.warpPerspective(board, H, (w, h), flags=cv2.INTER_AREA, borderValue=0.6)
        p = tmp_path / f"v{k}.png"
        write_image(p, np.repeat(img[..., None], 3, -1))
        paths.append(p)
    assert board_points(inner, sq).shape == (35, 3)
    cam, rms, used = calibrate(paths, inner=inner, square=sq, distortion=False)
    assert len(used) >= 5 and rms < 0.5
    np.testing.assert_allclose(cam.K, K, atol=3.0)
    with pytest.raises(CameraError, match="at least 3 views"):
        calibrate(paths[:2], inner=inner, square=sq)


def test_a_large_plate_is_fitted_at_a_working_size(tmp_path, small_model):
    """``find_curves`` brings a plate longer than WORKING_SIZE to it: a sequence's frame (no
    crop) is only reduced, a single plate is cropped to its face first; the camera follows
    (every pixel keeps its ray), and a curves file in the file's pixels lands on the crop."""
    import json

    from invface.pipeline.plates import WORKING_SIZE, find_curves
    from invface.render.plates import Plate
    W, H = 3000, 2000
    cam = Camera.front_view(W, H)
    X = np.random.default_rng(1).normal([0, 0, 0.05], 0.03, (200, 3))
    uv = cam.project(X)[0]
    names = ["jaw_line", "nose_bridge"]
    curves = {names[0]: uv[:100], names[1]: uv[100:]}
    for crop in (False, True):
        plate = Plate(image=np.zeros((H, W, 3), np.float32), camera=cam, path="")
        found, _ = find_curves(small_model, plate, dict(curves), crop=crop)
        c = plate.crop
        assert c["size"] == [W, H] and max(plate.camera.size) <= WORKING_SIZE
        assert plate.image.shape[:2] == plate.camera.size[::-1]
        if not crop:
            assert c["origin"] == [0, 0] and plate.camera.size == (1024, 683)
        else:
            assert 0 < c["origin"][0] and max(plate.camera.size) < W / 2       # around the points only
        np.testing.assert_allclose(plate.camera.project(X)[0], np.concatenate([found[n] for n in names]), atol=1e-9)
    # a curves file (in the file's pixels) read again on the cropped plate lands on the crop
    path = tmp_path / "c.curves.json"
    path.write_text(json.dumps({"image_size": [W, H], "curves": {n: v.tolist() for n, v in curves.items()}}))
    again, _ = find_curves(small_model, plate, path)
    for n in names:
        np.testing.assert_allclose(again[n], found[n], atol=1e-9)
