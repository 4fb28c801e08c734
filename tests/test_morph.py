"""The model builder (paper 001): morph the template onto new faces, robustness, import."""
import numpy as np
from matplotlib.pyplot import imread as plt_imread
from scipy.spatial.distance import pdist
import pytest
import trimesh
from scipy.spatial import cKDTree

from invface.errors import MeshError
from invface.mesh.closest import closest_points
from invface.mesh.triangles import triangle_areas, vertex_normals
from invface.morph.blendshapes import read_blendshapes, recognised
from invface.morph.build import build_model, inside_fraction, orient_target
from invface.morph.curvature import stencil_curvature
from invface.morph.landmarks import find_landmarks, template_landmarks
from invface.morph.openings import OPENINGS, inner_surfaces, opening_centres, ordered_loops, split_loop
from invface.morph.synthetic import front_part, onto_part, random_identity, random_pose, torso
from invface.morph.target import clean

# sharp features must be found within 3 mm, the softer ones (corners of slits that the
# 5 mm stencil smears, lips, chin) within 5 mm; landmarks on flat regions (top of the head,
# head extremes, neck start) slide along the surface and are only held to 15 mm
SHARP = ("nose_tip", "nose_bridge", "subnasale", "eye_inner_L", "eye_inner_R", "alar_L", "alar_R")
SOFT = ("chin", "stomion", "lip_upper", "lip_lower", "eye_outer_L", "eye_outer_R",
        "mouth_corner_L", "mouth_corner_R")


@pytest.fixture(scope="module")
def actors(small_expressive_model):
    """Two identities of the small template: (model, result, truth surface in the model frame)."""
    tpl = small_expressive_model
    out = []
    for seed in (3, 4):
        X = random_identity(tpl.neutral, seed, amplitude=0.003)
        Y, R, t = random_pose(X, seed, unit=0.001)
        model, res = build_model((Y, tpl.triangles), template=tpl, expressions="copy")
        A = model.scan_transform
        out.append((model, res, Y @ A[:3, :3].T + A[:3, 3], R))
    return out


def test_round_trip(actors, small_expressive_model):
    tpl = small_expressive_model
    tl = template_landmarks(tpl)
    tri, w, _ = closest_points(np.array(list(tl.values())), tpl.neutral, tpl.triangles)
    for model, res, truth, R in actors:
        assert res.target.unit == "mm"
        A = model.scan_transform
        assert np.allclose(np.linalg.det(A[:3, :3]), 1e-9, rtol=1e-6)        # mm -> m, no mirror
        known = dict(zip(tl, np.einsum("nk,nkj->nj", w, truth[tpl.triangles[tri]])))
        err = {k: np.linalg.norm(res.landmarks[k] - known[k]) * 1000 for k in tl}
        assert max(err[k] for k in SHARP) < 3.0, err
        assert max(err[k] for k in SOFT) < 5.0, err
        assert max(err.values()) < 15.0, err
        # skin on the target, and in correspondence with it
        d = closest_points(model.neutral, truth, tpl.triangles)[2]
        assert d.mean() < 1e-3
        corr = np.linalg.norm(model.neutral - truth, axis=1)
        assert np.mean(corr) < 0.005
        # the template has no ears: no ear boxes, nearly all the skin snapped (a cheekbone and
        # a jaw angle boxed as "ears" once left 38 % of it to the Poisson fill)
        assert res.stats["ear_boxes"] == 0 and res.stats["snapped_fraction"] > 0.9
        q = res.stats["quality"]
        assert q["inverted"] == 0 and q["min_volume_m3"] > 0
        # as many centre-line points inside the flesh as in the template (0.88 on this small
        # head: its lids over the eyeballs are one tet thick, and 3-point lines at 2/3)
        own = inside_fraction(tpl.rest_positions, tpl.tets, np.concatenate([mu.centerline for mu in tpl.muscles]))
        assert res.stats["centerlines_inside"] > own - 0.03, (res.stats["centerlines_inside"], own)
        # the new anatomy is not the template's
        assert np.abs(model.rest_positions - tpl.rest_positions).max() > 0.003
        emb = model.embedded_surface(model.rest_positions)
        assert np.abs(emb - model.neutral).max() < 2e-3
        # the eyes and teeth came along as rigid pieces, hidden behind the closed lids and lips
        eye, eye0 = (mm.parts.vertices[mm.parts.part("eye_L")][::9] for mm in (model, tpl))
        scale = pdist(eye) / pdist(eye0)
        assert np.ptp(scale) < 1e-9 and abs(scale[0] - 1) < 0.1
        assert _parts_in_front_of_the_skin(model) < 20


def test_smile_simulates_on_morphed_model(actors):
    from invface.sim.quasistatic import Simulator
    from invface.template.expressions import ACTION_UNITS, activations_for
    model = actors[0][0]
    res = Simulator(model).solve(activations_for(ACTION_UNITS["lipCornerPull_L"], model.muscles))
    assert res.converged and res.inverted == 0
    x = model.embedded_surface(res.X)
    corner = model.landmarks["mouth_corner_L"]
    assert np.linalg.norm(x[corner] - model.neutral[corner]) > 0.001
    # and the blendshape-driven simulation (tracks precomputed on the new model) runs
    xs = model.surface({"mouthSmileLeft": 1.0}, kind="simulation")
    assert np.isfinite(xs).all()


def test_smooth_skin_embedding_and_its_derivatives(actors):
    """A morphed model's skin is embedded by moving least squares: exact at rest, and the
    simulation's surface derivatives go through the same weights (adjoint vs finite differences)."""
    model = actors[0][0]
    assert model.meta["skin_embedding"]["method"] == "moving_least_squares"
    W = model.embedding_matrix()
    assert W.nnz > 10 * W.shape[0]                               # not the 4 barycentric weights
    assert np.abs(W @ model.rest_positions - model.neutral).max() < 1e-12
    sim = model.surface_model("simulation")
    p = model.parameters({"mouthSmileLeft": 0.6, "jawOpen": 0.3})
    sim.solve(p, warm=None, rtol=1e-10)
    gx = np.random.default_rng(2).standard_normal(model.neutral.shape)
    g = sim.surface_vjp(p, gx)
    i, h = model.blendshape_names.index("mouthSmileLeft"), 1e-4
    e = np.zeros_like(p)
    e[i] = h
    x = [sim.surface_of(sim.solve(p + s * e, warm=None, rtol=1e-10)) for s in (1, -1)]
    fd = np.sum(gx * (x[0] - x[1])) / (2 * h)
    assert abs(g[i] - fd) <= 1e-4 * abs(fd), (g[i], fd)


