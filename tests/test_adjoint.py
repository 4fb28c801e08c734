"""Blendshape-driven tracks (Eq. 7-11) and end-to-end derivatives (Sec. 7): Poisson precompute,
forward model, tangent vs adjoint vs finite differences, the Dr.Jit bridge."""
import drjit as dr
import numpy as np
import pytest

from invface.errors import ControlsError, InvfaceError
from invface.mesh.tets import laplacian
from invface.sim.adjoint import Sensitivity, cold_finite_differences
from invface.sim.contact import TriangleContacts
from invface.sim.driven import DrivenSimulation
from invface.sim.poisson import PoissonTransfer

Float = dr.llvm.ad.Float


@pytest.fixture(scope="module")
def driven(small_expressive_model):
    return DrivenSimulation(small_expressive_model)


def test_poisson_precompute_is_the_exact_poisson_solution_and_linear(small_expressive_model):
    m = small_expressive_model
    pt = PoissonTransfer(m)
    dX = m.track_displacements
    assert dX.shape == (len(m.blendshape_names), len(m.rest_positions), 3)
    b = np.random.default_rng(0).uniform(0, 1, len(dX))
    combined = np.tensordot(b, m.blendshapes, axes=(0, 0))
    exact = pt.solve(combined[None])[0]                     # Poisson solve of the combined shape
    assert np.abs(np.tensordot(b, dX, axes=(0, 0)) - exact).max() <= 1e-10 * np.abs(exact).max()
    # it is a Poisson solution: Dirichlet data on the outer boundary, harmonic elsewhere
    assert np.allclose(exact[pt.ids], pt.S @ combined, atol=1e-15)
    L = laplacian(m.rest_positions, m.tets)
    r = (L @ exact)[pt.free]
    assert np.abs(r).max() <= 1e-10 * np.abs(L @ np.where(np.isin(np.arange(len(exact)), pt.ids)[:, None], exact, 0)).max()
    # the outer boundary lies on the render skin; bone-attached vertices are not in it
    assert not np.isin(pt.ids, m.fixed_cranium).any() and not np.isin(pt.ids, m.fixed_jaw).any()


@pytest.mark.parametrize("shape", ["mouthLowerDownLeft", "mouthRollLower", "mouthUpperUpLeft"])
def test_poisson_field_carries_each_lip_with_its_own_shape(small_expressive_model, shape):
    """The lips meet at the slit at rest, so a lip's slit and contact-face vertices lie on the
    other lip's skin too. Their Dirichlet data must be their own lip's: before, on this head, the
    inner lower lip's field missed lowerLipDepress by 5.1 of its 5.3 mm, and upperLipRaise moved
    it 4.1 mm."""
    m = small_expressive_model
    k = m.blendshape_names.index(shape)
    field = m.embedding_matrix() @ m.track_displacements[k]
    for curve in ("lip_inner_lower", "lip_inner_upper"):
        i = np.asarray(m.curves[curve])
        moved = np.linalg.norm(m.blendshapes[k][i], axis=1).mean()
        err = np.linalg.norm(field[i] - m.blendshapes[k][i], axis=1).mean()
        assert err < 0.05 * moved + 2e-4, (curve, err, moved)


def test_zero_controls_give_the_rest_pose(driven):
    r = driven.solve(np.zeros(len(driven.parameter_names)), warm=None)
    assert r.sim.iterations == 0
    assert np.abs(r.X - driven.model.rest_positions).max() < 1e-12
    assert np.allclose(r.tracks.activations, 0)


def test_driven_smile_follows_the_blendshape_and_recovers_activations(driven):
    m = driven.model
    k = m.blendshape_names.index("mouthSmileLeft")
    p = np.zeros(len(driven.parameter_names))
    p[k] = 1.0
    r = driven.solve(p, warm=None)
    x_sim, x_bs = driven.surface_of(r), m.surface({"mouthSmileLeft": 1.0})
    err = np.linalg.norm(x_sim - x_bs, axis=1)
    moved = np.linalg.norm(x_bs - m.neutral, axis=1).max()
    assert moved > 0.005 and err.mean() < 0.03 * moved and err.max() < 0.6 * moved
    i = m.muscle_names.index("zygomaticus_major_L")
    assert abs(r.tracks.activations[i] - m.blendshape_activations[k, i]) < 0.2    # one curve for all shapes
    assert r.tracks.activations[m.muscle_names.index("zygomaticus_major_R")] < 0.05


