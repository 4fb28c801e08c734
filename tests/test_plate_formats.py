"""Plates as VFX delivers them: DPX/Cineon log, EXR, TIFF, PPM, BMP, WebP read through
OpenImageIO, colour spaces converted to linear Rec.709 (checked against hand-computed code
values), numbered sequences and inclusive frame ranges."""
import subprocess
import sys

import numpy as np
import pytest

oiio = pytest.importorskip("OpenImageIO")
pytest.importorskip("PyOpenColorIO")

from invface.errors import ImageError, InvfaceError  # noqa: E402
from invface.io import colorspaces  # noqa: E402
from invface.io.images import load_image, write_image  # noqa: E402
from invface.io.sequences import find_sequence, frame_numbers  # noqa: E402
from invface.pipeline.clips import open_clip, parse_frames  # noqa: E402

H, W = 6, 8


def _linear():
    """A (H, W, 3) linear test image: a ramp over 0.002-0.9, different per channel."""
    t = np.linspace(0.002, 0.9, H * W).reshape(H, W)
    return np.stack([t, t[::-1, ::-1], np.full_like(t, 0.18)], -1).astype(np.float32)


def _write(path, code, typedesc, attrs=None, bits=None):
    """Write code values (H, W, C) in [0, 1] (or float) with OpenImageIO."""
    spec = oiio.ImageSpec(code.shape[1], code.shape[0], code.shape[2], typedesc)
    if bits:
        spec.attribute("oiio:BitsPerSample", bits)
    for k, v in (attrs or {}).items():
        spec.attribute(k, v)
    out = oiio.ImageOutput.create(str(path))
    assert out.open(str(path), spec), oiio.geterror()
    if typedesc == oiio.UINT8:        # integers as they are: the PNM writer mis-converts floats
        code = np.round(np.clip(code, 0, 1) * 255).astype(np.uint8)
    assert out.write_image(np.ascontiguousarray(code) if code.dtype == np.uint8 else np.ascontiguousarray(code, np.float32))
    out.close()


def test_hand_computed_code_values():
    # ACEScct: (log2(0.18) + 9.72) / 17.52 = 0.41359, 10-bit code 423
    code = colorspaces.from_linear(np.full((1, 3), 0.18), "ACEScct")
    assert code[0, 0] == pytest.approx(0.41359, abs=1e-4)
    assert round(float(code[0, 0]) * 1023) == 423
    assert colorspaces.to_linear(np.full((1, 3), 423 / 1023), "ACEScct")[0, 0] == pytest.approx(0.18, abs=1e-3)
    # Cineon (Kodak): 685 + 300 log10(0.18 (1 - o) + o), o = 10^(-590 * 0.002 / 0.6): code 467.8
    o = 10 ** (-590 * 0.002 / 0.6)
    assert colorspaces.from_linear(np.full((1, 3), 0.18), "Cineon")[0, 0] * 1023 == pytest.approx(
        685 + 300 * np.log10(0.18 * (1 - o) + o), abs=1e-3)
    assert colorspaces.to_linear(np.array([[685, 95, 1023]]) / 1023, "cineon")[0].tolist() == pytest.approx(
        [1.0, 0.0, (10 ** (338 * 0.002 / 0.6) - o) / (1 - o)], abs=1e-5)
    # sRGB: 8-bit code 128 is ((128/255 + 0.055) / 1.055)^2.4 = 0.21586
    assert colorspaces.to_linear(np.full((1, 3), 128 / 255), "sRGB")[0, 0] == pytest.approx(0.21586, abs=1e-5)
    # OCIO aliases and case resolve to canonical names; an unknown name gets close matches
    assert colorspaces.resolve("acescct") == "ACEScct" and colorspaces.resolve("SRGB") == "sRGB"
    with pytest.raises(ImageError, match="ARRI LogC3"):
        colorspaces.resolve("logc")