def test_partial_scan_is_completed_from_the_template(small_expressive_model):
    """A front-of-face scan (paper 001 sec. 8.1): the outer landmarks land on its cut edge,
    so they keep the template's and their curves are left out; the face is morphed and the
    rest of the head completed. (Before, the head was squeezed to the cut: correspondence
    10.8 mm on the scan, 23.9 mm off it; now 4.4 and 8.5 mm.)"""
    tpl = small_expressive_model
    X = random_identity(tpl.neutral, 3, amplitude=0.003)
    used, faces = front_part(X, tpl.triangles, 0.02)     # the front of the head: no back, no ears
    Y, _, _ = random_pose(X[used], 3, unit=0.001)
    model, res = build_model((Y, faces), template=tpl, expressions="copy")
    assert {"top_of_head", "head_extreme_L", "head_extreme_R"} <= set(res.stats["off_scan_landmarks"])
    # the identity in the model frame, carried there by its scanned part
    A = model.scan_transform
    truth = onto_part(X, used, Y @ A[:3, :3].T + A[:3, 3])
    err = np.linalg.norm(model.neutral - truth, axis=1) * 1000
    on = np.zeros(len(X), bool)
    on[used] = True
    assert err[on].mean() < 6.0 and err[~on].mean() < 12.0, (err[on].mean(), err[~on].mean())
    assert res.stats["quality"]["inverted"] == 0


def _kept_part(X, F, keep):
    """(ids of the kept vertices, faces on them) for the triangles ``keep`` (T,) bool."""
    ids = np.unique(F[keep])
    remap = np.full(len(X), -1)
    remap[ids] = np.arange(len(ids))
    return ids, remap[F[keep]]


def test_a_landmark_rule_that_finds_nothing_falls_back(small_expressive_model):
    """A scan cut 2 cm below the nose tip: the chin rule finds no profile below it. The chin
    falls back to the template's carried by the face similarity, with the rule's words, and
    the neck start is off the scan; nothing raises. (The mouth, cut away too, is not held
    here: its corners are registered onto the cut's edge.)"""
    tpl = small_expressive_model
    tl = template_landmarks(tpl)
    X = random_identity(tpl.neutral, 3, amplitude=0.003)
    _, faces = _kept_part(X, tpl.triangles, X[tpl.triangles].mean(1)[:, 1] > tl["nose_tip"][1] - 0.02)
    ids = np.unique(faces)
    L, off, fell = find_landmarks(X[ids], np.searchsorted(ids, faces), tpl)
    assert fell["chin"] == "the profile ends below the nose: no chin found"
    assert "neck_start" in off
    assert L["chin"][1] < tl["nose_tip"][1] - 0.05            # below the cut, where a chin is
    assert np.linalg.norm(L["nose_tip"] - tl["nose_tip"]) < 0.005


@pytest.mark.parametrize("damage", ["chin cut off", "hole at the lips"])
def test_a_damaged_scan_builds_and_simulates(small_expressive_model, damage):
    """Issue 62 item 2. A scan cut 3 mm below the lower lip (no chin): the chin found on the cut
    edge, with the template's chin more than 1 cm off the scan, is off the scan; before, the
    cut edge was taken for the chin (21 mm off) and the stomion, placed from it, was 8 mm
    off. A scan with a 8 mm wide hole down the lips (a scanner's dropout): the profile has no
    mouth, the stomion and lips fall back with a warning, and the hole, narrower than the
    carried mouth corners' span, is not taken for the parted lips. Both build, the mouth
    corners and the stomion within 5 mm, and a smile simulates."""
    from invface.sim.quasistatic import Simulator
    from invface.template.expressions import ACTION_UNITS, activations_for
    tpl = small_expressive_model
    tl = template_landmarks(tpl)
    X = random_identity(tpl.neutral, 3, amplitude=0.003)
    c = X[tpl.triangles].mean(1)
    if damage == "chin cut off":
        keep = c[:, 1] > tl["lip_lower"][1] - 0.003
    else:
        keep = ~((np.abs(c[:, 0]) < 0.004) & (c[:, 1] < tl["subnasale"][1] - 0.002)
                 & (c[:, 1] > tl["lip_lower"][1] - 0.003) & (c[:, 2] > 0))
    used, faces = _kept_part(X, tpl.triangles, keep)
    Y, _, _ = random_pose(X[used], 3, unit=0.001)
    said = []
    model, res = build_model((Y, faces), template=tpl, expressions="copy", progress=said.append)
    fell = {f["landmark"]: f["rule"] for f in res.stats["landmark_fallbacks"]}
    if damage == "chin cut off":
        assert {"chin", "neck_start"} <= set(res.stats["off_scan_landmarks"]) and not fell
        assert any(m.startswith("partial scan: chin, neck_start off the scan") for m in said), said
    else:
        assert fell == {"stomion": "no mouth found on the profile at the height of the mouth corners",
                        "lip_upper": "the stomion fell back: the lip is taken at it",
                        "lip_lower": "the stomion fell back: the lip is taken at it"}
        assert ("warning: landmark stomion: no mouth found on the profile at the height of the mouth corners; it "
                "falls back to the template's landmark carried by the face similarity, and its curves are left "
                "out") in said
    A = model.scan_transform
    truth = onto_part(X, used, Y @ A[:3, :3].T + A[:3, 3])
    tri, w, _ = closest_points(np.array([tl[k] for k in tl]), tpl.neutral, tpl.triangles)
    known = dict(zip(tl, np.einsum("nk,nkj->nj", w, truth[tpl.triangles[tri]])))
    err = {k: np.linalg.norm(res.landmarks[k] - known[k]) * 1000 for k in ("stomion", "mouth_corner_L",
                                                                           "mouth_corner_R")}
    assert max(err.values()) < 5.0, err
    assert res.stats["quality"]["inverted"] == 0
    r = Simulator(model).solve(activations_for(ACTION_UNITS["lipCornerPull_L"], model.muscles))
    assert r.converged and r.inverted == 0


def _ict_mix(seed):
    """Face ``seed`` of ICT-FaceKit's identity space (its 20 shapes at coefficients ~ N(0, 1.5^2),
    seeded as in bench/identity_3d.py): vertices (n,3) cm, faces. Skips without ICT-FaceKit."""
    from conftest import ICT
    from invface.io.meshes import read_mesh
    if not (ICT / "identities.npz").exists():
        pytest.skip("ICT-FaceKit data (../shared/data/ict-facekit) is not available")
    V, F = read_mesh(ICT / "neutral.obj")
    S = np.load(ICT / "identities.npz")["deltas"]
    return V + np.tensordot(np.random.default_rng(seed).normal(0, 1.5, len(S)), S, axes=1), F


def _ict_mix_landmarks(model, seed):
    """Face ``seed`` of ICT-FaceKit's identity space (its 20 shapes at coefficients ~ N(0, 1.5^2),
    seeded as in bench/identity_3d.py), oriented onto ``model`` and its landmarks found: (L, off,
    fell, annotated: Multi-PIE index -> ICT's annotated point in the model frame (3,) m, the
    alignment). Skips without ICT-FaceKit."""
    import json

    from conftest import ICT
    mix, F = _ict_mix(seed)
    ids = json.load(open(ICT / "landmarks.json"))["landmarks_68_multipie"]
    target, al, _, _ = orient_target(clean(mix, F, unit="cm"), model, "cm")
    L, off, fell = find_landmarks(al.apply(target.vertices), target.faces, model)

    def annotated(i):
        return al.apply(mix[ids[i]] * 0.01)
    return L, off, fell, annotated, al