def _state(driven):
    p = driven.model.parameters({"weights": {"mouthSmileLeft": 0.6, "browInnerUp": 0.5, "mouthPucker": 0.3},
                                 "jaw": [0.06, 0.01, -0.01, 0.0005, -0.0003, 0.0004]})
    return p, driven.solve(p, warm=None, rtol=1e-10)


def test_tangent_adjoint_and_finite_differences_agree(driven):
    p, r = _state(driven)
    S = Sensitivity(driven, r)
    dX = S.tangent()
    rng = np.random.default_rng(1)
    gX = rng.standard_normal(r.X.shape)
    g_adj = S.gradient(gX)
    g_tan = np.einsum("pni,ni->p", dX, gX)
    assert np.abs(g_adj - g_tan).max() <= 1e-8 * np.abs(g_adj).max()
    names = driven.parameter_names
    checks = [("mouthSmileLeft", 1e-4), ("mouthPucker", 1e-4), ("jaw_rx", 1e-5), ("jaw_ry", 1e-5),
              ("jaw_tz", 1e-6)]
    for name, h in checks:
        i = names.index(name)
        e = np.zeros_like(p)
        e[i] = h
        Xs = [driven.solve(p + s * e, warm=None, rtol=1e-10).X for s in (1, -1)]
        fd = (Xs[0] - Xs[1]) / (2 * h)
        err = np.linalg.norm(fd - dX[i]) / np.linalg.norm(fd)
        print(name, err)
        assert err <= 1e-4, name
    # the jaw moves the lower face; a blendshape weight moves its side of the face
    assert np.linalg.norm(dX[names.index("jaw_rx")]) > 0


def test_adjoint_matches_cold_finite_differences_with_contacts_acting(small_expressive_model):
    """Issue 25: the surface is a function of the controls alone, and surface_vjp is its
    derivative. At a puckered mouth, the lower lip rolled in, with the jaw closing onto the lips (flesh-flesh
    and lip-on-jaw contacts acting), the adjoint of L(p) = sum(g * surface(p)) matches
    central differences of solves that each start from rest, on every control (relative
    error <= 1e-3), and a warm solve reaches the cold solve's surface."""
    m = small_expressive_model
    ds = DrivenSimulation(m)
    # (browInnerUp at 0.3, not 0.2: a muscle at its activation's break inside the one-sided
    # differences' steps of another control spoils them)
    p = m.parameters({"weights": {"mouthRollLower": 0.8, "mouthPucker": 0.3, "mouthSmileLeft": 0.3,
                                  "browInnerUp": 0.3},
                      "jaw": [-0.04, 0.02, -0.01, 0.0005, -0.0004, 0.0003]})
    r = ds.solve(p, warm=None, rtol=1e-10)
    c, jm = ds.sim.contacts.of(TriangleContacts), m.jaw_matrix(ds.split(p)[1])
    acting, kinds = c.acting(r.X, jm), c.kinds()
    assert (acting & kinds["flesh"]).sum() > 20 and (acting & kinds["jaw"]).sum() > 5
    gx = np.random.default_rng(3).standard_normal(m.neutral.shape)
    g = ds.surface_vjp(p, gx)
    fd = cold_finite_differences(ds, p, gx)
    err = np.abs(g - fd) / np.maximum(np.abs(fd), 1e-3 * np.abs(fd).max())
    print("adjoint vs cold FD, max relative error", err.max(), ds.parameter_names[int(err.argmax())])
    assert err.max() <= 1e-3, dict(zip(ds.parameter_names, err.round(6)))
    # path independence: from the last finite-difference state, warm, to the same surface
    warm = ds.solve(p, warm="last", rtol=1e-10)
    assert np.abs(ds.surface_of(warm) - ds.surface_of(r)).max() <= 1e-7


def test_a_point_solved_before_is_solved_again_from_rest_when_the_warm_start_fails(
        small_expressive_model, monkeypatch):
    """A fit comes back to its accepted point after rejected trials, warm from the last
    rejected state; where Newton stalls from there (at the end of an ICT jawOpen fit it did,
    at a relative residual of 2e-6, and the fit crashed) the point is solved from rest. A
    point never solved is not retried: the fit rejects that trial."""
    from invface.errors import SimulationError
    ds = DrivenSimulation(small_expressive_model)
    p = [small_expressive_model.parameters({"mouthSmileLeft": v}) for v in (0.5, 0.8, 0.65)]
    accepted = ds.result_at(p[0])
    ds.result_at(p[1])                                          # a rejected trial
    calls, real = [], ds.sim.solve

    def stalls_when_warm(*a, warm=None, **kw):
        calls.append(warm is not None)
        if warm is not None:
            raise SimulationError("Newton did NOT converge (test)")
        return real(*a, warm=warm, **kw)
    monkeypatch.setattr(ds.sim, "solve", stalls_when_warm)
    again = ds.result_at(p[0])
    assert calls == [True, False] and again.sim.converged
    assert np.abs(again.X - accepted.X).max() < 1e-6
    calls.clear()
    with pytest.raises(SimulationError):
        ds.result_at(p[2])
    assert calls == [True]


