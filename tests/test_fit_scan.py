"""Dogleg least squares and 3D scan fitting (paper 000, Eq. 13)."""
import numpy as np
import pytest

from invface.errors import InvfaceError
from invface.fit.dogleg import dogleg
from invface.fit.scan import fit_scan
from invface.model.rig import euler_xyz

ROT, TR = np.array([0.05, -0.1, 0.02]), np.array([0.003, -0.002, 0.005])


def _rosenbrock(z):
    x, y = z
    return np.array([10 * (y - x * x), 1 - x]), np.array([[-20 * x, 10.0], [-1.0, 0.0]])


def test_dogleg_minimises_rosenbrock_with_and_without_bounds():
    res = dogleg(_rosenbrock, [-1.2, 1.0], max_iter=100)
    np.testing.assert_allclose(res.x, [1, 1], atol=1e-6)
    assert res.status in ("cost", "gradient", "step") and res.history[-1]["accepted"] in (True, False)
    res = dogleg(_rosenbrock, [-1.2, 1.0], lower=[-2, -2], upper=[0.5, 2], max_iter=100)
    np.testing.assert_allclose(res.x, [0.5, 0.25], atol=1e-5)       # the constrained optimum


def test_dogleg_box_step_does_not_crawl_along_a_bound():
    """Correlated variables whose unconstrained Gauss-Newton step leaves the box: the
    bounded step solves for the free variables with the others held (a projected step
    crawled here), and reaches the bounded least-squares optimum in a few iterations."""
    from scipy.optimize import lsq_linear
    rng = np.random.default_rng(1)
    A = rng.normal(size=(60, 20)) + 3 * rng.normal(size=(60, 1))         # correlated columns
    b = A @ rng.uniform(-1, 1, 20) + 0.01 * rng.normal(size=60)
    ref = lsq_linear(A, b, bounds=(0, 1), tol=1e-12)
    assert np.sum((ref.x <= 1e-9) | (ref.x >= 1 - 1e-9)) == 9               # the box is active
    # (the projected step was still 0.33 off after 30 iterations)
    res = dogleg(lambda x: (A @ x - b, A), np.zeros(20), 0.0, 1.0, max_iter=30)
    np.testing.assert_allclose(res.x, ref.x, atol=1e-8)
    assert res.iterations <= 6 and res.status != "max_iter"


def test_dogleg_curvature_scale_falls_where_the_cost_falls_faster_than_its_slope():
    """A Gaussian well 1 - exp(-(x - 5)^2 / 2) with the curvature at its bottom (1) as the
    model's: on the concave flank every Gauss-Newton step is a fraction of what the cost
    allows and falls faster than linearly (c <= 0). There mu halves (it was held: 54
    iterations, as without adapting)."""
    from invface.fit.dogleg import NormalEquations

    def well(x):
        d = x[0] - 5.0
        e = np.exp(-d * d / 2)
        return NormalEquations(1 - e, np.array([d * e]), np.array([[1.0]]))
    runs = {ad: dogleg(well, np.array([1.5]), max_iter=200, ftol=1e-12, gtol=1e-8, adapt_curvature=ad)
            for ad in (False, True)}
    for r in runs.values():
        np.testing.assert_allclose(r.x, [5.0], atol=1e-6)
    assert runs[False].iterations >= 50 and runs[True].iterations <= 25
    assert [h["mu"] for h in runs[True].history[:4]] == [0.5, 0.25, 0.125, 0.0625]


def test_dogleg_computes_derivatives_only_at_accepted_points():
    """A lazy NormalEquations: a rejected trial costs only its residual."""
    from invface.fit.dogleg import NormalEquations
    calls = {"cost": 0, "derivatives": 0}

    def fun(z):
        calls["cost"] += 1
        r, J = _rosenbrock(z)

        def derivatives():
            calls["derivatives"] += 1
            return J.T @ r, J.T @ J
        return NormalEquations(0.5 * float(r @ r), derivatives=derivatives)

    res = dogleg(fun, [-1.2, 1.0], max_iter=100, radius=10.0)
    np.testing.assert_allclose(res.x, [1, 1], atol=1e-6)
    accepted = sum(h["accepted"] for h in res.history)
    assert accepted < len(res.history)                         # some trials were rejected
    assert calls["derivatives"] <= accepted + 1 and calls["cost"] == len(res.history) + 1