@pytest.mark.parametrize("seed", [3, 13])
def test_ict_identity_mix_eye_corners(small_model, seed):
    """Faces of ICT-FaceKit's identity space (20 shapes, coefficients ~ N(0, 1.5^2), seeded as in
    bench/identity_3d.py) whose profile has no dip at the nose bridge (their foreheads slope
    on back from the nose): the bridge is the search window's edge, 20 mm above the eyes, and
    the eye priors moved with it miss the eye openings (eye corners were 20-32 mm from ICT's
    annotated ones). An opening is now also looked for where the similarity alone puts it:
    every eye corner within 3 mm."""
    L, off, fell, annotated, _ = _ict_mix_landmarks(small_model, seed)
    corners = {"eye_outer_R": 36, "eye_inner_R": 39, "eye_inner_L": 42, "eye_outer_L": 45}
    err = {k: np.linalg.norm(L[k] - annotated(i)) * 1000 for k, i in corners.items()}
    assert max(err.values()) < 3.0, err
    assert not off and not fell


def test_ict_identity_mix_as_deep_as_wide_is_not_turned_over(small_model):
    """Face 15 of ICT's identity space (bench/identity_3d.py's seeding) is as deep as it is
    wide: its two larger moments of inertia are 1 % apart, so the inertia axes in their plane
    are arbitrary, and the symmetry plane taken from them was 20 degrees off the face. Its
    profile then missed the nose and the alignment turned the face upside down (eye corners
    147 mm off). The plane is now the normal of least reflection error in the axes' planes:
    the face aligns upright and its landmarks sit on ICT's annotated ones."""
    L, _, _, annotated, al = _ict_mix_landmarks(small_model, 15)
    assert np.degrees(np.arccos(np.clip((np.trace(al.R) - 1) / 2, -1, 1))) < 10     # the mix is in the model frame
    points = {"nose_tip": 30, "eye_outer_R": 36, "eye_inner_R": 39, "eye_inner_L": 42, "eye_outer_L": 45,
              "mouth_corner_R": 48, "mouth_corner_L": 54}
    err = {k: np.linalg.norm(L[k] - annotated(i)) * 1000 for k, i in points.items()}
    assert max(err.values()) < 7.0, err


@pytest.mark.parametrize("seed", [4, 6, 9])
def test_ict_identity_mixes_whose_lips_stand_out(small_model, seed):
    """Faces of ICT's identity space (bench/identity_3d.py's seeding) whose lips stand out.
    On faces 6 and 9 the upper lip stands 1-9 mm further forward than the nose tip, and the
    nose tip, taken as the most forward point near its prior, was the lip (27-28 mm off ICT's
    annotated tip, the subnasale 19-20 mm); it is now the forward bump of the face's outline
    nearest the prior. Face 4 is 30 mm longer below the mouth than the carried template, so its
    lower lip lay nearer the carried chin than its chin did, and was taken for it (53 mm off);
    a bump that small is no longer a chin candidate."""
    L, _, fell, annotated, _ = _ict_mix_landmarks(small_model, seed)
    err = {k: np.linalg.norm(L[k] - annotated(i)) * 1000 for k, i in (("nose_tip", 30), ("subnasale", 33), ("chin", 8))}
    assert max(err.values()) < 6.5 and not fell, (err, fell)


@pytest.mark.parametrize("seed", [12, 20])
def test_ict_identity_mixes_whose_chin_underside_runs_at_45_degrees(small_model, seed):
    """Faces of ICT's identity space (bench/identity_3d.py's seeding) whose chin's underside runs
    near 45 degrees down to the neck: no maximum of the down-and-forward support stands out
    there by 1 cm. On face 20 its best was a wrinkle of the neck, 35.8 mm off ICT's annotated
    chin (face 12: 5.1 mm); the support 30 degrees below forward, where the chin stands out
    more, finds it."""
    L, _, fell, annotated, _ = _ict_mix_landmarks(small_model, seed)
    assert np.linalg.norm(L["chin"] - annotated(8)) * 1000 < 2.0 and not fell


@pytest.mark.parametrize("seed", [1, 2])
def test_ict_identity_mixes_whose_nose_turns_into_the_lip_rounded(small_model, seed):
    """Faces of ICT's identity space (bench/identity_3d.py's seeding) whose columella turns into
    the upper lip in a rounded curve: the sharpest concave corner at a 2 mm scale was the upper
    lip's deepest point, 8-9 mm below ICT's annotated subnasale. The point deepest behind the
    line from the nose tip to the upper lip is the junction."""
    L, _, fell, annotated, _ = _ict_mix_landmarks(small_model, seed)
    assert np.linalg.norm(L["subnasale"] - annotated(33)) * 1000 < 5.0 and not fell


@pytest.mark.parametrize("seed", [4, 12, 19, 20])
def test_ict_identity_mixes_with_a_wide_bald_head_keep_their_scalp(small_model, seed):
    """Faces of ICT's identity space whose bald crania stand 28-46 mm outside the template's
    carried scalp. Their ears, 16-39 mm out and rough, were taken for hair (faces 12, 19, 20),
    and face 4's cranium, smooth but beyond CROWN, for a crown: the scalp followed the
    template, 9-18 mm (median) off the scan's. A rough patch that lies wholly at the template's
    head extremes is an ear, and a smooth one beyond CROWN that rises from the skin as a
    gentle slope is a cranium: nothing is left out."""
    mix, F = _ict_mix(seed)
    assert orient_target(clean(mix, F, unit="cm"), small_model, "cm")[3] == []


def test_ict_identity_mix_whose_scalp_is_left_out_builds(default_model):
    """Face 9 of ICT's identity space (bench/identity_3d.py's seeding): its bald cranium stands
    up to 38 mm outside the template's carried scalp and is left out as a crown, so the skin
    morph fills the scalp up to a cut border. Its build stopped in the volume stage (15 flat
    tets at the temple): the template vertices past a corner of that border had all snapped
    onto the corner (4,553 coincident skin vertices), and the untangling's fixed regulariser
    left tets shrunk to slivers in place. It builds, with no skin vertices snapped together
    and no flat tet."""
    import json

    from conftest import ICT
    from invface.io.meshes import read_mesh
    from invface.mesh.tets import radius_ratio
    from invface.morph.volume import DEGENERATE
    if not (ICT / "identities.npz").exists():
        pytest.skip("ICT-FaceKit data (../shared/data/ict-facekit) is not available")
    V, F = read_mesh(ICT / "neutral.obj")
    S = np.load(ICT / "identities.npz")["deltas"]
    mix = V + np.tensordot(np.random.default_rng(9).normal(0, 1.5, len(S)), S, axes=1)
    said = []
    model, res = build_model((mix, F), template=default_model, unit="cm", expressions="none",
                             progress=said.append)
    assert any(m.startswith("hair or a crown over the scalp") for m in said), said
    assert res.stats["quality"]["inverted"] == 0
    assert radius_ratio(model.rest_positions, model.tets).min() > DEGENERATE
    together = len(cKDTree(model.neutral).query_pairs(1e-7))
    assert together <= len(cKDTree(default_model.neutral).query_pairs(1e-7)), together
    ids = json.load(open(ICT / "landmarks.json"))["landmarks_68_multipie"]
    A = model.scan_transform
    eyes = [np.linalg.norm(model.neutral[model.landmarks[k]] - (A[:3, :3] @ mix[ids[i]] + A[:3, 3])) * 1000
            for k, i in (("eye_outer_L", 45), ("eye_outer_R", 36))]
    assert max(eyes) < 6.0, eyes