@pytest.mark.parametrize("ext,typedesc,bits,space,attrs,given", [
    (".dpx", oiio.UINT16, 10, "Cineon", {"dpx:Transfer": "Printing density"}, None),
    (".dpx", oiio.UINT16, 10, "Cineon", {}, None),                          # no transfer: Cineon log
    (".dpx", oiio.UINT16, 10, "ACEScct", {"dpx:Transfer": "Printing density"}, "ACEScct"),
    (".dpx", oiio.UINT16, 10, "linear", {"dpx:Transfer": "Linear"}, None),
    (".exr", oiio.HALF, None, "linear", {}, None),
    (".tif", oiio.UINT8, None, "sRGB", {}, None),
    (".tif", oiio.UINT16, None, "sRGB", {}, None),
    (".tif", oiio.FLOAT, None, "linear", {}, None),
    (".tif", oiio.UINT16, None, "ARRI LogC3 (EI800)", {}, "ARRI LogC3 (EI800)"),
    (".png", oiio.UINT16, None, "sRGB", {}, None),
    (".ppm", oiio.UINT8, None, "sRGB", {}, None),
    (".bmp", oiio.UINT8, None, "sRGB", {}, None),
    (".webp", oiio.UINT8, None, "sRGB", {"compression": "lossless"}, None),
])
def test_each_format_reads_back_its_linear_values(tmp_path, ext, typedesc, bits, space, attrs, given):
    truth = _linear()
    code = colorspaces.from_linear(truth, space)
    path = tmp_path / f"plate{ext}"
    _write(path, code, typedesc, attrs, bits)
    im = load_image(path, given)
    assert im.colorspace == space
    assert im.rgb.shape == (H, W, 3) and im.rgb.dtype == np.float32
    levels = {oiio.UINT8: 255, oiio.UINT16: 2 ** (bits or 16) - 1}.get(typedesc)
    if levels:   # a code value of quantisation (OpenImageIO's DPX writer truncates 16 to 10 bits),
        step = 1.0 / levels      # through the curve's slope; a wide gamut's matrix mixes the channels' errors
        slope = np.abs(colorspaces.to_linear(code + step, space) - colorspaces.to_linear(code, space))
        bound = slope if space in colorspaces.OWN else 2.0 * slope.max(-1, keepdims=True)
        assert np.all(np.abs(im.rgb - truth) <= bound + 1e-6)
    else:
        assert np.allclose(im.rgb, truth, rtol=1e-3, atol=1e-4)        # half floats


def test_grey_portable_map_and_alpha(tmp_path):
    grey = np.linspace(0, 1, H * W).reshape(H, W, 1)
    _write(tmp_path / "g.pgm", grey, oiio.UINT8)
    im = load_image(tmp_path / "g.pgm")
    assert np.allclose(im.rgb[..., 0], im.rgb[..., 2]) and im.alpha is None
    rgba = np.concatenate([np.full((H, W, 3), 0.5), np.linspace(0, 1, H * W).reshape(H, W, 1)], -1)
    _write(tmp_path / "a.tif", rgba, oiio.UINT16)
    im = load_image(tmp_path / "a.tif")
    assert im.alpha is not None and im.alpha.max() == pytest.approx(1.0)


def test_exif_orientation_turns_the_photo_upright(tmp_path):
    img = np.zeros((4, 6, 3), np.float32)
    img[0, 0] = 1.0                                   # stored top-left is white
    _write(tmp_path / "o.tif", img, oiio.UINT8, {"Orientation": 6})   # 6: shown turned 90 deg clockwise
    im = load_image(tmp_path / "o.tif")
    assert im.rgb.shape == (6, 4, 3)
    assert im.rgb[0, -1].min() > 0.9 and im.rgb.sum() == pytest.approx(im.rgb[0, -1].sum())


def test_cmyk_jpeg_is_read_as_rgb(tmp_path):
    Image = pytest.importorskip("PIL.Image")
    Image.new("RGB", (16, 8), (200, 30, 30)).convert("CMYK").save(tmp_path / "cmyk.jpg", quality=100)
    im = load_image(tmp_path / "cmyk.jpg")
    r, g, b = colorspaces.from_linear(im.rgb, "sRGB")[4, 8] * 255
    assert r > 150 and g < 80 and b < 80 and im.rgb.shape == (8, 16, 3)


def _sequence(folder, numbers, name="shot.{:04d}.exr"):
    for n in numbers:
        spec_img = np.full((H, W, 3), n / 4000.0, np.float32)
        _write(folder / name.format(n), spec_img, oiio.FLOAT,
               {"FramesPerSecond": 25.0} if name.endswith(".exr") else {})


