"""The head's inner parts: eyeballs, teeth, tongue, mouth lining (model.parts, template.parts)."""
import numpy as np
import pytest

from invface.errors import BundleError
from invface.model.facemodel import FaceModel
from invface.render.camera import Camera
from invface.render.renderer import FaceRenderer
from invface.render.synthetic import skin_albedo, studio_light
from invface.template.shape import EYE_CENTER, EYE_RADIUS, skin_field

OPEN = {"jaw": [0.25, 0, 0, 0, 0, 0]}


def test_the_template_has_eyes_teeth_tongue_and_lining_inside_its_skin(small_model):
    parts = small_model.parts
    assert parts.names == ["eye_L", "conjunctiva_L", "eye_R", "conjunctiva_R", "upper_teeth", "lower_teeth", "tongue", "mouth_lining"]
    parts.validate()
    # nothing pokes through the skin at rest
    assert skin_field(parts.vertices.copy()).max() < 0
    eye = parts.vertices[parts.part("eye_L")]
    assert np.allclose(np.linalg.norm(eye - EYE_CENTER, axis=1), EYE_RADIUS)
    # the pupil is dark and faces forward; the sclera is light
    alb = parts.albedo[parts.part("eye_L")]
    front = eye[:, 2] > EYE_CENTER[2] + 0.99 * EYE_RADIUS
    assert alb[front].max() < 0.05 and alb.max() > 0.6
    # left-right symmetric teeth, the upper incisors ahead of the lower ones (overjet)
    up, lo = parts.vertices[parts.part("upper_teeth")], parts.vertices[parts.part("lower_teeth")]
    assert np.allclose(np.sort(up[:, 0]), np.sort(-up[:, 0]), atol=1e-9)
    assert up[:, 2].max() > lo[:, 2].max() + 0.002


def test_the_jaw_carries_the_lower_teeth_and_tongue_rigidly_and_leaves_the_rest(small_model):
    m = small_model
    rest, opened = m.parts.vertices, m.parts_positions(OPEN)
    for name in ("eye_L", "upper_teeth"):
        assert np.array_equal(opened[m.parts.part(name)], rest[m.parts.part(name)])
    for name in ("lower_teeth", "tongue"):
        a, b = rest[m.parts.part(name)], opened[m.parts.part(name)]
        assert np.abs(b - a).max() > 0.01                                   # it opened
        d0 = np.linalg.norm(a[:, None] - a[None, ::7], axis=-1)
        d1 = np.linalg.norm(b[:, None] - b[None, ::7], axis=-1)
        assert np.abs(d1 - d0).max() < 1e-9                                 # rigidly
    # the lining's floor follows the jaw and its roof stays
    lining = m.parts.part("mouth_lining")
    moved = np.linalg.norm(opened[lining] - rest[lining], axis=1)
    y = rest[lining, 1]
    assert moved[y > np.percentile(y, 90)].max() < 1e-3 < moved[y < np.percentile(y, 10)].min()
    # a parameter vector gives the same as the controls
    assert np.array_equal(m.parts_positions(m.parameters(OPEN)), opened)


def test_parts_survive_the_bundle_and_a_bad_parts_field_is_named(small_model, tmp_path):
    path = tmp_path / "m.npz"
    small_model.save(path)
    back = FaceModel.load(path)
    assert back.parts.names == small_model.parts.names
    assert np.array_equal(back.parts.vertices, small_model.parts.vertices)
    assert np.array_equal(back.parts.triangles, small_model.parts.triangles)
    with np.load(path) as z:
        data = {k: z[k] for k in z.files}
    data["parts_albedo"] = data["parts_albedo"] * 3
    bad = tmp_path / "bad.npz"
    np.savez(bad, **data)
    with pytest.raises(BundleError, match=r"bad.npz: field 'parts_vertices' albedo is not \(P,3\) in \[0, 1\]"):
        FaceModel.load(bad)


def _front(model, w, parts, coverage=False):
    cam = Camera.front_view(160, 120, fov_deg=12, eye=(0.0, -0.035, 0.5), target=(0.0, -0.035, 0.1))
    r = FaceRenderer(model.triangles, cam, spp=4, parts=model.parts if parts else None)
    x = model.surface(w)
    if coverage:
        return r.coverage(x, parts_x=model.parts_positions(w))[0]
    return r.image(x, studio_light(), skin_albedo(model), parts_x=model.parts_positions(w))


def test_an_open_mouth_shows_teeth_and_a_dark_inside_not_the_background(small_model):
    m = small_model
    without, with_parts = _front(m, OPEN, False), _front(m, OPEN, True)
    hole = (without[..., 3] < 0.01) & (with_parts[..., 3] > 0.99)
    assert hole.sum() > 150                                      # the open mouth, filled
    lum = with_parts[..., :3].mean(-1)
    skin = lum[without[..., 3] > 0.99].mean()
    inside = lum[hole]
    assert (inside < 0.5 * skin).mean() > 0.2                    # the dark lining and tongue
    assert (inside > skin).sum() > 10                            # the lower teeth
    # a closed mouth hides them; the open mouth's pixels stay out of Eq. 14's data term
    closed = _front(m, None, True)[..., 3] - _front(m, None, False)[..., 3]
    assert (closed > 0.5).sum() < 0.1 * hole.sum()
    covered = np.zeros(hole.size, bool)
    covered[_front(m, OPEN, True, coverage=True)] = True
    assert not covered[hole.ravel()].any()
    assert np.array_equal(np.flatnonzero(covered), _front(m, OPEN, False, coverage=True))