def test_snap_past_a_corner_of_the_scan_leaves_the_vertex_to_the_fill():
    """A template vertex beyond a corner of a partial scan's border has the corner vertex as its
    closest point: it is off the scan, as one beyond an edge is. Before, every such vertex
    snapped onto that one corner (4,553 coincident skin vertices on an ICT face whose scalp was
    left out, and a build that stopped in its volume stage)."""
    from invface.morph.surface import snap
    g = np.linspace(-0.02, 0.02, 21)
    X, Y = np.meshgrid(g, g)
    Vt = np.column_stack([X.ravel(), Y.ravel(), np.zeros(X.size)])
    q = np.arange(21 * 21).reshape(21, 21)
    Ft = np.concatenate([np.column_stack([q[:-1, :-1].ravel(), q[:-1, 1:].ravel(), q[1:, 1:].ravel()]),
                         np.column_stack([q[:-1, :-1].ravel(), q[1:, 1:].ravel(), q[1:, :-1].ravel()])])
    inside = (np.abs(Vt[:, :2]) <= 0.01 + 1e-9).all(1)
    keep = inside[Ft].all(1)
    used = np.unique(Ft[keep])
    Vg = Vt[used] + [0.0, 0.0, 0.001]
    Fg = np.searchsorted(used, Ft[keep])
    Vs, ok, _, _ = snap(Vt, Ft, Vg, Fg)
    assert ok[inside & (np.abs(Vt[:, :2]) < 0.01 - 1e-9).all(1)].all()
    assert not ok[~inside].any()
    assert len(cKDTree(Vs[ok]).query_pairs(1e-9)) == 0


def _parts_in_front_of_the_skin(model):
    """Pixels of a front view at rest where an inner part pokes through the skin (seen where
    the skin alone would be)."""
    from invface.render.camera import Camera
    from invface.render.renderer import FaceRenderer
    cam = Camera.front_view(160, 120, fov_deg=40, eye=(0.0, 0.0, 0.5), target=(0.0, 0.0, 0.1))
    skin = FaceRenderer(model.triangles, cam, spp=4).coverage(model.neutral)[0]
    both = FaceRenderer(model.triangles, cam, spp=4, parts=model.parts).coverage(model.neutral)[0]
    return len(np.setdiff1d(skin, both))


def test_real_scan_ict_neutral(small_model, tmp_path):
    """ICT-FaceKit's neutral (cm, with neck, ears, open eyes, lips rolled into the mouth; proportions
    1-2 cm off the template's) builds a valid model with landmarks on its real features;
    its jawOpen blendshape is split into the jaw's rotation and a remainder that the muscle
    simulation follows."""
    from conftest import ICT
    from invface.io.meshes import read_mesh
    from invface.mesh.tets import radius_ratio, signed_volumes
    from invface.mesh.triangles import boundary_loops, boundary_vertices, umbrella
    if not (ICT / "neutral.obj").exists():
        pytest.skip("ICT-FaceKit data (../shared/data/ict-facekit) is not available")
    V, F = read_mesh(ICT / "neutral.obj")
    ex = np.load(ICT / "expressions.npz")
    for name in ("jawOpen", "mouthSmile_L"):
        trimesh.Trimesh(V + ex["deltas"][list(ex["names"]).index(name)], F, process=False).export(tmp_path / f"{name}.obj")
    model, res = build_model(ICT / "neutral.obj", blendshapes=tmp_path, template=small_model, expressions="none")
    jaw = np.array(model.meta["blendshape_jaw"]["jawOpen"])
    assert 0.2 < jaw[0] < 0.45 and np.abs(jaw[1:]).max() < 0.02, jaw           # 14 degrees and 3.8 mm forward (the jaw may not rise)
    p = model.parameters({"weights": {"jawOpen": 1.0}, "jaw": jaw})
    target = model.surface_model("blendshape").surface(p)                       # the imported shape
    err = np.linalg.norm(model.surface_model("simulation").surface(p) - target, axis=1)
    moved = np.linalg.norm(target - model.neutral, axis=1) > 0.001
    assert err[moved].mean() < 0.004, err[moved].mean()                         # 3.2 mm, offsets to 42
    # the skin is embedded smoothly: the simulated lip line does not tear into spikes where the
    # dense skin crosses the coarse lip tets' faces (barycentric: creases up to 12.7 mm)
    # (measured off the skin's open edges, where the umbrella is one-sided: since the scan is
    # aligned 2 cm lower than before issue 27, the template's neck edge lies on ICT's throat,
    # where jawOpen moves it 2 cm from the simulation's, a 12 mm one-sided "crease"). The fold at
    # the lower lip's corners grew from 5.3 to 7.2 mm when the lower lip's slit vertices took their
    # own lip's Poisson data (10-20 mm of jawOpen's) instead of the upper lip's
    X = model.surface_model("simulation").result_at(p).X
    crease = umbrella(model.embedded_surface(X), model.triangles) - umbrella(target, model.triangles)
    crease = crease[~boundary_vertices(model.triangles, len(model.neutral))]
    assert crease.max() < 0.008, crease.max()                                   # 7.2 mm
    assert (signed_volumes(model.rest_positions, model.tets) > 0).all()
    assert radius_ratio(model.rest_positions, model.tets).min() >= 0.005
    own = inside_fraction(small_model.rest_positions, small_model.tets,
                          np.concatenate([mu.centerline for mu in small_model.muscles]))
    assert res.stats["centerlines_inside"] > own - 0.03, (res.stats["centerlines_inside"], own)   # 0.89 / 0.88
    A = model.scan_transform
    V = V @ A[:3, :3].T + A[:3, 3]
    L = res.landmarks
    # the nose tip is the scan's most forward point near the midline
    mid = np.abs(V[:, 0]) < 0.02
    assert np.linalg.norm(L["nose_tip"] - V[mid][np.argmax(V[mid, 2])]) < 0.002
    # ICT's lips roll into the mouth and its lids into the sockets: the holes are at the back
    # of the inner lips and lids. Those hidden surfaces are left out, so the openings are the
    # lip line (closed) and the lid lines
    assert any("inner lips" in note for note in res.target.notes)
    holes = [res.aligned[h] for h in boundary_loops(res.target.faces) if len(h) < 200]
    # eye and mouth corners at the ends of the openings, the stomion between the lips
    mouth = min(holes, key=lambda H: np.linalg.norm(H.mean(0) - L["stomion"]))
    for side, k in (("L", np.argmax), ("R", np.argmin)):
        assert np.linalg.norm(L[f"mouth_corner_{side}"] - mouth[k(mouth[:, 0])]) < 0.002
        eye = min(holes, key=lambda H: np.linalg.norm(H.mean(0) - L[f"eye_outer_{side}"]))
        assert np.linalg.norm(L[f"eye_outer_{side}"] - eye[np.argmax(np.abs(eye[:, 0]))]) < 0.002
        assert np.linalg.norm(L[f"eye_inner_{side}"] - eye[np.argmin(np.abs(eye[:, 0]))]) < 0.002
    assert mouth[:, 1].min() - 0.001 <= L["stomion"][1] <= mouth[:, 1].max() + 0.001
    # the chin on the face (3-6 cm below the mouth), not at the base of the scan's neck
    assert 0.03 < L["stomion"][1] - L["chin"][1] < 0.06
    # the head's width measured on the skull, not across the ears (ears reach |x| > 8.5 cm)
    assert abs(L["head_extreme_L"][0]) < 0.085 and abs(L["head_extreme_R"][0]) < 0.085
    # the template's closed lid and lip slits lie on the openings, upper half on the upper
    # rim, so the skin is not torn there; the ears are boxed out, not snapped into stumps
    assert res.stats["openings_mapped"] == ["eye_L", "eye_R", "mouth"] and res.stats["ear_boxes"] == 2
    rims = np.concatenate(holes)
    for name, (a, b) in OPENINGS.items():
        halves = next(h for lp in ordered_loops(small_model.triangles) if (h := split_loop(
            small_model.neutral, small_model.triangles, lp, res.template_landmarks[a], res.template_landmarks[b])))
        up, lo = (model.neutral[h] for h in halves)
        assert cKDTree(rims).query(np.concatenate([up, lo]))[0].max() < 0.0015, name
        gap = up[1:-1, 1].mean() - lo[1:-1, 1].mean()
        assert (gap < 0.001) if name == "mouth" else (gap > 0.004), (name, gap)    # lips closed, eyes open
    # the skin keeps to its side of the lips: each vertex is embedded in a tet that moves
    # with the jaw as much as the vertex's own skinning weight says
    vj = np.einsum("vk,vk->v", model.embed_weights, model.volume_jaw_weights[model.tets[model.embed_tets]])
    assert np.abs(vj - model.jaw_weights).max() < 0.5
    assert np.abs(model.embedding_matrix() @ model.volume_jaw_weights - model.jaw_weights).max() < 0.5
    assert np.abs(model.neutral[:, 0]).max() < 0.085
    assert res.stats["inverted_triangles"] < 40


