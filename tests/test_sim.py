"""Quasistatic simulation: material derivatives, FVM kernels, Newton, contacts, bad input."""
import numpy as np
import pytest
from meshes import box_tets

from invface.errors import InvfaceError, MeshError
from invface.sim import linsolve, materials
from invface.sim.contact import EyeballContacts, TriangleContacts
from invface.sim.fem import Elements, FleshModel, Pattern
from invface.sim.quasistatic import Simulator
from invface.sim.tracks import MuscleTracks, Tracks, activation_slopes

MAT = materials.Material()


def flesh_block():
    X, tets = box_tets((3, 2, 2), (0.03, 0.02, 0.02))
    el = Elements(X, tets)
    d = np.tile([1.0, 0, 0], (len(tets), 1))
    return X, tets, el, FleshModel(el, MAT, np.arange(len(tets)), d, np.zeros(len(tets), int))


def test_material_derivatives_match_finite_differences():
    rng = np.random.default_rng(1)
    F = np.eye(3) + 0.3 * rng.standard_normal((6, 3, 3))
    F[0] = np.diag([1.0, 1.0, 0.1])             # inside the volume barrier (J < 0.2)
    d = rng.standard_normal((6, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    a = rng.random(6)
    for fn in (lambda F, o: materials.isotropic(F, MAT, o), lambda F, o: materials.fibre(F, d, a, MAT, o)):
        psi, P, H = fn(F, 2)
        h = 1e-6
        for k in range(9):
            E = np.zeros(9)
            E[k] = h
            E = E.reshape(3, 3)
            pp, Pp, _ = fn(F + E, 1)
            pm, Pm, _ = fn(F - E, 1)
            assert np.allclose((pp - pm) / (2 * h), P[:, k // 3, k % 3], rtol=1e-5, atol=1e-5 * np.abs(P).max())
            assert np.allclose(((Pp - Pm) / (2 * h)).reshape(6, 9), H[:, :, k], rtol=1e-5,
                               atol=1e-5 * np.abs(H).max())


def test_forces_and_stiffness_match_finite_differences():
    X, tets, el, flesh = flesh_block()
    rng = np.random.default_rng(2)
    Xd = X + 0.0007 * rng.standard_normal(X.shape)      # no tet inverted (the energy is +inf there)
    dof = np.arange(len(X))
    pat = Pattern(dof, tets)
    E, g_nodes, Ke = flesh.evaluate(Xd, [0.6], 2)
    g = pat.scatter(g_nodes)
    K = pat.matrix(pat.assemble(Ke), full=True)
    v = rng.standard_normal(g.size)
    h = 1e-7
    Ep, gp, _ = flesh.evaluate(Xd + h * v.reshape(-1, 3), [0.6], 1)
    Em, gm, _ = flesh.evaluate(Xd - h * v.reshape(-1, 3), [0.6], 1)
    assert abs((Ep - Em) / (2 * h) - g @ v) <= 1e-5 * abs(g @ v)
    dg = (pat.scatter(gp) - pat.scatter(gm)) / (2 * h)
    assert np.linalg.norm(dg - K @ v) <= 1e-5 * np.linalg.norm(K @ v)


def test_pattern_with_constrained_vertices_and_extra_pairs_matches_a_dense_assembly():
    """fem.Pattern's slots (built from 3x3 vertex-pair blocks) against a dense assembly of the
    same element matrices and coupling blocks, constrained vertices removed."""
    X, tets, _, _ = flesh_block()
    N, T = len(X), len(tets)
    rng = np.random.default_rng(5)
    free = rng.random(N) > 0.3
    dof = np.full(N, -1)
    dof[free] = np.arange(free.sum())
    pairs = rng.integers(0, N, size=(40, 2))
    pairs = pairs[pairs[:, 0] != pairs[:, 1]]
    Ke = rng.normal(size=(T, 12, 12))
    Ke += Ke.transpose(0, 2, 1)
    B = rng.normal(size=(len(pairs), 3, 3))
    pat = Pattern(dof, tets, pairs)
    both = np.concatenate([pairs, pairs[:, ::-1]])
    got = pat.matrix(pat.assemble(Ke, [(both, np.concatenate([B, B.transpose(0, 2, 1)]))]), full=True).toarray()
    A = np.zeros((3 * N, 3 * N))
    for t in range(T):
        d = (3 * tets[t][:, None] + np.arange(3)).reshape(-1)
        A[np.ix_(d, d)] += Ke[t]
    for (v, u), b in zip(pairs, B):
        A[3 * v:3 * v + 3, 3 * u:3 * u + 3] += b
        A[3 * u:3 * u + 3, 3 * v:3 * v + 3] += b.T
    keep = (3 * np.flatnonzero(free)[:, None] + np.arange(3)).reshape(-1)
    assert np.allclose(got, A[np.ix_(keep, keep)], atol=1e-12)
    assert np.array_equal(pat.diag_slot, pat.slots(np.arange(pat.n), np.arange(pat.n)))
    v = rng.normal(size=pat.n)                  # the symmetric product the conjugate gradients use
    data = pat.assemble(Ke, [(both, np.concatenate([B, B.transpose(0, 2, 1)]))])
    assert np.allclose(pat.matvec(data)(v), A[np.ix_(keep, keep)] @ v, atol=1e-10)


def test_rest_state_has_zero_force_and_patch_test():
    X, tets, el, flesh = flesh_block()
    _, g0, _ = flesh.evaluate(X, [0.0], 1)
    assert np.abs(g0).max() < 1e-12
    # affine deformation: uniform stress, interior nodes force-free, same P in every tet
    A = np.array([[1.1, 0.05, 0.0], [0.02, 0.95, 0.03], [0.0, -0.04, 1.02]])
    Xa = X @ A.T + [0.01, -0.02, 0.005]
    F = el.deformation_gradient(Xa)
    assert np.allclose(F, A, atol=1e-12)
    _, g_nodes, _ = flesh.evaluate(Xa, [0.3], 1)
    f = Pattern(np.arange(len(X)), tets).scatter(g_nodes).reshape(-1, 3)
    interior = np.all((X > 1e-9) & (X < np.array([0.03, 0.02, 0.02]) - 1e-9), axis=1)
    assert interior.any()
    assert np.abs(f[interior]).max() < 1e-9 * np.abs(f).max()


def test_uniaxial_fibre_stretch_matches_closed_form():
    """F = diag(l, s, s), fibres along x: FVM reaction on the x = L face equals P11 * area."""
    X, tets, el, flesh = flesh_block()
    lam, s, a = 1.15, 0.94, 0.7
    m = MAT
    c = 2 * m.mu10 + 4 * m.mu01
    J = lam * s * s
    u = lam - 1
    fp = m.passive_p1 * (np.exp(m.passive_p2 * u) - 1)
    fa = np.exp(-(u / m.active_width) ** 2)
    P11 = (2 * m.mu10 * lam + 2 * m.mu01 * lam * 2 * s * s + (m.kappa * (J - 1) - c) * s * s
           + m.sigma_max * (fp + a * fa))
    Xd = X * [lam, s, s]
    _, g_nodes, _ = flesh.evaluate(Xd, [a], 1)
    f = Pattern(np.arange(len(X)), tets).scatter(g_nodes).reshape(-1, 3)
    face = np.isclose(X[:, 0], 0.03)
    area = 0.02 * 0.02
    assert np.isclose(f[face, 0].sum() / area, P11, rtol=1e-10)


def _clamped(H):
    w, Q = np.linalg.eigh(H)
    return np.einsum("tik,tk,tjk->tij", Q, np.maximum(w, 0), Q)


def test_closed_form_eigensystems_rebuild_and_project_the_material_stiffness():
    """The isotropic term's analytic eigensystem rebuilds its dP/dF (floor -inf), and the
    analytic clamping of both terms equals clamping the eigenvalues of a 9x9 eigensolver, on
    stretched, compressed, near-barrier and equal-singular-value F."""
    rng = np.random.default_rng(3)
    F = np.eye(3) + 0.35 * rng.standard_normal((400, 3, 3))
    F = np.concatenate([F[np.linalg.det(F) > 0.05],
                        [np.eye(3) * 0.9, np.diag([1.2, 1.2, 0.3]), np.diag([0.5, 0.5, 0.15])]])
    _, _, H = materials.isotropic(F, MAT)
    prm = MAT.params()
    rebuilt = np.zeros_like(H)
    for t in range(len(F)):
        materials.iso_projected(F[t], prm, -np.inf, rebuilt[t])
    scale = np.abs(H).max()
    assert np.abs(rebuilt - H).max() < 1e-12 * scale
    assert (np.linalg.eigvalsh(H)[:, 0] < -1e-6 * scale).mean() > 0.5     # most need the fix
    Hp = materials.isotropic(F, MAT, project=True)[2]
    assert np.abs(Hp - _clamped(H)).max() < 1e-12 * scale
    d = rng.standard_normal((len(F), 3))
    d /= np.linalg.norm(d, axis=1)[:, None]
    a = rng.uniform(0, 1, len(F))
    Hf = materials.fibre(F, d, a, MAT)[2]
    assert (np.linalg.eigvalsh(Hf)[:, 0] < -1e-6 * np.abs(Hf).max()).any()
    Hfp = materials.fibre(F, d, a, MAT, project=True)[2]
    assert np.abs(Hfp - _clamped(Hf)).max() < 1e-12 * np.abs(Hf).max()


def test_tracks_energy_and_gradient():
    rng = np.random.default_rng(3)
    tr = Tracks([0, 2], [[0, 0, 0], [1, 1, 1]], 5.0)
    X = rng.standard_normal((3, 3))
    assert np.isclose(tr.energy(X), 2.5 * (np.sum(X[0] ** 2) + np.sum((X[2] - 1) ** 2)))
    assert np.allclose(tr.gradient(X), 5.0 * (X[[0, 2]] - [[0, 0, 0], [1, 1, 1]]))


def test_centerline_length_and_activation_curve(small_model):
    m = small_model
    tr = MuscleTracks(m, np.zeros((0, len(m.rest_positions), 3)), np.ones(len(m.rest_positions), bool), 1.0)
    L, _ = tr.lengths(tr.rest_centerlines)
    assert np.allclose(L, [mu.rest_length for mu in m.muscles], rtol=1e-12)
    rng = np.random.default_rng(4)
    C = tr.rest_centerlines + 1e-3 * rng.standard_normal(tr.rest_centerlines.shape)
    _, dL = tr.lengths(C)
    dC = rng.standard_normal(C.shape)
    h = 1e-7
    fd = (tr.lengths(C + h * dC)[0] - tr.lengths(C - h * dC)[0]) / (2 * h)
    assert np.allclose(fd, np.bincount(tr.owner, np.sum(dL * dC, 1), minlength=len(L)), rtol=1e-6)
    mus = m.muscles[0]
    L0 = mus.rest_length
    a, da = mus.activation(0.75 * L0), activation_slopes(mus, 0.75 * L0)
    assert np.isclose(a, 0.5) and np.allclose(da, -2.0 / L0)
    assert mus.activation(1.2 * L0) == 0.0


def test_activation_derivative_is_the_one_into_the_box(small_expressive_model):
    """The activation Jacobian in the weights is the forward difference, into the box: at rest,
    where a muscle with no slack sits on its curve's break (the lengthening side's slope, 0,
    gave the adjoint a 7.8 % error on browOuterUp_R at weight 0 on the default head), and
    at a smile, where muscles sit on their ramps."""
    from invface.model.rig import jaw_transform_derivatives
    from invface.sim.driven import DrivenSimulation
    m = small_expressive_model
    ds = DrivenSimulation(m, contact=False)
    p = np.zeros(len(ds.parameter_names))
    b0, jaw = ds.split(p)
    jm = m.jaw_matrix(jaw)
    smile = b0.copy()
    smile[[m.blendshape_names.index(n) for n in ("mouthSmileLeft", "mouthSmileRight")]] = 0.7
    h = 1e-6
    for b in (b0, smile):
        st = ds.tracks.evaluate(b, jm)
        da = ds.tracks.activation_jacobian(st, jm, jaw_transform_derivatives(jaw, m.jaw_pivot, m.jaw_frame))
        fwd = np.stack([(ds.tracks.evaluate(b + h * e, jm).activations - st.activations) / h
                        for e in np.eye(len(b))], 1)
        assert np.abs(fwd).max() > 0.5                       # some shapes do activate muscles
        assert np.allclose(da[:, :ds.n_blendshapes], fwd, rtol=1e-4, atol=1e-6 * np.abs(fwd).max())
    assert ds.tracks.evaluate(smile, jm).activations[[i for i, mu in enumerate(m.muscles)
                                                      if mu.name.startswith("zygomaticus_major")]].min() > 0.2


def test_activation_ramp_keeps_a_muscle_passive_when_its_neighbours_carry_it():
    """The least-squares ramp: shapes that engage the muscle shorten it by 8-12 % (activation
    0.8); others carry it along by up to 3 %. The slack lies between, so those stay at 0."""
    from invface.template.expressions import MIN_RAMP, activation_ramp
    strain = np.array([0.08, 0.10, 0.12, 0.0, 0.01, 0.02, 0.03, -0.02])
    target = np.array([0.8, 0.8, 0.8, 0, 0, 0, 0, 0])
    e0, e1 = activation_ramp(strain, target)
    assert 0.02 <= e0 < 0.08 and e1 - e0 >= MIN_RAMP - 1e-12
    a = np.clip((strain - e0) / (e1 - e0), 0, 1)
    assert a[3:].max() < 0.05 and np.abs(a[:3] - 0.8).max() < 0.2
    assert activation_ramp(strain, np.zeros_like(strain))[0] >= 0.12     # engaged by none: never active


def test_calibrated_curves_name_the_muscles_a_shape_engages(small_expressive_model):
    """On the small head, each shape at weight 1 activates (above 0.05) more than half of the
    muscles it engages (49 of 75 pairs) and few others (65 of 2161). A smile activates
    zygomaticus major most."""
    m = small_expressive_model
    tr = MuscleTracks(m, m.track_displacements, np.ones(len(m.rest_positions), bool), 1.0)
    jaws, K = m.meta.get("blendshape_jaw", {}), len(m.blendshape_names)
    A = np.array([tr.evaluate(np.eye(K)[k], m.jaw_matrix(np.asarray(jaws.get(n, np.zeros(6)), float))).activations
                  for k, n in enumerate(m.blendshape_names)])
    engaged = m.blendshape_activations > 0
    assert ((A > 0.05) & engaged).sum() > 0.55 * engaged.sum()
    assert ((A > 0.05) & ~engaged).sum() < 0.05 * (~engaged).sum()
    smile = A[m.blendshape_names.index("mouthSmileLeft")]
    assert m.muscles[int(np.argmax(smile))].name == "zygomaticus_major_L"


@pytest.fixture(scope="module")
def sim(small_model):
    return Simulator(small_model)


def test_rest_pose_is_equilibrium(sim):
    r = sim.solve()
    assert r.converged and r.iterations == 0
    assert np.abs(r.X - sim.model.rest_positions).max() < 1e-12


def test_newton_converges_quadratically_on_smile(sim):
    acts = {n: 0.6 for n in sim.muscle_names if n.startswith("zygomaticus_major")}
    r = sim.solve(acts)
    assert r.converged and r.inverted == 0
    res = np.array(r.residuals)
    # the last steps far faster than linear (a projected or shifted Hessian gives ratios of
    # 0.5-0.9); not cleanly quadratic, as the lip contacts' forces bend over 0.01 mm (their
    # Hessian along the last Newton step is 5 % off at 0.01 mm, 4e-6 at 0.001 mm): 0.08 and
    # 0.01 here, on the teeth (without contacts 1e-4 and 3e-5); 0.11 and 0.02 with the lids free
    # on the eyeballs (no lid contact acts: the path changed)
    assert res[-1] < 1e-6 and res[-1] < 0.1 * res[-2] and res[-2] < 0.15 * res[-3]
    # smile: the mouth corners move up and out (3.3 and 0.5 mm; 1.8 mm out over the skin
    # offset by the old depths, 12 mm under the zygoma, not the table's 7)
    x0 = sim.model.neutral[sim.model.landmarks["mouth_corner_L"]]
    x1 = sim.surface(r)[sim.model.landmarks["mouth_corner_L"]]
    assert x1[1] - x0[1] > 0.002 and x1[0] - x0[0] > 0.0003
    # quasi-incompressible flesh: total volume within 1 %
    v0 = sim.elements.volume.sum()
    assert abs(sim.elements.volumes(r.X).sum() / v0 - 1) < 0.01
    # warm start: fewer iterations than cold
    r2 = sim.solve({k: 0.65 for k in acts}, warm=r)
    assert r2.converged and r2.iterations < r.iterations
    # the factorisation at the solution is kept for adjoint solves
    assert r.solver is not None and np.all(np.isfinite(r.solver.solve(np.ones(sim.pattern.n))))


def test_activation_gradient_matches_finite_differences(sim):
    """The muscle-level adjoint (sim.adjoint.activation_gradient, the paper-scale bench's
    gradient) against central differences of cold solves at a smile, contacts acting."""
    from invface.sim.adjoint import activation_gradient
    names = [n for n in sim.muscle_names if n.startswith(("zygomaticus_major", "levator_anguli_oris"))]
    a = sim.activation_vector({n: 0.5 for n in names})
    r = sim.solve(a, rtol=1e-10)
    gX = np.random.default_rng(3).normal(size=r.X.shape)
    g = activation_gradient(sim, r, gX)
    L = lambda b: np.sum(gX * sim.solve(b, rtol=1e-10).X)
    checked = [sim.muscle_names.index(n) for n in names[:2]] + [int(np.argmax(np.abs(g)))]
    L0 = L(a)
    for m in checked:
        e = np.zeros_like(a)
        e[m] = 1e-4
        if a[m] > 0:
            fd = (L(a + e) - L(a - e)) / 2e-4
        else:               # at the activation's lower bound: second-order, into the box
            fd = (-3 * L0 + 4 * L(a + e) - L(a + 2 * e)) / 2e-4
        assert abs(fd - g[m]) < 1e-4 * np.abs(g).max() + 1e-3 * abs(fd), (sim.muscle_names[m], fd, g[m])
    assert np.abs(g).max() > 0


def test_jaw_open_keeps_tets_positive_and_lips_apart(sim):
    r = sim.solve(jaw=[0.2, 0, 0, 0, 0, 0])
    assert r.converged and r.inverted == 0 and r.min_J > 0.2
    m = sim.model
    x = sim.surface(r)
    up, lo = m.curves["lip_inner_upper"], m.curves["lip_inner_lower"]
    assert x[up, 1].mean() - x[lo, 1].mean() > 0.01


def test_wide_open_jaw_starts_inside_the_energy_domain(sim):
    """Issue 25: at the jaw's upper bound (0.6 rad, 8 mm down and forward) the lower lip
    crushes tets with three cranium-fixed vertices against the volume barrier; the jaw-skinned
    guess for a wider opening inverts them (a start where the energy is infinite), the solver's
    start does not, and the warm solve from there converges."""
    jaw = np.array([0.6, 0, 0, 0, -0.008, 0.008])
    r = sim.solve(jaw=jaw)
    assert r.converged and r.inverted == 0 and r.min_J < 0.05
    wider = jaw + [0.02, 0, 0, 0, 0, 0]
    guess = r.X + sim.model.skinned_volume(wider) - sim.model.skinned_volume(jaw)
    fixed = sim.dof_of_vertex < 0
    guess[fixed] = sim.constrained_positions(wider)[fixed]
    assert (sim.elements.volumes(guess) <= 0).any()
    start = sim._start(r.X, jaw, wider)
    assert (sim.elements.volumes(start) > 0).all()
    assert np.abs(start[fixed] - sim.constrained_positions(wider)[fixed]).max() < 1e-12
    assert sim.solve(jaw=wider, warm=r).converged


def test_load_step_predictor_is_second_order(sim):
    """Issue 25: a load step starts from the Euler predictor X + dX/dt h (the tangent of the
    equilibrium path, sim._tangent_start); its residual shrinks as h^2 (the jaw-skinned start's
    as h), so a step near a crushed tet starts nearer its equilibrium."""
    acts = np.array([0.6 if n.startswith("zygomaticus_major") else 0.0 for n in sim.muscle_names])
    jaw = np.array([0.1, 0, 0, 0, 0, 0])
    r = sim.solve(acts, jaw=jaw, rtol=1e-10)
    secs = dict(assembly=0.0, factor=0.0, solve=0.0)
    residual = {}
    for h in (0.04, 0.02):
        a1, j1 = acts + h, jaw + [h, 0, 0, 0, 0, 0]
        pred = sim._tangent_start(r.X, r.newton_data, (acts, jaw, None), (a1, j1, None), secs)
        skin = sim._start(r.X, jaw, j1)
        jm = sim.model.jaw_matrix(j1)
        residual[h] = [np.linalg.norm(sim._total(x, a1, jm, None, 1)[1]) for x in (pred, skin)]
        fixed = sim.dof_of_vertex < 0
        assert np.abs(pred[fixed] - sim.constrained_positions(j1)[fixed]).max() < 1e-12
        assert sim._better_start(skin, pred, a1, j1, None) is pred
    (p1, s1), (p2, s2) = residual[0.04], residual[0.02]
    assert 3.0 < p1 / p2 < 5.0 and s1 / s2 < 2.5       # second order against first order
    assert p2 < 0.2 * s2


def test_contact_gap_and_energy_derivatives_match_finite_differences():
    """The plane gap of a point and a triangle and the gated penalty of a contact are C2
    functions of the 12 coordinates: gradients and Hessians against central differences."""
    from invface.sim.contact.triangles import contact_energy, plane_gap
    rng = np.random.default_rng(5)
    q = 0.01 * rng.standard_normal((6, 12))
    gap = plane_gap(*(q[:, 3 * i:3 * i + 3] for i in range(4)), order=0)
    dv = q[:, :3] - (q[:, 3:6] + q[:, 6:9] + q[:, 9:]) / 3
    r = np.sqrt(np.einsum("ci,ci->c", dv, dv) - gap ** 2)      # in-plane distance
    reach = np.stack([0.5 * r, 1.5 * r], 1)                     # inside the gate's fall-off
    fns = [lambda q, o: plane_gap(*(q[:, 3 * i:3 * i + 3] for i in range(4)), order=o),
           lambda q, o: contact_energy(q, gap + 0.003, reach, 100.0, o)]   # 3 mm penetration
    for fn in fns:
        _, G, H = fn(q, 2)
        h = 1e-7
        for k in range(12):
            e = np.zeros(12)
            e[k] = h
            fd = (fn(q + e, 0) - fn(q - e, 0)) / (2 * h)
            assert np.allclose(fd, G[:, k], rtol=1e-6, atol=1e-6 * np.abs(G).max())
            fh = (fn(q + e, 1)[1] - fn(q - e, 1)[1]) / (2 * h)
            assert np.allclose(fh, H[:, :, k], rtol=1e-6, atol=1e-6 * np.abs(H).max())


def test_contacts_push_back_penetration(sim):
    c = sim.contacts.of(TriangleContacts)
    X, M = sim.model.rest_positions, np.eye(4)
    assert len(c) > 0 and np.all(c.gaps(X, M) > -1e-12) and c.energy(X, M) == 0
    # push a lip vertex into the facing lip: positive energy, force out of the other lip
    i = np.flatnonzero(c.flesh)[0]
    Q = c.points(X, M)
    n = np.cross(Q[c.tri[i, 1]] - Q[c.tri[i, 0]], Q[c.tri[i, 2]] - Q[c.tri[i, 0]])
    n /= np.linalg.norm(n)
    Xp = X.copy()
    Xp[c.v[i]] -= (c.gaps(X, M)[i] + 5e-4) * n
    assert c.energy(Xp, M) > 0 and c.gradient(Xp, M)[c.v[i]] @ n < 0
    # gradient and Hessian blocks of the whole contact set against finite differences
    rng = np.random.default_rng(6)
    Xr = Xp + 2e-4 * rng.standard_normal(X.shape)
    dX = rng.standard_normal(X.shape)
    h = 1e-8
    fd = (c.energy(Xr + h * dX, M) - c.energy(Xr - h * dX, M)) / (2 * h)
    assert np.isclose(fd, np.sum(c.gradient(Xr, M) * dX), rtol=1e-5)
    dg = (c.gradient(Xr + h * dX, M) - c.gradient(Xr - h * dX, M)) / (2 * h)
    Hd = np.zeros_like(X)
    for pairs, B in c.blocks(Xr, M):
        np.add.at(Hd, pairs[:, 0], np.einsum("pij,pj->pi", B, dX[pairs[:, 1]]))
    assert np.linalg.norm(dg - Hd) <= 1e-5 * np.linalg.norm(dg)


def test_contact_projection_lifts_only_the_contacts_negative_curvature(sim):
    """Where the exact Newton matrix does not factor, Newton first projects each acting
    contact's 12x12 Hessian to PSD with the flesh's terms exact: the correction added to the
    exact matrix is PSD, touches only the acting contacts' vertices, and the contacts' part
    of the corrected matrix is PSD where the exact one was not."""
    c, pat = sim.contacts.of(TriangleContacts), sim.pattern
    X, M = sim.model.rest_positions.copy(), np.eye(4)
    rng = np.random.default_rng(7)
    lips = np.unique(c.v[c.flesh])                             # lips and lids
    X[lips] += 6e-4 * rng.standard_normal((len(lips), 3))      # pushed into each other
    acting = c.acting(X, M)
    assert acting.sum() > 10
    delta = sim._contact_projection(X, M)
    exact = pat.assemble(None, sim.contacts.blocks(X, M))
    rows = np.flatnonzero(np.abs(pat.matrix(delta, full=True)).sum(1).A1 > 0)
    ids = np.unique(np.concatenate([c.v[acting], c.tri[acting].ravel(), sim.contacts.of(EyeballContacts).terms(X, 0)[0]]))
    dof = sim.dof_of_vertex[ids[ids < sim.N]]
    touched = (3 * dof[dof >= 0, None] + np.arange(3)).ravel()
    assert len(rows) > 0 and np.isin(rows, touched).all()
    sub = lambda data: pat.matrix(data, full=True)[rows][:, rows].toarray()
    scale = np.abs(sub(exact)).max()
    assert np.linalg.eigvalsh(sub(exact)).min() < -1e-3 * scale
    assert np.linalg.eigvalsh(sub(delta)).min() > -1e-9 * scale
    assert np.linalg.eigvalsh(sub(exact + delta)).min() > -1e-9 * scale


def test_lids_slide_on_the_eyeballs(sim):
    """The lids' inner layer is free and kept outside the eyeball by its sphere contact: the
    contact's gradient and Hessian against finite differences, and pushing a lid vertex into
    the eyeball gives an outward force."""
    e = sim.contacts.of(EyeballContacts)
    X = sim.model.rest_positions
    assert len(e) > 0 and np.all(e.rest_gap == 0.0) and len(e.terms(X, 0)[0]) == 0
    assert np.all(sim.dof_of_vertex[e.v] >= 0)                      # free: they slide
    gap, n, _ = e._gap(X)
    Xp = X.copy()
    Xp[e.v] -= (gap + 3e-4)[:, None] * n                              # 0.3 mm into the eyeball
    v, E, g = e.terms(Xp, 1)
    assert len(v) == len(e) and np.all(E > 0) and np.all(np.einsum("ci,ci->c", g, n) < 0)
    rng = np.random.default_rng(7)
    Xr = Xp + 5e-5 * rng.standard_normal(X.shape)
    dX = rng.standard_normal(X.shape)
    h = 1e-9
    c = sim.contacts
    fd = (c.energy(Xr + h * dX, np.eye(4)) - c.energy(Xr - h * dX, np.eye(4))) / (2 * h)
    assert np.isclose(fd, np.sum(c.gradient(Xr, np.eye(4)) * dX), rtol=1e-5)
    dg = (c.gradient(Xr + h * dX, np.eye(4)) - c.gradient(Xr - h * dX, np.eye(4))) / (2 * h)
    Hd = np.zeros_like(X)
    for pairs, B in c.blocks(Xr, np.eye(4)):
        np.add.at(Hd, pairs[:, 0], np.einsum("pij,pj->pi", B, dX[pairs[:, 1]]))
    assert np.linalg.norm(dg - Hd) <= 1e-5 * np.linalg.norm(dg)


def test_blink_closes_one_eye_in_both_models(small_expressive_model):
    """eyeBlinkLeft closes the left fissure in the rig (the lids rotated back onto the slit) and
    the simulation follows it through the palpebral tracks; the right eye stays open.
    (Measured: the simulation closes the fissure from 9.9 to 4.0 mm on this small head, to
    1.6 mm on the default one.)"""
    m = small_expressive_model

    def fissure(x, side):
        up, lo = m.curves[f"eye_{side}_upper"], m.curves[f"eye_{side}_lower"]
        return np.linalg.norm(x[up[len(up) // 2]] - x[lo[len(lo) // 2]])

    assert fissure(m.neutral, "L") > 0.008
    for kind, closed in (("blendshape", 1e-6), ("simulation", 0.005)):
        x = m.surface({"eyeBlinkLeft": 1.0}, kind=kind)
        assert fissure(x, "L") < closed, (kind, fissure(x, "L"))
        assert fissure(x, "R") > 0.008, kind


def test_bad_activation_input(sim):
    with pytest.raises(InvfaceError, match="NaN|nan"):
        sim.solve({sim.muscle_names[0]: float("nan")})
    with pytest.raises(InvfaceError, match="outside"):
        sim.solve({sim.muscle_names[0]: 1.5})
    with pytest.raises(InvfaceError, match="unknown muscle"):
        sim.solve({"no_such_muscle": 0.5})
    with pytest.raises(InvfaceError, match="jaw"):
        sim.solve(jaw=[0, 0])


def test_bad_rest_mesh(small_model):
    import copy
    bad = copy.copy(small_model)
    tets = small_model.tets.copy()
    tets[0] = tets[0][[0, 2, 1, 3]]
    bad.tets = tets
    with pytest.raises(MeshError, match="inverted"):
        Simulator(bad)
    nm = copy.copy(small_model)
    t0 = small_model.tets[0]
    apex = np.setdiff1d(np.arange(len(small_model.rest_positions)), small_model.tets[:3].ravel())[:2]
    nm.tets = np.concatenate([small_model.tets, [[t0[0], t0[1], t0[2], apex[0]], [t0[0], t0[1], t0[2], apex[1]]]])
    with pytest.raises(MeshError, match="non-manifold"):
        Simulator(nm)


def test_template_expression_blendshapes(small_expressive_model):
    """The template's ARKit shapes move what ARKit says they move, on the side it says (Left
    is the actor's left, +X), each with the activations that calibrate its muscles' curves;
    tongueOut moves no skin."""
    m = small_expressive_model
    K = len(m.blendshape_names)
    assert m.blendshapes.shape == (K, len(m.neutral), 3)
    assert m.blendshape_activations.shape == (K, len(m.muscles))
    for name in m.blendshape_names:          # every shape moves the skin but tongueOut (the tongue only)
        moves = np.linalg.norm(m.blendshapes[m.blendshape_names.index(name)], axis=1).max()
        assert (moves == 0) if name == "tongueOut" else (moves > 1e-3), name

    def moved(name, landmark):
        k = m.blendshape_names.index(name)
        return m.blendshapes[k][m.landmarks[landmark]]

    # smile L lifts the left mouth corner more than the right one
    assert moved("mouthSmileLeft", "mouth_corner_L")[1] > 0.001
    assert moved("mouthSmileLeft", "mouth_corner_L")[1] > 3 * abs(moved("mouthSmileLeft", "mouth_corner_R")[1])
    # the frown pulls the corner down, the brow raiser lifts the brow; mouthLeft moves the mouth to +X
    assert moved("mouthFrownRight", "mouth_corner_R")[1] < -0.0005
    assert moved("browInnerUp", "brow_L")[1] > 1e-3
    assert moved("mouthLeft", "mouth_corner_L")[0] > 0.003 and moved("mouthLeft", "mouth_corner_R")[0] > 0.003
    # the zygomaticus major is what a smile engages, on its own side
    zyg = [i for i, mu in enumerate(m.muscles) if mu.name == "zygomaticus_major_L"][0]
    assert m.blendshape_activations[m.blendshape_names.index("mouthSmileLeft"), zyg] > 0.5
    assert m.blendshape_activations[m.blendshape_names.index("mouthSmileRight"), zyg] == 0
    # the lower lip's down and the jaw open separate the inner lips (with the paired jaw)
    from invface.report.expressions import blendshape_pose
    for name in ("mouthLowerDownLeft", "jawOpen"):
        x = m.surface(blendshape_pose(m, name))
        gap = x[m.curves["lip_inner_upper"], 1].mean() - x[m.curves["lip_inner_lower"], 1].mean()
        assert gap > 0.002, (name, gap)


@pytest.mark.parametrize("contacts", [False, True])
def test_newton_steps_climb_the_fallback_ladder_from_one_rung_below_the_last(contacts):
    """Newton tries its matrices least altered first: the exact Hessian, then (with contacts)
    the contact-projected one, then the Levenberg-Marquardt shifts, then the per-element
    projected matrix; the next step starts one rung below the one that worked (no failed
    factorisations of the rungs below that), and back at the exact Hessian once it works.
    With contacts, the exact Hessian is not factorised where its submatrix around the acting
    contacts is not positive definite (``_contact_region_indefinite``)."""
    from types import SimpleNamespace
    from invface.sim import linsolve

    n = 4
    H = np.diag([4.0, 3.0, 2.0, -1.0])              # needs mu >= 0.25 of diag|H| to factor
    C = np.diag([0.0, 0.0, 0.0, 0.5])               # what projecting the contacts adds: still not SPD
    P = np.diag([4.0, 3.0, 2.0, 0.5])               # the "projected" matrix
    tried, region = [], []                            # region: the contact-region test's calls
    sees = [False]                                    # whether it sees the last row (off: it never fires)

    class Dense:
        def factor(self, values):
            A = values.reshape(n, n)
            tried.append(A.copy())
            if np.linalg.eigvalsh(A).min() <= 0:
                raise linsolve.NotSPD("not SPD")
            self.A = A

        def solve(self, b):
            return np.linalg.solve(self.A, b)

    fake = SimpleNamespace(_solver=Dense(), pattern=SimpleNamespace(
                               diag_slot=np.arange(n) * (n + 1),
                               matvec=lambda v: (lambda x: v.reshape(n, n) @ x)),
                           CG_RTOL=Simulator.CG_RTOL, CG_ITER=Simulator.CG_ITER, CG_GATE=Simulator.CG_GATE,
                           EXACT_BELOW=Simulator.EXACT_BELOW,
                           force_scale=1e6,
                           contacts=object() if contacts else None,
                           SHIFTS=Simulator.SHIFTS, CONTACT_SHIFTS=Simulator.CONTACT_SHIFTS,
                           _contact_projection=lambda X, jm: C.ravel().copy(),
                           _contact_region_indefinite=lambda X, jm, v: region.append(
                               sees[0] and v.reshape(n, n)[3, 3] <= 0) or region[-1],
                           _total=lambda *a, **k: (0.0, None, P.ravel().copy()),
                           _factorisations=0, _exact_factor=-1)
    fake._ladder = lambda: Simulator._ladder(fake)
    fake._factor = lambda values: Simulator._factor(fake, values)
    fake._held_factor_step = lambda *a: Simulator._held_factor_step(fake, *a)
    fake._factored_direction = lambda *a: Simulator._factored_direction(fake, *a)
    ladder = fake._ladder()
    shifts = Simulator.CONTACT_SHIFTS if contacts else Simulator.SHIFTS
    assert ladder == [("exact", 0.0)] + ([("contacts", 0.0)] if contacts else []) \
        + [("contacts" if contacts else "exact", mu) for mu in shifts] + [("projected", 0.0)]
    g = np.ones(n)
    secs = {"factor": 0.0, "solve": 0.0, "assembly": 0.0}
    memory = [0, None]
    dx = Simulator._newton_step(fake, None, None, None, None, H.ravel().copy(), g, secs, memory)
    assert np.allclose(dx, -np.linalg.solve(P, g))
    assert len(tried) == len(ladder) and memory[0] == len(ladder) - 1
    assert fake._factorisations == len(tried) and fake._exact_factor == -1   # no exact factorisation held
    base = H + C if contacts else H
    for A, (kind, mu) in zip(tried[1:-1], ladder[1:-1]):      # mu diag|H| added to the last entry
        assert np.isclose(A[3, 3], base[3, 3] + mu)
    tried.clear()
    Simulator._newton_step(fake, None, None, None, None, H.ravel().copy(), g, secs, memory)
    assert len(tried) == 2 and np.isclose(tried[0][3, 3], base[3, 3] + shifts[-1])   # the last shift, projected
    tried.clear()
    SPD = np.diag([4.0, 3.0, 2.0, 1.0])
    Simulator._newton_step(fake, None, None, None, None, SPD.ravel().copy(), g, secs, memory)
    assert len(tried) == 1 and memory[0] == len(ladder) - 2       # the rung below worked
    for _ in range(len(ladder)):
        Simulator._newton_step(fake, None, None, None, None, SPD.ravel().copy(), g, secs, memory)
    assert memory[0] == 0                                       # back at the exact Hessian
    assert fake._exact_factor == fake._factorisations and np.allclose(memory[1], SPD.ravel())   # ... and held
    # with it held, the next steps are conjugate gradients on the new exact Hessian, no
    # factorisation, while that is within CG_GATE of the held one (0.6 % here)
    tried.clear()
    near = np.diag([4.02, 2.98, 2.01, 1.01])
    dx = Simulator._newton_step(fake, None, None, None, None, near.ravel().copy(), g, secs, memory)
    assert not tried and np.allclose(dx, -np.linalg.solve(near, g), rtol=1e-5)
    # the forcing term: the relative residual (|g| / (force scale sqrt n)) while below CG_RTOL
    fake.force_scale = 1e-6
    dx = Simulator._newton_step(fake, None, None, None, None, near.ravel().copy(), g, secs, memory)
    assert not tried and np.linalg.norm(near @ dx + g) <= Simulator.CG_RTOL * np.linalg.norm(g)
    fake.force_scale = 1e6
    # a Hessian further from the held one (3 %, as when contacts switch): a factorisation
    far = np.diag([4.1, 2.9, 2.05, 1.1])
    Simulator._newton_step(fake, None, None, None, None, far.ravel().copy(), g, secs, memory)
    assert len(tried) == 1 and np.allclose(tried[0], far)
    assert fake._exact_factor == fake._factorisations and np.allclose(memory[1], far.ravel())
    # ... and one that is not positive definite, even with no gate: the ladder, from the exact Hessian
    tried.clear()
    fake.CG_GATE = np.inf
    Simulator._newton_step(fake, None, None, None, None, H.ravel().copy(), g, secs, memory)
    assert len(tried) >= 2 and np.allclose(tried[0], H)
    # far from equilibrium (a relative residual above EXACT_BELOW) the exact Hessian is not
    # tried where there are contacts: the ladder starts at the contact-projected matrix
    tried.clear()
    fake.force_scale, memory[:] = 1e-6, [0, None]
    Simulator._newton_step(fake, None, None, None, None, SPD.ravel().copy(), g, secs, memory)
    assert np.allclose(tried[0], SPD + C if contacts else SPD) and memory[0] == int(contacts)
    # the contact-region test was asked before the exact Hessian's factorisations, with contacts only
    assert (len(region) > 0) == contacts
    # near equilibrium, a Hessian whose contact region (here its last entry) is not positive
    # definite: with contacts the test says so, and the exact Hessian is not factorised
    tried.clear(), region.clear()
    fake.force_scale, memory[:], sees[0] = 1e6, [0, None], True
    Simulator._newton_step(fake, None, None, None, None, H.ravel().copy(), g, secs, memory)
    assert np.allclose(tried[0], H + C if contacts else H)
    assert region == ([True] if contacts else [])


def test_the_contact_region_test_proves_a_newton_matrix_indefinite_near_the_contacts(sim, monkeypatch):
    """Simulator._contact_region_indefinite: the Newton matrix on the acting contacts' flesh
    vertices and CONTACT_RINGS rings around them. At an equilibrium with the lips pressed (60
    vertices in contact) it is positive definite, like the whole matrix. With one contact
    vertex's diagonal entry made negative it is not, nor is the whole matrix (the ladder then
    skips its factorisation); the same entry at the free vertex farthest from the contacts is
    outside the region: the test does not see it, the factorisation does. On this small head
    the region is over REGION_FRACTION of the DOFs: by default not tested at all."""
    from invface.sim import linsolve
    r = sim.solve({n: 0.8 for n in sim.muscle_names if n.startswith("orbicularis")})
    jm = sim.model.jaw_matrix(r.jaw)
    verts = sim.contacts.acting_vertices(r.X, jm)
    bad = r.newton_data.copy()
    bad[sim.pattern.diag_slot[3 * sim.dof_of_vertex[verts[0]]]] *= -1
    assert not sim._contact_region_indefinite(r.X, jm, bad)          # too large a region to test
    monkeypatch.setattr(sim, "REGION_FRACTION", 1.0)
    assert len(verts) > 10 and not sim._contact_region_indefinite(r.X, jm, r.newton_data)
    solver = sim.make_solver()
    solver.factor(r.newton_data)
    dist = np.linalg.norm(r.X[:, None] - r.X[verts][None], axis=2).min(1)
    free = sim.dof_of_vertex >= 0
    for vertex, seen in ((verts[0], True), (int(np.argmax(np.where(free, dist, -1))), False)):
        bad = r.newton_data.copy()
        bad[sim.pattern.diag_slot[3 * sim.dof_of_vertex[vertex]]] *= -1
        assert sim._contact_region_indefinite(r.X, jm, bad) == seen
        with pytest.raises(linsolve.NotSPD):
            solver.factor(bad)


def test_preconditioned_cg_solves_with_a_nearby_factorisation_and_refuses_indefinite_matrices():
    """The adjoint's conjugate gradients (sim.linsolve.preconditioned_cg): preconditioned by the
    factorisation of a matrix 1 % away, they reach rtol 1e-12 in a few iterations, with no
    back-substitution after the residual that meets rtol (k iterations: k + 1 of them); on an
    indefinite matrix, or when the iterations run out, they return None."""
    import scipy.sparse as sps
    n = 200
    A = sps.random(n, n, 0.03, random_state=2)
    A = (A + A.T + 6 * sps.eye(n)).tocsr()
    near = (A + 0.01 * sps.diags(np.random.default_rng(1).uniform(-1, 1, n)) @ A).toarray()
    near = 0.5 * (near + near.T)
    calls = []

    def precondition(r):
        calls.append(1)
        return np.linalg.solve(near, r)

    b = np.random.default_rng(0).standard_normal(n)
    x = linsolve.preconditioned_cg(lambda v: A @ v, precondition, b, rtol=1e-12)
    assert np.linalg.norm(A @ x - b) <= 1e-12 * np.linalg.norm(b) and len(calls) <= 8
    k = len(calls) - 1                          # the iterations it took
    assert linsolve.preconditioned_cg(lambda v: A @ v, precondition, b, rtol=1e-12, max_iter=k) is not None
    assert linsolve.preconditioned_cg(lambda v: A @ v, precondition, b, rtol=1e-12, max_iter=k - 1) is None
    assert linsolve.preconditioned_cg(lambda v: -(A @ v), precondition, b) is None
    assert linsolve.preconditioned_cg(lambda v: A @ v, lambda r: r, b, max_iter=2) is None


@pytest.mark.skipif("pardiso" not in linsolve.available(), reason="MKL PARDISO not installed")
def test_pardiso_is_found_from_the_mkl_wheel_without_pypardisos_search():
    """pypardiso globs the whole prefix for MKL's library, once on import and once per
    PyPardisoSolver (1.2 s per process here, every CLI call and Dask worker); the library is
    found from the mkl wheel's file list instead, and pypardiso is never imported."""
    import subprocess
    import sys
    code = ("import sys; from invface.sim import linsolve; linsolve._pardiso_function(); "
            "print(linsolve.available()[0], 'pypardiso' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.split() == ["pardiso", "False"]


@pytest.mark.parametrize("name", linsolve.available())
def test_solvers_solve_and_refuse_a_matrix_that_is_not_positive_definite(name):
    """Newton's fallbacks hang on NotSPD: each solver solves an SPD matrix (several right-hand
    sides), refuses the same matrix shifted indefinite, and factors the SPD one again after;
    a second solver of the pattern (PARDISO: with the first one's ordering) solves the same."""
    import scipy.sparse as sps
    n = 300
    A = sps.random(n, n, 0.02, random_state=1)
    A = (A + A.T + 5 * sps.eye(n)).tocsr()
    P = linsolve.MatrixPattern(A)
    solver = linsolve.make_solver(P, name)
    b = np.random.default_rng(0).standard_normal((n, 3))
    solver.factor(P.values(A))
    x = solver.solve(b)
    assert np.abs(A @ x - b).max() < 1e-10
    with pytest.raises(linsolve.NotSPD):
        solver.factor(P.values(A - 20 * sps.eye(n)))
    solver.factor(P.values(A))
    assert np.abs(solver.solve(b) - x).max() < 1e-10
    assert name != "pardiso" or len(P.pardiso_perm) == n
    second = linsolve.make_solver(P, name)
    second.factor(P.values(A))
    assert np.abs(second.solve(b) - x).max() < 1e-10


def test_contact_gates_do_not_narrow_below_the_minimum_radius(small_model, monkeypatch):
    """Contacts pair and gate over 1.5 tet edges, but never less than MIN_CONTACT_RADIUS (a
    refined mesh's edges would narrow them): with the minimum set above 1.5 edges of the small
    model, every pair's gate reaches the minimum, and the pairs are a superset of those 1.5
    edges find."""
    from invface.sim import quasistatic
    from invface.sim.contact import MIN_CONTACT_RADIUS

    narrow = Simulator(small_model)
    assert narrow.contacts.of(TriangleContacts).radius == pytest.approx(1.5 * narrow.edge_length)
    assert narrow.contacts.of(TriangleContacts).radius > MIN_CONTACT_RADIUS
    wide_radius = 2.0 * narrow.contacts.of(TriangleContacts).radius
    monkeypatch.setattr(quasistatic, "MIN_CONTACT_RADIUS", wide_radius)
    wide = Simulator(small_model)
    assert wide.contacts.of(TriangleContacts).radius == wide_radius
    assert np.all(wide.contacts.of(TriangleContacts).reach[:, 1] == wide_radius)
    pairs = lambda c: set(zip(c.v.tolist(), map(tuple, c.tri.tolist())))
    assert len(wide.contacts.of(TriangleContacts)) > len(narrow.contacts.of(TriangleContacts))
    assert pairs(narrow.contacts.of(TriangleContacts)) <= pairs(wide.contacts.of(TriangleContacts))


def test_simulator_refuses_material_constants_without_a_finite_rest_energy(small_model):
    """A NaN material constant is named at set-up, not met as NaN residuals in the first solve."""
    with pytest.raises(InvfaceError, match="material constants"):
        Simulator(small_model, material=materials.Material(mu10=float("nan")))