def test_numbered_sequences_and_inclusive_ranges(tmp_path):
    _sequence(tmp_path, [1001, 1002, 1003])
    (tmp_path / "notes.txt").write_text("not a frame")
    assert [n for n, _ in find_sequence(tmp_path / "shot.####.exr")] == [1001, 1002, 1003]
    assert [n for n, _ in find_sequence(tmp_path / "shot.%04d.exr")] == [1001, 1002, 1003]
    assert [n for n, _ in find_sequence(tmp_path / "shot.%d.exr")] == [1001, 1002, 1003]
    clip = open_clip(tmp_path / "shot.####.exr", "1002-1003")
    assert clip.kind == "sequence" and clip.names == ["shot.1002", "shot.1003"]
    frames = list(clip.frames())
    assert [f.plate.image[0, 0, 0] for f in frames] == pytest.approx([1002 / 4000, 1003 / 4000])
    assert frames[0].plate.colorspace == "linear"
    assert clip.fps == pytest.approx(25.0) and frames[1].time - frames[0].time == pytest.approx(1 / 25)
    assert open_clip(tmp_path / "shot.####.exr", "1001-1003x2").names == ["shot.1001", "shot.1003"]
    assert open_clip(tmp_path / "shot.####.exr", "0:2").names == ["shot.1001", "shot.1002"]   # positions
    assert open_clip(tmp_path, "1003-1003").names == ["shot.1003"]          # a numbered folder
    with pytest.raises(InvfaceError, match="no frame numbered in 1005-1009.*1001-1003"):
        open_clip(tmp_path / "shot.####.exr", "1005-1009")
    with pytest.raises(InvfaceError, match="FIRST-LAST"):
        open_clip(tmp_path / "shot.####.exr", "1001")
    with pytest.raises(InvfaceError, match="no file .* matches"):
        open_clip(tmp_path / "take.####.exr")


def test_frame_numbers_and_parse_rules():
    assert frame_numbers(["a/shot_0007.png", "a/shot_0009.png"]) == [7, 9]
    assert frame_numbers(["a/left.png", "a/right.png"]) is None
    assert frame_numbers(["a/x1.png", "a/y2.png"]) is None
    assert parse_frames("3-5", 10) == [3, 4, 5]
    assert parse_frames("0:10:4", 10) == [0, 4, 8]
    assert parse_frames("-2:", 10) == [8, 9]
    with pytest.raises(InvfaceError, match="FIRST <= LAST"):
        parse_frames("5-3", 10)


def test_cli_colorspace_errors_are_one_line(tmp_path):
    _write(tmp_path / "p.dpx", np.full((H, W, 3), 0.4), oiio.UINT16, {}, 10)
    run = subprocess.run([sys.executable, "-m", "invface.cli", "fit-plate", str(tmp_path / "p.dpx"),
                          "--colorspace", "slog", "-o", str(tmp_path / "fit")], capture_output=True, text=True)
    assert run.returncode == 2 and "Traceback" not in run.stderr
    assert "argument --colorspace: 'slog': unknown colour space" in run.stderr and "S-Log3" in run.stderr
    assert run.stderr.strip().splitlines()[-1].startswith("invface fit-plate: error: argument --colorspace")


def test_without_openimageio_opencv_and_openexr_read_what_they_can(tmp_path, monkeypatch):
    """The fallback readers (OpenImageIO not importable): PNG through OpenCV and EXR through
    OpenEXR give the same linear pixels; DPX is refused with the package to install."""
    truth = _linear()
    write_image(tmp_path / "p.png", truth, bits=16)
    write_image(tmp_path / "p.exr", truth)
    _write(tmp_path / "p.dpx", colorspaces.from_linear(truth, "Cineon"), oiio.UINT16, {}, 10)
    with_oiio = {ext: load_image(tmp_path / f"p{ext}").rgb for ext in (".png", ".exr")}
    monkeypatch.setitem(sys.modules, "OpenImageIO", None)            # import OpenImageIO now fails
    for ext, rgb in with_oiio.items():
        np.testing.assert_allclose(load_image(tmp_path / f"p{ext}").rgb, rgb, atol=1e-6)
    with pytest.raises(ImageError, match="p.dpx: reading '.dpx' files needs OpenImageIO"):
        load_image(tmp_path / "p.dpx")