def test_inner_lips_behind_the_lip_line_are_left_out(small_model):
    """A head whose lips roll into the mouth (as production heads such as ICT's do): strips of
    skin run from the template's closed lip slit up and back into the upper lip and down and
    back into the lower one, so the hole is behind the lips. inner_surfaces finds exactly the
    strips (hidden from the front, joined to the hole), and without them the mouth's opening
    is the lip line again. The template's own bare slits have nothing behind them."""
    V, F = small_model.neutral, small_model.triangles
    TL = template_landmarks(small_model)
    up, lo = next(h for lp in ordered_loops(F) if (h := split_loop(V, F, lp, TL["mouth_corner_L"], TL["mouth_corner_R"])))

    def with_strips():
        """V, F with three rows of inner lip behind each half of the slit, 4 mm back each."""
        Vs, Fs = [V], [F]
        n = len(V)
        for half, dy in ((up, 1.0), (lo, -1.0)):
            rows = [half] + [n + k * len(half) + np.arange(len(half)) for k in range(3)]
            for k in range(1, 4):
                Vs.append(V[half] + k * np.array([0.0, 0.0015 * dy, -0.004]))
            n += 3 * len(half)
            for a, b in zip(rows[:-1], rows[1:]):
                quad = np.stack([a[:-1], a[1:], b[1:], b[:-1]], 1)
                tri = np.concatenate([quad[:, [0, 1, 2]], quad[:, [0, 2, 3]]])
                Fs.append(tri if dy > 0 else tri[:, ::-1])
        return np.concatenate(Vs), np.concatenate(Fs)

    Vr, Fr = with_strips()
    inner = inner_surfaces(Vr, Fr, opening_centres(TL))
    assert inner[len(F):].all() and not inner[:len(F)].any()
    loops = ordered_loops(Fr[~inner])
    assert any(split_loop(Vr, Fr[~inner], lp, TL["mouth_corner_L"], TL["mouth_corner_R"]) for lp in loops)
    assert not inner_surfaces(V, F, opening_centres(TL)).any()          # the template: bare slits


def test_stencil_curvature_of_a_sphere():
    s = trimesh.creation.icosphere(5, radius=0.05)
    k = stencil_curvature(s.vertices, s.faces)
    assert np.all(np.abs(k - 20.0) < 1.5)           # 1/r, convex positive, both directions


def test_cleaning_handles_duplicates_flips_and_units(small_model):
    V, F = small_model.neutral, small_model.triangles
    Fbad = F.copy()
    Fbad[::7] = Fbad[::7, ::-1]                      # inconsistent winding
    Fall = Fbad[:, ::-1]                             # and everything inside out
    V2 = np.concatenate([V, V[:50]])                 # duplicated vertices
    F2 = np.concatenate([Fall, np.array([[len(V) + 0, len(V) + 1, len(V) + 2]])])
    t = clean(V2 * 100, F2, name="scan.obj")
    assert t.unit == "cm" and np.isclose(t.scale, 0.01)
    assert any("duplicated" in n for n in t.notes)
    fn = np.cross(t.vertices[t.faces[:, 1]] - t.vertices[t.faces[:, 0]], t.vertices[t.faces[:, 2]] - t.vertices[t.faces[:, 0]])
    assert (fn[:, 2] > 0).mean() > 0.6                # the face's normals point forward (+Z) again
    # the template's closed lip and lid slits: their two sides coincide in the neutral, but
    # blendshapes part them, so with the shapes given they stay two (the copies still merge)
    opening = np.random.default_rng(0).normal(scale=0.002, size=V.shape)
    shapes = np.concatenate([opening, opening[:50]])[None] * 100
    t2 = clean(V2 * 100, F2, name="scan.obj", shapes=shapes)
    assert len(t.vertices) < len(V) and len(t2.vertices) == len(V)


@pytest.mark.parametrize("shape", ["sphere", "box"])
def test_non_faces_are_rejected(shape, small_model):
    m = trimesh.creation.icosphere(4, radius=0.09) if shape == "sphere" else \
        trimesh.creation.box((0.16, 0.22, 0.18)).subdivide().subdivide().subdivide()
    with pytest.raises(MeshError, match="face"):
        build_model((m.vertices, m.faces), template=small_model, expressions="none")


def test_bad_meshes_named():
    tri = trimesh.creation.icosphere(3, radius=0.1)
    V = tri.vertices.copy()
    V[5] = np.nan
    with pytest.raises(MeshError, match="scan.ply.*NaN"):
        clean(V, tri.faces, name="scan.ply")
    # no unit fits a 3.5e-6 unit box: provisionally scaled, the face decides (build_model)
    t = clean(tri.vertices * 1e-5, tri.faces, name="tiny.obj")
    assert t.unit == "none" and np.isclose(np.linalg.norm(np.ptp(t.vertices, axis=0)), 0.3)
    with pytest.raises(MeshError, match="flat.obj.*coincide"):
        clean(np.zeros_like(tri.vertices), tri.faces, name="flat.obj")
    with pytest.raises(MeshError, match="at least"):
        clean(tri.vertices, tri.faces[:100], name="few.obj")


