import json
import zipfile

import numpy as np
import pytest

import invface
from invface.errors import BundleError, InvfaceError


def test_round_trip_is_exact(small_model, tmp_path):
    p = tmp_path / "head.npz"
    small_model.save(p)
    m = invface.FaceModel.load(p)
    for field in ("neutral", "triangles", "rest_positions", "tets", "fixed_cranium", "fixed_jaw",
                  "embed_tets", "embed_weights", "jaw_weights", "volume_jaw_weights", "jaw_pivot", "jaw_frame"):
        a, b = getattr(small_model, field), getattr(m, field)
        assert a.shape == b.shape and np.array_equal(a, b), field
    assert m.landmarks == small_model.landmarks
    assert list(m.curves) == list(small_model.curves)
    assert all(np.array_equal(m.curves[k], small_model.curves[k]) for k in m.curves)
    assert m.muscle_names == small_model.muscle_names
    for a, b in zip(m.muscles, small_model.muscles):
        assert np.array_equal(a.tets, b.tets) and np.array_equal(a.fibers, b.fibers)
        assert np.array_equal(a.centerline, b.centerline) and a.side == b.side
    for (va, fa), (vb, fb) in ((m.cranium_mesh, small_model.cranium_mesh), (m.jaw_mesh, small_model.jaw_mesh)):
        assert np.array_equal(va, vb) and np.array_equal(fa, fb)
    assert m.meta == json.loads(json.dumps(small_model.meta))


def test_a_smooth_skin_embedding_round_trips_and_is_validated(small_model, tmp_path):
    """A morphed model's smooth skin embedding is stored as its parameters (meta) and rebuilt
    on load, the same matrix; an unknown method is named on load."""
    from invface.mesh.embedding import MLS
    m = small_model.replace(meta={**small_model.meta, "skin_embedding": dict(MLS, rings=1)})
    p = tmp_path / "smooth.npz"
    m.save(p)
    back = invface.FaceModel.load(p)
    assert (back.embedding_matrix() != m.embedding_matrix()).nnz == 0
    X = m.rest_positions + 0.001 * np.sin(40 * m.rest_positions[:, [1, 2, 0]])
    assert np.abs(back.embedded_surface(X) - small_model.embedded_surface(X)).max() > 1e-6   # not the barycentric one
    assert np.abs(back.embedded_surface(m.rest_positions) - m.neutral).max() < 1e-12
    header = json.loads(str(np.load(p)["header"]))
    header["meta"]["skin_embedding"]["method"] = "radial_basis"
    bad = tmp_path / "bad.npz"
    _rewrite(p, bad, header=np.array(json.dumps(header)))
    with pytest.raises(BundleError, match="bad.npz.*'header'.*skin_embedding must be"):
        invface.FaceModel.load(bad)


def _rewrite(src, dst, **changes):
    with np.load(src, allow_pickle=False) as d:
        arrays = {k: d[k] for k in d.files}
    for k, v in changes.items():
        if v is None:
            arrays.pop(k)
        else:
            arrays[k] = v
    np.savez(dst, **arrays)


@pytest.fixture(scope="module")
def saved(small_model, tmp_path_factory):
    p = tmp_path_factory.mktemp("bundle") / "head.npz"
    small_model.save(p)
    return p


def test_truncated_file_raises(saved, tmp_path):
    data = saved.read_bytes()
    bad = tmp_path / "truncated.npz"
    bad.write_bytes(data[: len(data) // 2])
    with pytest.raises(InvfaceError, match="truncated.npz"):
        invface.FaceModel.load(bad)


def test_garbage_and_missing_file_raise(tmp_path):
    bad = tmp_path / "garbage.npz"
    bad.write_bytes(b"not a zip file at all")
    with pytest.raises(BundleError, match="garbage.npz"):
        invface.FaceModel.load(bad)
    with pytest.raises(BundleError, match="no such file"):
        invface.FaceModel.load(tmp_path / "absent.npz")


def test_corrupted_member_raises(saved, tmp_path):
    bad = tmp_path / "corrupt.npz"
    data = bytearray(saved.read_bytes())
    with zipfile.ZipFile(saved) as z:
        info = z.getinfo("tets.npy")
    mid = info.header_offset + 100 + info.compress_size // 2
    data[mid:mid + 64] = bytes(64)
    bad.write_bytes(bytes(data))
    with pytest.raises(BundleError):
        invface.FaceModel.load(bad)


@pytest.mark.parametrize("field,value,message", [
    ("tets", None, "'tets' is missing"),
    ("neutral", np.full((4, 3), np.nan), "'neutral'"),
    ("triangles", np.array([[0, 1, 10 ** 7]]), "'triangles' has indices outside"),
    ("jaw_weights", "scale", "'jaw_weights'"),
    ("embed_weights", "scale", "'embed_weights' rows must sum to 1"),
    ("muscle_fibers", "scale", "'muscle_fibers' must be unit"),
    ("tets", "flip", "inverted"),
    ("header", np.array("{not json"), "'header' is not valid JSON"),
    ("header", np.array("[1, 2]"), "'header' is not a JSON object"),
    ("header", "version 2.5", "header: field 'version' is 2.5, not a whole number"),
    ("header", "a muscle with no name", "header muscle 0: missing field 'name'"),
])
def test_bad_fields_name_the_field(saved, tmp_path, field, value, message):
    with np.load(saved, allow_pickle=False) as d:
        orig = d[field] if field in d.files else None
    if isinstance(value, str) and value == "scale":
        value = orig * 2.0
    elif isinstance(value, str) and value == "flip":
        value = orig[:, [0, 2, 1, 3]]
    elif isinstance(value, str) and field == "header":
        header = json.loads(str(orig))
        if value == "version 2.5":
            header["version"] = 2.5
        else:
            del header["muscles"][0]["name"]
        value = np.array(json.dumps(header))
    bad = tmp_path / "bad.npz"
    _rewrite(saved, bad, **{field: value})
    with pytest.raises(BundleError, match=message):
        invface.FaceModel.load(bad)


def test_save_is_atomic(small_model, tmp_path, monkeypatch):
    p = tmp_path / "head.npz"
    p.write_bytes(b"previous content")

    def boom(*a, **k):
        raise OSError("disk full")
    monkeypatch.setattr(np, "savez_compressed", boom)
    with pytest.raises(OSError):
        small_model.save(p)
    assert p.read_bytes() == b"previous content"
    assert list(tmp_path.iterdir()) == [p]