def test_a_state_that_is_not_a_stable_equilibrium_has_no_derivatives(driven):
    """The tangent needs the exact Newton matrix at the solution to be positive definite; at
    a saddle (here: the matrix negated) the sensitivity raises SimulationError, which a fit's
    dogleg treats as a rejected trial point, not a crash (an ICT jawOpen fit met one in CI)."""
    import dataclasses
    from invface.errors import SimulationError
    _, r = _state(driven)
    saddle = dataclasses.replace(r.sim, newton_data=-r.sim.newton_data, _solver=None)
    with pytest.raises(SimulationError, match="not a stable equilibrium"):
        Sensitivity(driven, dataclasses.replace(r, sim=saddle)).tangent()
    # the adjoint's conjugate gradients meet the negative curvature and hand over to the same check
    assert saddle._newton_factor is not None
    with pytest.raises(SimulationError, match="not a stable equilibrium"):
        Sensitivity(driven, dataclasses.replace(r, sim=saddle)).gradient(np.ones_like(r.X))


def test_a_gradient_right_after_a_solve_reuses_the_last_newton_factorisation(driven):
    """Issue 30: an adjoint solve at a fresh solution makes no factorisation. Conjugate
    gradients on the exact matrix there, preconditioned with the last Newton step's factorised
    exact Hessian, agree with the matrix's own factorisation to the size of the forward solve's
    tolerance (they stop at a relative residual of ADJOINT_CG_RTOL = 1e-6: 1e-7 here); once the
    simulator has factorised something else, the result falls back to its own factorisation,
    with the same gradient."""
    import dataclasses
    p, r = _state(driven)
    assert r.sim._newton_factor is not None and r.sim._solver is None
    gX = np.random.default_rng(4).standard_normal(r.X.shape)
    g_cg = Sensitivity(driven, r).gradient(gX)
    assert r.sim._solver is None                                # no factorisation was made
    own = dataclasses.replace(r, sim=dataclasses.replace(r.sim, _newton_factor=None))
    g_own = Sensitivity(driven, own).gradient(gX)
    assert own.sim._solver is not None
    assert np.abs(g_cg - g_own).max() <= 1e-6 * np.abs(g_own).max()
    driven.solve(0.5 * p, warm=None)                            # the simulator factorises again
    g_later = Sensitivity(driven, r).gradient(gX)
    assert r.sim._solver is not None
    assert np.abs(g_later - g_own).max() <= 1e-12 * np.abs(g_own).max()


def test_surface_models_share_one_interface_and_the_bridge_matches_the_adjoint(small_expressive_model):
    m = small_expressive_model
    rng = np.random.default_rng(2)
    for kind in ("blendshape", "simulation"):
        sm = m.surface_model(kind)
        p0 = m.parameters({"mouthSmileLeft": 0.5, "jaw": [0.04, 0, 0, 0, 0, 0]})
        x = sm.surface(p0)
        assert x.shape == m.neutral.shape
        gx = rng.standard_normal(x.shape)
        p = Float(p0.astype(np.float32))
        dr.enable_grad(p)
        flat = SurfaceFunctionFor(sm)(p)
        dr.backward(dr.sum(flat * Float(gx.reshape(-1).astype(np.float32))))
        ref = sm.surface_vjp(p0, gx)
        assert np.abs(np.array(p.grad) - ref).max() <= 1e-5 * np.abs(ref).max(), kind
        J = sm.surface_jacobian(p0)
        assert np.abs(np.einsum("pvi,vi->p", J, gx) - ref).max() <= 1e-8 * np.abs(ref).max(), kind
        # forward-mode through the op gives the tangent Jacobian
        p2 = Float(p0.astype(np.float32))
        dr.enable_grad(p2)
        flat2 = SurfaceFunctionFor(sm)(p2)
        dp = np.zeros_like(p0)
        dp[0] = 1.0
        dr.set_grad(p2, Float(dp.astype(np.float32)))
        fwd = np.array(dr.forward_to(flat2)).reshape(-1, 3)
        assert np.abs(fwd - J[0]).max() <= 1e-5 * np.abs(J[0]).max() + 1e-12, kind
    bs = m.surface_model("blendshape")
    p0 = m.parameters({"mouthSmileLeft": 0.5, "jaw": [0.1, 0.02, 0, 0.001, 0, 0]})
    J = bs.surface_jacobian(p0)
    for i in (0, len(p0) - 6, len(p0) - 5, len(p0) - 3):
        e = np.zeros_like(p0)
        e[i] = 1e-6
        fd = (bs.surface(p0 + e) - bs.surface(p0 - e)) / 2e-6
        assert np.abs(fd - J[i]).max() <= 1e-6 * np.abs(J[i]).max()
    assert np.allclose(m.surface({"mouthSmileLeft": 0.5}, kind="simulation"),
                       m.surface_model("simulation").surface(m.parameters({"mouthSmileLeft": 0.5})))