def test_blendshape_import(tmp_path):
    s = trimesh.creation.icosphere(2, radius=0.1)
    s.export(tmp_path / "neutral.obj")
    moved = s.copy()
    moved.vertices[:, 1] += 0.001
    moved.export(tmp_path / "jawOpen.obj")
    moved.export(tmp_path / "mouthSmile_L.ply")
    names, D = read_blendshapes(tmp_path, len(s.vertices), s.vertices)
    assert names == ["jawOpen", "mouthSmile_L"] and np.allclose(D[:, :, 1], 0.001)
    assert recognised("mouthSmile_L") == "ARKit" and recognised("lipCornerPull_L") == "FACS"
    trimesh.creation.icosphere(1).export(tmp_path / "broken.obj")
    with pytest.raises(MeshError, match="broken.obj.*topology"):
        read_blendshapes(tmp_path, len(s.vertices), s.vertices)


def test_jaw_split_recovers_the_skinning(small_model):
    """A jaw shape made by the rig's own skinning (plus a lip offset) is split back into its
    jaw parameters and a remainder that the rig turns into exactly the imported shape; a jaw
    beyond the range that fits keep to is split at that range."""
    from invface.model.rig import JAW_LOWER, JAW_UPPER, skin
    from invface.morph.jaw import fit_jaw, is_jaw_shape, split_jaw
    m = small_model
    n, w = m.neutral, m.jaw_weights
    j0 = np.array([0.2, 0.02, -0.01, 0.0, -0.002, 0.001])     # inside the box: the jaw drops, never rises
    assert np.allclose(fit_jaw(m, skin(n, w, m.jaw_matrix(j0)), w > 0), j0, atol=1e-7)
    far = fit_jaw(m, skin(n, w, m.jaw_matrix(j0 + [0, 0, 0, 0, 0, 0.01])), w > 0)   # 11 mm forward
    assert abs(far[5] - JAW_UPPER[5]) < 1e-9 and np.all(far >= JAW_LOWER) and np.all(far <= JAW_UPPER)
    lip = n[m.landmarks["stomion"]]
    bump = 0.002 * np.exp(-np.sum((n - lip) ** 2, 1) / (2 * 0.01 ** 2))[:, None] * np.array([0, -1.0, 0.5])
    shape = skin(n + bump, w, m.jaw_matrix(j0))
    names = ["jawOpen", "mouthSmile_L"]
    D = np.array([shape - n, bump])
    out, jaws, stats = split_jaw(m, names, D)
    assert list(stats) == ["jawOpen"] and jaws["mouthSmile_L"] == [0.0] * 6
    assert abs(jaws["jawOpen"][0] - 0.2) < 0.01 and np.allclose(out[1], bump)
    assert np.abs(skin(n + out[0], w, m.jaw_matrix(jaws["jawOpen"])) - shape).max() < 1e-12
    assert stats["jawOpen"]["mean_after_mm"] < 0.2 * stats["jawOpen"]["mean_before_mm"]
    assert all(map(is_jaw_shape, ["jawOpen", "jawLeft", "AU26", "AU27_mouthStretch"]))
    assert not any(map(is_jaw_shape, ["mouthClose", "AU12", "lipCornerPull_L"]))


def test_imported_jaw_shape_drives_the_simulation(small_expressive_model, tmp_path):
    """An actor's blendshape files with the jaw's rotation baked into jawOpen: the build splits
    it into the jaw and a remainder, so the blendshape rig reproduces the imported shape and
    the muscle simulation (jaw bone at the split jaw, tracks from the remainder) follows it.
    Unsplit, an ICT jawOpen asked the simulation to open the skin around a closed jaw, and
    Newton did not converge."""
    def write_mesh(path, V, F):
        trimesh.Trimesh(V, F, process=False).export(path)
    tpl = small_expressive_model
    X = random_identity(tpl.neutral, 5, amplitude=0.003)
    Y, R, t = random_pose(X, 5, unit=0.001)
    write_mesh(tmp_path / "neutral.obj", Y, tpl.triangles)
    rig = tpl.surface_model("blendshape")
    files = tmp_path / "shapes"
    files.mkdir()
    imported = {}
    # the template's, jaw rotation included, under ICT-FaceKit's names
    for name, own in (("jawOpen", "jawOpen"), ("mouthSmile_L", "mouthSmileLeft")):
        p = tpl.parameters({"weights": {own: 1.0}, "jaw": tpl.meta["blendshape_jaw"][own]})
        imported[name] = X + rig.surface(p) - tpl.neutral
        write_mesh(files / f"{name}.obj", (imported[name] @ R.T + t) / 0.001, tpl.triangles)
    model, res = build_model(tmp_path / "neutral.obj", blendshapes=files, template=tpl)
    jaw = np.array(model.meta["blendshape_jaw"]["jawOpen"])
    made = tpl.meta["blendshape_jaw"]["jawOpen"][0]
    assert abs(jaw[0] - made) < 0.05 and np.abs(jaw[1:3]).max() < 0.02, (jaw, made)
    assert set(res.stats["jaw_split"]) == {"jawOpen"}
    assert model.meta["blendshape_jaw"]["mouthSmile_L"] == [0.0] * 6
    # the 50 ARKit controls the folder lacks come from the template, and the summary says so
    assert model.blendshape_names[:2] == ["jawOpen", "mouthSmile_L"] and len(model.blendshape_names) == 52
    assert set(res.stats["filled_from_template"]) == set(tpl.blendshape_names) - {"jawOpen", "mouthSmileLeft"}
    filled = model.blendshape_names.index("mouthRollLower")
    assert np.abs(model.blendshapes[filled] - tpl.blendshapes[tpl.blendshape_names.index("mouthRollLower")]).max() < 2e-3
    on = res.surface.snapped
    A = model.scan_transform
    for name, shape in imported.items():
        truth = ((shape @ R.T + t) / 0.001) @ A[:3, :3].T + A[:3, 3]      # the file, model frame
        p = model.parameters({"weights": {name: 1.0}, "jaw": model.meta["blendshape_jaw"][name]})
        rig_x = model.surface_model("blendshape").surface(p)
        assert closest_points(rig_x[on], truth, tpl.triangles)[2].max() < 5e-5, name   # 2 mm with the lips merged
        sim_x = model.surface_model("simulation").surface(p)
        d = closest_points(sim_x[on], truth, tpl.triangles)[2]
        assert d.mean() < 0.001 and np.quantile(d, 0.95) < 0.003, (name, d.mean(), np.quantile(d, 0.95))


def _with_torso(Y, F, unit):
    """A bust: the head (Y (n,3) file units, F) over a separate torso larger than the head
    (an ellipsoid 46 x 26 x 30 cm whose top meets the neck), in the same file units."""
    T, G = torso(Y[np.argmin(Y[:, 1])] * unit)
    return np.concatenate([Y, T / unit]), np.concatenate([F, G + len(Y)])