def _truth(model, kind, seed=0):
    """Random weights on the shapes that move the skin (a scan sees nothing of tongueOut, which
    moves the tongue alone), one control of each opposite pair at most (as a face makes them,
    and the prior charges both), the jaw opened 0.08 rad, and the scan they make, posed."""
    from invface.model import FitVector
    skin = np.flatnonzero(np.abs(model.blendshapes).reshape(len(model.blendshapes), -1).max(1) > 0)
    rng = np.random.default_rng(seed)
    b = np.zeros(len(model.blendshape_names))
    b[skin] = np.where(rng.random(len(skin)) < 0.3, rng.uniform(0.2, 0.8, len(skin)), 0)
    for i, j in FitVector.of(model).opposites:
        if b[i] > 0:
            b[j] = 0.0
    p = np.r_[b, [0.08, 0, 0, 0, 0, 0]]
    sm = model.surface_model(kind)
    # the simulation solved cold, from rest (the same surface as warm, to the Newton tolerance)
    x = sm.surface(p) if kind == "blendshape" else sm.surface_of(sm.solve(p, warm=None))
    return p, x @ euler_xyz(ROT).T + TR


@pytest.mark.parametrize("kind", ["blendshape", "simulation"])
def test_scan_fit_recovers_controls_and_pose(small_expressive_model, kind):
    m = small_expressive_model
    p, scan = _truth(m, kind)
    fit = fit_scan(m, scan, kind=kind, lam=1e-8)
    assert np.abs(fit.p - p).max() < 2e-3
    assert np.abs(fit.rotation - ROT).max() < 1e-4 and np.abs(fit.translation - TR).max() < 1e-5
    assert np.median(fit.error) < 1e-5


def test_paper_lambda_biases_weights_by_about_1e_3(small_expressive_model):
    m = small_expressive_model
    p, scan = _truth(m, "blendshape")
    fit = fit_scan(m, scan, kind="blendshape")           # lambda = 1e-6 on m^2 residuals
    # most weights within 3e-3; the gaze's lid shapes, which move a few hundred vertices by
    # 2.4 mm at most, by up to 0.025 (with lambda 1e-8 every weight is within 2e-3, above)
    err = np.abs(fit.p - p)
    assert np.median(err) < 3e-3 and 1e-3 < err.max() < 0.03, err.max()


def test_nearest_point_mode_fits_a_scan_in_another_topology(small_expressive_model):
    import trimesh
    m = small_expressive_model
    p, scan = _truth(m, "blendshape", seed=1)
    V, F = trimesh.remesh.subdivide(scan, m.triangles)            # other vertex count and order
    order = np.random.default_rng(0).permutation(len(V))
    inv = np.argsort(order)
    fit = fit_scan(m, V[order], inv[F], kind="blendshape", mode="nearest", lam=1e-8)
    assert np.median(fit.error) < 5e-5 and np.abs(fit.p - p).max() < 0.05


@pytest.mark.parametrize("opening", [0.0, 0.35])
def test_nearest_mode_jaw_search_finds_the_opening(small_expressive_model, opening):
    """The coarse jaw search that starts nearest-mode fits finds the hinge opening of a scan
    in another topology (the rig's jaw opened by ``opening`` rad, subdivided) within 0.05 rad."""
    import trimesh
    from invface.fit.scan import search_jaw
    from invface.model import FitVector
    from invface.mesh.triangles import boundary_vertices
    m = small_expressive_model
    p = m.parameters({"jaw": [opening, 0, 0, 0, 0, 0]})
    V, F = trimesh.remesh.subdivide(m.surface_model("blendshape").surface(p), m.triangles)
    found = search_jaw(m, FitVector.of(m).pack(), V, F, 0.01, boundary_vertices(m.triangles, len(m.neutral)),
                       boundary_vertices(F, len(V)))
    assert abs(found - opening) <= 0.05 + 1e-9, found


def test_scan_fit_rejects_bad_scans(small_expressive_model):
    m = small_expressive_model
    with pytest.raises(InvfaceError, match="correspondence mode needs the model's topology"):
        fit_scan(m, m.neutral[:-5])
    bad = m.neutral.copy()
    bad[3, 0] = np.nan
    with pytest.raises(InvfaceError, match="non-finite"):
        fit_scan(m, bad)
    with pytest.raises(InvfaceError, match="align the scan"):
        fit_scan(m, m.neutral + [0.5, 0, 0], m.triangles, mode="nearest")


@pytest.fixture(scope="module")
def ict_actor(small_expressive_model):
    """The small template morphed onto the ICT-FaceKit neutral, the template's expressions
    carried over (skips without ../shared)."""
    from conftest import ICT
    from invface.morph.build import build_model
    if not (ICT / "expressions.npz").exists():
        pytest.skip("ICT-FaceKit data (../shared/data/ict-facekit) is not available")
    model, _ = build_model(ICT / "neutral.obj", template=small_expressive_model, expressions="copy")
    return model