def test_posed_bridge_is_one_adjoint_product_of_the_pose_and_the_model(small_expressive_model):
    """bridge.PosedSurfaceFunction: z = (p, rotation, translation) -> x_R; its reverse pass is
    the posed Jacobian's transpose for both kinds (the simulation's through one surface_vjp)
    and matches finite differences on the rig in every entry kind (a weight, the jaw,
    rotation, translation); its forward pass is the posed Jacobian."""
    from invface.bridge import PosedSurfaceFunction
    from invface.model.pose import posed_jacobian, posed_surface
    from invface.model import FitVector
    m = small_expressive_model
    vec = FitVector.of(m)
    z0 = vec.from_dict({"weights": {"mouthSmileLeft": 0.4}, "jaw": [0.04, 0, 0, 0, 0, 0],
                        "rotation": [0.05, -0.1, 0.02], "translation": [0.002, 0.0, -0.001]})
    gx = np.random.default_rng(4).standard_normal(m.neutral.shape)
    for kind in ("blendshape", "simulation"):
        sm = m.surface_model(kind)
        fn = PosedSurfaceFunction(sm, vec)
        z = Float(z0.astype(np.float32))
        dr.enable_grad(z)
        xr = fn(z, exact=z0)
        np.testing.assert_allclose(fn.last, posed_surface(sm, z0, vec)[1], atol=1e-12)
        dr.backward(dr.sum(xr * Float(gx.reshape(-1).astype(np.float32))))
        grad = np.array(dr.grad(z), np.float64)
        _, J = posed_jacobian(sm, z0, vec)
        ref = np.einsum("kvi,vi->k", J, gx)
        assert np.abs(grad - ref).max() <= 1e-5 * np.abs(ref).max(), kind
        z2 = Float(z0.astype(np.float32))
        dr.enable_grad(z2)
        out = fn(z2, exact=z0)
        dz = np.zeros_like(z0)
        dz[vec.names.index("rotation_y")] = 1.0
        dr.set_grad(z2, Float(dz.astype(np.float32)))
        np.testing.assert_allclose(np.array(dr.forward_to(out)).reshape(-1, 3), J[vec.names.index("rotation_y")], atol=1e-6)
    for i in map(vec.names.index, ("mouthSmileLeft", "jaw_rx", "rotation_y", "translation_z")):
        e = np.zeros_like(z0)
        e[i] = 1e-6
        rig = m.surface_model("blendshape")
        fd = np.sum(gx * (posed_surface(rig, z0 + e, vec)[1] - posed_surface(rig, z0 - e, vec)[1])) / 2e-6
        g_rig = np.einsum("kvi,vi->k", posed_jacobian(rig, z0, vec)[1], gx)
        assert g_rig[i] == pytest.approx(fd, rel=1e-5), vec.names[i]


def SurfaceFunctionFor(sm):
    from invface.bridge import SurfaceFunction
    return SurfaceFunction(sm)


def test_bad_controls_are_rejected(driven, small_expressive_model):
    with pytest.raises(ControlsError, match="expected"):
        driven.solve(np.zeros(3))
    p = np.zeros(len(driven.parameter_names))
    p[2] = np.nan
    with pytest.raises(ControlsError, match="non-finite"):
        driven.solve(p)
    with pytest.raises(InvfaceError, match="unknown blendshape"):
        small_expressive_model.surface({"smile": 1.0}, kind="simulation")