def _difficult_scan(tpl, kind):
    """(file vertices, faces, metres per file unit, truth-landmark source (X, ids, faces)) of a
    template identity with one real-scan difficulty (issue 27)."""
    X = random_identity(tpl.neutral, 5, amplitude=0.003)
    F = tpl.triangles
    rng = np.random.default_rng(7)
    if kind == "holes":              # scanner holes on the cheeks and forehead, 6 mm across
        c = X[F].mean(1)
        centres = X[tpl.landmarks["nose_tip"]] + np.array([[0.04, -0.01, -0.03], [-0.04, -0.01, -0.03],
                                                            [0.02, 0.07, -0.02], [-0.03, 0.08, -0.03]])
        F = F[np.min(np.linalg.norm(c[:, None] - centres[None], axis=2), axis=1) > 0.006]
    # the head upright in front of the torso (a bust is scanned standing), in the file's unit
    unit = {"no_unit": 1 / 37.3}.get(kind, 0.001)
    Y = X / unit
    if kind == "bust":
        Y, F = _with_torso(Y, F, unit)
    if kind == "spikes":             # ten spikes of 300 mm on the face
        Y = Y.copy()
        ids = rng.choice(np.flatnonzero(X[:, 2] > 0.05), 10, replace=False)
        d = X[ids] - X.mean(0)
        Y[ids] += 0.3 / unit * d / np.linalg.norm(d, axis=1, keepdims=True)
    if kind == "crown":              # a crown over the scalp (Nefertiti's): a cylinder 14 cm across
        top = X[tpl.landmarks["top_of_head"]]
        c = trimesh.creation.cylinder(radius=0.07, height=0.12, sections=48).subdivide().subdivide()
        C = c.vertices @ np.array([[1, 0, 0], [0, 0, 1], [0, 1, 0.0]]) + top + np.array([0, 0.04, -0.01])
        Y = np.concatenate([Y, C / unit])
        F = np.concatenate([F, c.faces + len(X)])
    if kind == "cranium":            # a bald cranium standing out by half its height above the brows
        lift = np.clip(0.5 * (X[:, 1] - X[tpl.landmarks["glabella"], 1] - 0.025), 0, 0.045)
        Y = (X + lift[:, None] * vertex_normals(X, F)) / unit
    if kind == "hair":               # hair 25 mm thick (+-20 %) over the scalp, thinning over 2 cm to a hairline
        lift = X[:, 1] - X[tpl.landmarks["glabella"], 1] - 0.04
        thick = 0.025 * np.clip(lift / 0.02, 0, 1) * (1 + 0.2 * np.sin(X[:, 0] * 300) * np.sin(X[:, 2] * 300))
        Y = (X + thick[:, None] * vertex_normals(X, F)) / unit
    if kind == "second_piece":       # a ball apart from the head, a quarter of its size
        s = trimesh.creation.icosphere(3, radius=0.05 / unit)
        Y = np.concatenate([Y, s.vertices + Y.mean(0) + np.array([0.2, 0, 0]) / unit])
        F = np.concatenate([F, s.faces + len(X)])
    return Y, F, unit, X


@pytest.mark.parametrize("kind", ["bust", "crown", "hair", "spikes", "holes", "second_piece", "no_unit"])
def test_real_scan_difficulties_build(kind, small_expressive_model):
    """Issue 27: a template identity with shoulders (a torso larger than the head), a crown,
    hair, ten 300 mm spikes, holes, a second piece, or no unit builds with no inverted tet and
    the sharp landmarks within 3 mm of the known ones; the unit comes from the face; under hair
    or a crown the scalp is the template's carried by the face, not the hair's surface."""
    tpl = small_expressive_model
    Y, F, unit, X = _difficult_scan(tpl, kind)
    model, res = build_model((Y, F), template=tpl, expressions="none")
    st = res.stats
    assert st["quality"]["inverted"] == 0
    if kind == "no_unit":
        assert st["unit"] == "none" and "no physical unit" in st["unit_summary"]
        assert abs(st["scale"] * 37.3 - 1) < 0.1            # the adult face's size, within 10 %
    else:
        assert st["unit"] == "mm" and np.isclose(st["scale"], 0.001), st["unit_summary"]
    if kind == "bust":
        assert any(n.startswith("cropped") for n in st["cleaning"]), st["cleaning"]
    if kind == "spikes":
        assert any("10 spike vertices" in n for n in st["cleaning"]), st["cleaning"]
    A = model.scan_transform
    truth = X / unit @ A[:3, :3].T + A[:3, 3]               # the identity in the model frame
    if kind in ("hair", "crown"):
        covered = {"hair": {"top", "left side", "right side"}, "crown": {"top"}}[kind]
        assert covered <= set(st["hidden_scalp"]), st["cleaning"]
        assert any(n.startswith("hair or a crown over the scalp") for n in st["cleaning"]), st["cleaning"]
        top = tpl.neutral[:, 1] > tpl.neutral[tpl.landmarks["glabella"], 1] + 0.06     # under the full hair
        err = np.linalg.norm(model.neutral[top] - truth[top], axis=1) * 1000
        assert err.mean() < 8.0, err.mean()                 # the hair's surface is 25 mm out
    else:
        assert st["hidden_scalp"] == [], st["cleaning"]
    tl = template_landmarks(tpl)
    tri, w, _ = closest_points(np.array(list(tl.values())), tpl.neutral, tpl.triangles)
    known = dict(zip(tl, np.einsum("nk,nkj->nj", w, truth[tpl.triangles[tri]])))
    err = {k: np.linalg.norm(res.landmarks[k] - known[k]) * 1000 for k in SHARP}
    assert max(err.values()) < 3.0, err


def _real_scan_turned(name):
    """(vertices (n,3) turned by bench/scan_variants.py's rotation, faces, the rotation (3,3))
    of the real scan ``name``; the test is skipped where the scans are not available."""
    from conftest import SHARED
    from invface.io.meshes import read_mesh
    path = SHARED / "data" / "real" / "scans" / f"{name}.obj"
    if not path.exists():
        pytest.skip("the real scans (../shared/data/real/scans) are not available")
    V, F = read_mesh(path)[:2]
    R = np.linalg.qr(np.random.default_rng([0, 2]).normal(size=(3, 3)))[0]
    R *= np.sign(np.linalg.det(R))
    return np.asarray(V, float) @ R.T, F, R


def test_a_unitless_bust_turned_anywhere_is_found_at_its_scale(small_model):
    """Lee Perry-Smith's bust (no physical unit), turned by a random rotation: the first scale
    guess aligned its face 3.9 mm from the template's at 1.5 times the right scale (3.4 mm at
    the right one), under the 5 mm that ended the search, and every landmark was 5-18 cm off
    (bench/scan_variants.py). Every guess is now tried and the closest face wins."""
    V, F, _ = _real_scan_turned("lee_perry_smith")
    scale = orient_target(clean(V, F, name="lee"), small_model)[0].scale
    assert abs(np.log(scale / 0.047)) < np.log(1.1), scale      # unturned: 46-49 mm per file unit


def test_a_face_beside_a_torso_many_times_its_area_is_kept_and_aligned(small_model):
    """A face-only scan (cut behind the cheeks) over a torso 1.6 times the bust's: the face is
    a few per cent of the torso's area. Pieces under a tenth of the largest were dropped as
    debris, and the torso alone was left to align. The face is now kept, and the template's
    face lands on it."""
    tpl = small_model
    X = random_identity(tpl.neutral, 5, amplitude=0.003)
    used, F = front_part(X, tpl.triangles, X[tpl.landmarks["nose_tip"], 2] - 0.07)
    X = X[used]
    T, G = torso(X[np.argmin(X[:, 1])], radii=(0.37, 0.21, 0.24), below=(0.22, 0.06))
    assert triangle_areas(X, F).sum() < 0.1 * triangle_areas(T, G).sum()
    Y, G = np.concatenate([X, T]), np.concatenate([F, G + len(X)])
    target, al, _, _ = orient_target(clean(Y * 1000, G, name="face_and_torso", unit="mm"), tpl, "mm")
    nose = np.flatnonzero(used == tpl.landmarks["nose_tip"])[0]
    assert np.linalg.norm(al.apply(X[nose]) - tpl.neutral[tpl.landmarks["nose_tip"]]) < 0.005