@pytest.mark.parametrize("kind", ["blendshape", "simulation"])
def test_ict_expression_as_a_real_scan(ict_actor, kind):
    """An ICT-FaceKit expression (scan-derived, another rig, never seen by the model) fitted
    in nearest mode: the jaw opens and the moving part of the scan comes much closer."""
    from conftest import ICT
    from invface.mesh.closest import closest_points
    from invface.io.meshes import read_mesh
    m = ict_actor
    V0, F = read_mesh(ICT / "neutral.obj")
    data = np.load(ICT / "expressions.npz")
    delta = data["deltas"][list(data["names"]).index("jawOpen")]
    A = m.scan_transform
    S = (V0 + delta) @ A[:3, :3].T + A[:3, 3]
    covered = closest_points(V0 @ A[:3, :3].T + A[:3, 3], m.neutral, m.triangles)[2] < 0.002
    moving = S[(np.linalg.norm(delta, axis=1) * np.linalg.norm(A[:3, 0]) > 0.001) & covered]
    before = np.median(closest_points(moving, m.neutral, m.triangles)[2])
    fit = fit_scan(m, S, F, kind=kind, mode="nearest", max_iter=20)
    after = np.median(closest_points(moving, fit.surface, m.triangles)[2])
    assert before > 0.002                                  # the ICT jaw opens by centimetres
    assert after < 0.7 * before, (before, after)           # measured: 2.86 -> 1.38 / 1.72 mm
    assert fit.p[len(m.blendshape_names)] > 0.15  # the hinge opens (measured 0.21 / 0.27 rad; 0.08 without the jaw search)


def test_nearest_mode_jacobian_matches_finite_differences(small_expressive_model):
    """Both pair sets of the symmetric point-to-plane objective (model-to-scan and
    scan-to-model, barycentric) differentiate correctly in controls and pose."""
    from invface.fit.scan import _closest, _Objective
    from invface.model import FitVector
    m = small_expressive_model
    vec = FitVector.of(m)
    P = vec.P
    obj = _Objective(m.surface_model("blendshape"), 1e-6, vec)
    rng = np.random.default_rng(3)
    z = vec.pack(weights=rng.uniform(0, 0.4, vec.K), jaw=[0.05, 0, 0, 0, 0, 0], rotation=ROT, translation=TR)
    _, xr = obj.posed(z)
    S = m.neutral[::7] + rng.normal(0, 0.002, (len(m.neutral[::7]), 3))
    y = xr[::5] + rng.normal(0, 0.001, (len(xr[::5]), 3))
    nrm = rng.normal(size=y.shape)
    obj.pairs = (np.arange(0, len(xr), 5), y, nrm / np.linalg.norm(nrm, axis=1, keepdims=True))
    _, nb, trib, bb, _ = _closest(xr, m.triangles, S)
    obj.back = (m.triangles[trib], bb, S, nb)
    r, J = obj(z)
    assert len(r) == len(y) + len(S) + P + len(vec.opposites)
    d = rng.normal(size=len(z)) * 1e-6
    fd = (obj(z + d)[0] - obj(z - d)[0]) / 2
    np.testing.assert_allclose(J @ d, fd, rtol=1e-4, atol=1e-12)


def test_linear_term_holds_weak_weights_at_exactly_zero():
    """The weights' L1 term (c . x on x >= 0, ``dogleg.with_linear_term``): a variable whose data
    pull is weaker than its slope stays at 0 exactly (its column is not needed: the dogleg
    holds it at the bound), the others shrink by the slope over their curvature."""
    from invface.fit.dogleg import with_linear_term
    A = np.diag([1.0, 2.0, 1.0])
    b = np.array([1.0, 0.5, 0.05])
    c = np.array([0.1, 0.1, 0.1])
    res = dogleg(with_linear_term(lambda x: (A @ x - b, A), c), np.full(3, 0.5), np.zeros(3), np.ones(3),
                 max_iter=100)
    # minimiser of 0.5 |A x - b|^2 + c.x on x >= 0: x_k = max(0, (A_kk b_k - c_k) / A_kk^2)
    np.testing.assert_allclose(res.x, [0.9, (1.0 - 0.1) / 4, 0.0], atol=1e-8)
    assert res.x[2] == 0.0
    assert res.cost == pytest.approx(0.5 * np.sum((A @ res.x - b) ** 2) + c @ res.x)