def test_a_pose_is_chosen_by_the_scan_on_the_template_and_the_template_on_the_scan():
    """The poses measured on Lee Perry-Smith's head over a torso (bench/scan_variants.py, the
    default head): the side of the head near an ear lay on the template's cheeks and forehead
    3.03 mm (median) from it, closer than the face's own pose (3.34 mm), and every landmark
    was 15-20 cm off; the template's face then stood up to 23 mm off the scan (90th
    percentile) against 5.9 mm. On ICT face 6 the two best poses are both on the face (6.97
    and 6.74 mm the other way), and the closer one (2.31 against 3.16 mm) keeps its nose tip
    5 mm from ICT's (27 mm with the other)."""
    from invface.morph.orient import best_pose
    lee = ([3.03, 3.09, 3.34, 3.39, 3.56], [0.02295, 0.01772, 0.00586, 0.00568, 0.00647])
    assert list(best_pose(np.array(lee[0]) / 1000, lee[1], 2)) == [2, 3]
    assert best_pose([0.00231, 0.00316, 0.00338], [0.00697, 0.00674, 0.01343])[0] == 0


def test_the_nose_tip_candidates_do_not_depend_on_how_the_scan_is_turned():
    """Nefertiti's profile is one closed loop. Turned by bench/scan_variants.py's rotation, the
    loop's walk started at the nose tip, whose wedge was then cut by the walk's end, and no
    candidate came within 64 mm of the nose (every landmark 30-240 mm off). Closed loops are
    now also walked from half-way round (orient._walks)."""
    from invface.morph.orient import find_frames
    turned, F, R = _real_scan_turned("nefertiti")
    tips = []
    for Y in (turned @ R, turned):
        t = clean(Y, F, name="nefertiti", unit="mm")
        tips.append(np.array([fr.nose_tip for fr in find_frames(t.vertices, t.faces, refine=False)]))
    back = tips[1] @ R                                             # the turned candidates, unturned
    assert len(back) == len(tips[0])
    assert np.abs(back - tips[0]).max() < 1e-6


def test_a_scale_guess_whose_face_never_settles_is_not_chosen(small_model, monkeypatch):
    """Lee Perry-Smith unturned: the guess "cm" settled, after every pass, on a pose whose face
    the similarity still found 0.66 of the template's size, 3.29 mm from it against the right
    guess's 3.34 mm (the template's face 6.5 and 5.7 mm off the scan), and it won: every
    landmark 6-12 cm off. Guesses whose face settled to the template's size are chosen from
    first (the measures here are those probed on Lee)."""
    from invface.morph import units
    from invface.morph.orient import Alignment
    right = 0.0469

    def measure(target, template):
        settled = abs(np.log(target.scale / right)) < 1e-6
        r, u, sigma = (0.00334, 0.00566, 1.0) if settled else (0.00329, 0.0065, 0.66)
        return Alignment(np.eye(3), np.zeros(3), r, None, np.inf, u), sigma, (np.eye(3), np.zeros(3))

    monkeypatch.setattr(units, "_measure", measure)
    monkeypatch.setattr(units, "provisional_scales", lambda V: [("none", 0.01), ("none", right)])
    target = clean(small_model.neutral, small_model.triangles, name="lee")
    t, _, scaling = units.settle_unit(target, small_model)
    assert np.isclose(scaling.scale, right) and np.isclose(t.scale, right), scaling.summary


def test_the_stomion_of_an_open_mouth_is_on_the_lips_not_in_the_mouth(default_model):
    """Lee Perry-Smith's mouth is open onto a cavity 9 cm deep, whose profile points share the
    lips' heights. Turned by bench/scan_variants.py's rotation (at the scale its unitless search
    finds, 46.01 mm per unit), the stomion was taken from the cavity, 8 cm behind the lips, and
    the subnasale fell back. The stomion's candidates are now those on the face's outline."""
    V, F, _ = _real_scan_turned("lee_perry_smith")
    target, al, _, _ = orient_target(clean(V * 0.04601, F, name="lee", unit="m"), default_model, "m")
    L, _, fell = find_landmarks(al.apply(target.vertices), target.faces, default_model)
    assert "stomion" not in fell and "subnasale" not in fell, fell
    assert L["stomion"][2] > L["nose_tip"][2] - 0.025, L["stomion"]          # on the lips, 1-2 cm behind the tip


def test_a_crop_that_leaves_nothing_of_the_head_stops_with_one_line(small_expressive_model, monkeypatch):
    """When the alignment takes another part of the scan for the face (a box-shaped torso under
    a bust, bench/scan_variants.py), the crop to the head can leave nothing, and the landmark
    stage failed on the empty mesh with a ValueError. It is now a MeshError naming the scan."""
    import invface.morph.build as build
    from dataclasses import replace
    real = build.crop_to_head
    monkeypatch.setattr(build, "crop_to_head", lambda target, *a: (replace(real(target, *a)[0], faces=np.zeros((0, 3), int)), []))
    Y, F, _, _ = _difficult_scan(small_expressive_model, "bust")
    with pytest.raises(MeshError, match="bust: cropped to the head .* 0 triangles are left"):
        orient_target(clean(Y, F, name="bust", unit="mm"), small_expressive_model, "mm")


@pytest.mark.parametrize("kind", ["cranium", "crown"])
def test_a_wide_cranium_is_skin_and_a_crown_is_not(kind, small_expressive_model):
    """Both stand more than CROWN outside the template's carried scalp. A cranium up to 32 mm
    wider, rising from the brows as a gentle slope, is kept (it was left out as a crown); a
    crown stands on the head at a rim and is left out."""
    Y, F, unit, _ = _difficult_scan(small_expressive_model, kind)
    hidden = orient_target(clean(Y, F, unit="mm"), small_expressive_model, "mm")[3]
    assert (hidden == []) if kind == "cranium" else ("top" in hidden), hidden


def test_failed_build_names_its_stage_and_draws_what_it_found(small_model, tmp_path, monkeypatch):
    """When a stage cannot go on, the error names the stage and keeps its cause, and the
    failure preview draws the aligned scan with the landmarks found by then (issue 27)."""
    import invface.morph.build as mb
    from invface.report.morph import write_failure_preview

    def no_curves(V, F, L):
        raise MeshError("no section joins the eye corners")
    monkeypatch.setattr(mb, "curve_set", no_curves)
    V, F = small_model.neutral, small_model.triangles
    with pytest.raises(mb.BuildFailed, match="curves stage: no section joins the eye corners") as e:
        mb.build_model((V * 1000, F), template=small_model, expressions="none")
    found = e.value.found
    assert e.value.stage == "curves" and found["aligned"].shape == found["target"].vertices.shape
    assert set(found["landmarks"]) >= {"nose_tip", "chin"}
    path = write_failure_preview(found, tmp_path, size=120, spp=2)
    img = plt_imread(path)
    assert img.shape[:2] == (120, 240) and img[..., :3].std() > 0.05    # a drawn scan, not a blank
