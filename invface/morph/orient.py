"""Orientation and symmetry of a target face (paper 001 sec. 5).

1. Axes from the inertia tensor of the surface as a thin shell (mass = area).
2. The left/right symmetry plane: of the three planes through the centre of mass normal to
   an axis, the one with the least reflection error (mean distance from each reflected point
   to the closest point on the mesh). A head about as deep as it is wide has two nearly equal
   moments, and its axes in their plane are arbitrary: the plane of those two axes is also
   searched (``symmetry_normal``), and a direction there that reflects far better wins.
3. The profile curve (mesh ∩ symmetry plane); nose-tip candidates are the local maxima of
   the distance from the centre of mass that stick out of the profile on both sides (bridge
   above, subnasale below) as a wedge, the sharpest ones first. The paper takes the best
   one; on busts a crown's rim or the cut base can be sharper than the nose, so the
   candidates are kept and step 5 chooses.
4. Refinement of the plane's three free parameters (two tilts, one offset) on the nose and
   cheek region only (within 6 cm of the nose tip's height, 7.5 cm behind it).

5. Up/down: the frame leaves the sign of "up" open (both signs give a valid right-handed
   frame). Each nose candidate with each sign is mapped onto the template through the
   template's own frame and refined by trimmed rigid ICP on the face around the nose; the
   candidate that fits the template best wins, among those where the template's face also
   lies on the scan (``best_pose``). This replaces the paper's nose-shape scores
   for the sign, which the generated template's blunt nose does not follow. A scan in several
   large pieces (a head beside its stand) also gets each piece's own frames. The winning ICP
   pose is the rigid part of ``model.scan_transform``.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from ..errors import MeshError
from ..mesh.closest import TriangleLocator, barycentric_points
from ..mesh.sections import arc_length, plane_sections, resample
from ..mesh.triangles import edge_components, triangle_areas

NOSE_ARC = 0.015         # m along the profile either side of a nose-tip candidate
MAX_NOSE_ANGLE_DEG = 150      # a blunt or hole-broken nose still counts; the template alignment chooses
NOSE_CANDIDATES = 8      # profile wedges tried as the nose tip
FULL_ICP = 3             # of the candidate poses after a quick ICP, the best refined fully
SYMMETRY_STEP_DEG = 10   # the symmetry plane's normal is searched this many degrees apart ...
SYMMETRY_SCAN_SAMPLES = 300   # ... on this many samples, and taken over the inertia axis ...
SYMMETRY_GAIN = 0.8      # ... when its reflection error is below this share of the axis's
HEAD_REACH = 0.12        # m: the head around a nose tip (its centroid sets "forward")
REFINE_HEIGHT = 0.06     # m: the symmetry plane is refined on the nose and cheeks, this far
REFINE_DEPTH = 0.075     # above/below and behind the nose tip; their reflections are measured
REFINE_REACH = 0.03      # against the scan's triangles this much farther out
FACE_COVER = 0.06        # m: the template's skin this near its nose tip must lie on the scan ...
COVER_SAMPLES = 600      # ... measured on this many of its vertices, by the 90th percentile
COVER_GAIN = 1.5         # of their distances: a pose this many times the best pose's is not the face's


@dataclass
class Frame:
    """A face frame: origin (3,) (a point on the symmetry plane), rotation R (3,3) whose rows
    are the model axes X (left), Y (up), Z (forward) in target coordinates, nose tip (3,),
    symmetry error (m, mean) and the profile polyline (n,3), all in target coordinates."""
    origin: np.ndarray
    R: np.ndarray
    nose_tip: np.ndarray
    symmetry_error: float
    profile: np.ndarray


def shell_inertia(V, F):
    """Centre of mass (3,) and inertia tensor (3,3) of the surface as a thin shell of unit
    areal density (triangle masses at their centroids plus their own second moments)."""
    tri = V[F]
    area = triangle_areas(V, F)
    c = np.average(tri.mean(1), axis=0, weights=area)
    r = tri - c
    # second moment of a triangle with uniform density: A/12 (sum r_i r_i^T + (sum r_i)(sum r_i)^T)
    s = r.sum(1)
    C = np.einsum("t,tij->ij", area / 12, np.einsum("tki,tkj->tij", r, r) + np.einsum("ti,tj->tij", s, s))
    return c, np.trace(C) * np.eye(3) - C


def symmetry_error(mesh, samples, origin, normal):
    """Mean distance (m) from the reflections of samples (n,3) across the plane to the mesh
    (a ``TriangleLocator``)."""
    n = normal / np.linalg.norm(normal)
    refl = samples - 2 * ((samples - origin) @ n)[:, None] * n
    return float(mesh.closest(refl)[2].mean())


def _samples(V, n, seed=0):
    rng = np.random.default_rng(seed)
    return V[rng.choice(len(V), size=min(n, len(V)), replace=False)]


def _profile(V, F, origin, normal, near):
    """The profile polyline: the plane section chain passing nearest ``near`` (3,)."""
    chains = plane_sections(V, F, origin, normal)
    if not chains:
        raise MeshError("the symmetry plane does not cut the mesh: is this a face?")
    d = [np.linalg.norm(c.points - near, axis=1).min() for c in chains]
    return chains[int(np.argmin(d))].points


def _nose_scores(P, c):
    """Nose-tip candidates on profile P (n,3): list of (id, angle (rad)).

    A candidate is a local maximum of |P - c| (over +-5 mm of arc) that points away from c.
    Its angle is the opening angle of the triangle bridge-tip-base formed with the profile
    points NOSE_ARC either side: a nose is a wedge (about 90-110 degrees), a chin, lips or
    the top of the head are rounder.
    """
    s = arc_length(P)
    r = np.linalg.norm(P - c, axis=1)
    out = []
    for i in range(len(P)):
        if s[i] < NOSE_ARC or s[i] > s[-1] - NOSE_ARC:
            continue
        win = np.abs(s - s[i]) <= 0.005
        if r[i] < r[win].max():
            continue
        u = resample(P, s[i] + np.array([-NOSE_ARC, NOSE_ARC]), s) - P[i]
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        bis = -(u[0] + u[1])
        if np.linalg.norm(bis) < 1e-9 or bis @ (P[i] - c) <= 0:
            continue
        bis /= np.linalg.norm(bis)
        angle = float(np.arccos(np.clip(u[0] @ u[1], -1, 1)))
        out.append((i, angle))
    return out


def _walks(ch):
    """The points of a plane section ``ch`` (mesh.sections.Section) as walks to score: the
    chain, and for a closed loop also the loop started half-way round. ``_nose_scores`` skips
    the points within NOSE_ARC of a walk's ends, and where a loop starts depends on how the
    scan is turned: a loop that started at the nose tip lost the nose."""
    if not ch.closed:
        return [ch.points]
    P = np.roll(ch.points[:-1], (len(ch.points) - 1) // 2, axis=0)
    return [ch.points, np.r_[P, P[:1]]]


def _face_frame(V, F, c, n_sym, err, tip, refine, n_samples, cen, area):
    """The Frame whose nose tip is ``tip`` (3,) on the profile of the plane (c, n_sym); cen
    (f,3), area (f,): the triangles' centroids and areas."""
    # forward: from the centroid of the head around the tip (a bust's or a torso's centre of
    # mass lies low in the chest, and its direction to the nose tip would tilt the face up)
    head = np.linalg.norm(cen - tip, axis=1) < HEAD_REACH
    ch = np.average(cen[head], axis=0, weights=area[head]) if area[head].sum() > 0 else c
    f = tip - ch
    f -= (f @ n_sym) * n_sym
    f /= np.linalg.norm(f)
    y = np.cross(n_sym, f)          # up or down: decided by the template alignment
    z = np.cross(y, np.cross(f, y))
    z /= np.linalg.norm(z)
    x = np.cross(y, z)
    R = np.stack([x, y, z])
    origin = c - ((c - tip) @ x) * x         # on the plane
    P = _profile(V, F, origin, x, near=tip)
    fr = Frame(origin, R, tip, err, P)
    return refine_frame(V, F, fr, c, n_samples) if refine else fr


def refine_frame(V, F, fr, c, n_samples=1500):
    """The Frame ``fr`` with its symmetry plane refined (two tilts, one offset) on the nose and
    cheeks: within REFINE_HEIGHT of the tip's height and REFINE_DEPTH behind it (c: the
    centre of mass, which stays on the plane)."""
    origin, R, tip, err, P = fr.origin, fr.R, fr.nose_tip, fr.symmetry_error, fr.profile
    L = (V - origin) @ R.T
    tipL = (tip - origin) @ R.T
    keep = (L[:, 2] > tipL[2] - REFINE_DEPTH) & (np.abs(L[:, 1] - tipL[1]) < REFINE_HEIGHT)
    region = V[keep]
    if len(region) > 50:
        region = _samples(region, n_samples, seed=1)
        # the reflections stay near the region: measured against the triangles around it
        Lc = (V[F].mean(1) - origin) @ R.T
        Fr = F[(Lc[:, 2] > tipL[2] - REFINE_DEPTH - REFINE_REACH) & (np.abs(Lc[:, 1] - tipL[1]) < REFINE_HEIGHT
                                                                      + REFINE_REACH)]

        def plane(q):
            a, b, d = q
            n = R[0] + a * R[1] + b * R[2]
            return origin + d * R[0], n / np.linalg.norm(n)

        mesh = TriangleLocator(V, Fr)
        res = minimize(lambda q: symmetry_error(mesh, region, *plane(q)), np.zeros(3),
                       method="Nelder-Mead",
                       options={"xatol": 1e-4, "fatol": 1e-7, "initial_simplex":
                                np.array([[0, 0, 0], [0.05, 0, 0], [0, 0.05, 0], [0, 0, 0.005]])})
        o2, n2 = plane(res.x)
        x = n2
        y = R[1] - (R[1] @ x) * x
        y /= np.linalg.norm(y)
        z = np.cross(x, y)
        R = np.stack([x, y, z])
        origin = c - ((c - o2) @ x) * x
        err = float(res.fun)
        P = _profile(V, F, origin, x, near=tip)
        # the tip: the most forward profile point near the old tip
        near = np.linalg.norm(P - tip, axis=1) < 0.02
        cand = np.flatnonzero(near) if near.any() else np.arange(len(P))
        tip = P[cand[np.argmax((P[cand] - origin) @ z)]]
    return Frame(origin, R, tip, err, P)


def symmetry_normal(mesh, samples, c, moments, axes, step=SYMMETRY_STEP_DEG):
    """The normal (3,) of the left/right symmetry plane through ``c`` and its reflection error
    (m) of ``samples`` onto the mesh (a ``TriangleLocator``): the inertia axis (``axes`` (3, 3)
    columns, ``moments`` ascending) with the least error, as the paper takes it, unless a
    direction in the plane of the two axes of nearest moments has a reflection error below
    SYMMETRY_GAIN of that axis's. A head about as deep as it is wide has two nearly equal moments,
    and its axes in their plane are arbitrary: the inertia alone can tilt the plane off the
    nose. That plane is searched every ``step`` degrees on a few samples, then a degree apart
    around the best."""
    errs = [symmetry_error(mesh, samples, c, axes[:, k]) for k in range(3)]
    best = int(np.argmin(errs))
    i = int(np.argmin(np.diff(moments) / moments[1:]))          # the pair (i, i + 1) nearest in moment
    a, b = axes[:, i], axes[:, i + 1]
    few = samples[:SYMMETRY_SCAN_SAMPLES]

    def scan(degrees, points):
        return [(symmetry_error(mesh, points, c, np.cos(t) * a + np.sin(t) * b), t) for t in np.radians(degrees)]

    coarse_err, t = min(scan(np.arange(0, 180, step), few))
    if coarse_err >= SYMMETRY_GAIN * symmetry_error(mesh, few, c, axes[:, best]):
        return axes[:, best], errs[best]
    err, t = min(scan(np.degrees(t) + np.arange(1 - step, step), samples))
    return np.cos(t) * a + np.sin(t) * b, err


def find_frames(V, F, n_samples=1500, refine=True, candidates=NOSE_CANDIDATES):
    """Face frames of a cleaned mesh in metres (V (n,3), F (f,3)), one per nose-tip candidate
    (the ``candidates`` sharpest wedges of the profile, sharpest first). Raises MeshError when
    no nose-like feature is found (the mesh is not a face).

    The sharpest wedge is not always the nose: a bust's base, a crown's rim or a cut-off
    shoulder can be sharper, so ``align_to_template`` lets the template's face choose."""
    c, inertia = shell_inertia(V, F)
    moments, axes = np.linalg.eigh(inertia)
    n_sym, err = symmetry_normal(TriangleLocator(V, F), _samples(V, n_samples), c, moments, axes)

    chains = plane_sections(V, F, c, n_sym)
    if not chains:
        raise MeshError("the symmetry plane does not cut the mesh: is this a face?")
    # every piece of the profile (a bust's stand or a second piece has its own), with the
    # nose seen from the centre of mass and from the piece's own centre (a torso's centre of
    # mass lies so far below a head that the nose is no maximum of the distance from it)
    found = {}
    for ch in chains:
        if len(ch.points) > 4:
            for P in _walks(ch):
                for centre in (c, ch.points.mean(0)):
                    for i, a in _nose_scores(P, centre):
                        key = tuple(np.round(P[i], 6))
                        found[key] = min(a, found.get(key, np.inf))
    cands = sorted(((np.array(k), a) for k, a in found.items()), key=lambda t: t[1])
    if not cands:
        raise MeshError("no nose found on the profile curve: the mesh does not look like a face")
    if cands[0][1] > np.radians(MAX_NOSE_ANGLE_DEG):
        raise MeshError(f"no nose found: the sharpest point of the profile opens {np.degrees(cands[0][1]):.0f} "
                        f"degrees (a nose tip: under {MAX_NOSE_ANGLE_DEG} degrees); the mesh does not look like a face")
    tips = [p for p, a in cands if a <= np.radians(MAX_NOSE_ANGLE_DEG)][:candidates]
    cen, area = V[F].mean(1), triangle_areas(V, F)
    return [_face_frame(V, F, c, n_sym, err, tip, refine, n_samples, cen, area) for tip in tips]


def find_frame(V, F, n_samples=1500, refine=True):
    """The face frame of the sharpest nose-tip candidate (``find_frames``)."""
    return find_frames(V, F, n_samples, refine, candidates=1)[0]


@dataclass
class Alignment:
    """Rigid map of target metres into the model frame: x_model = R @ x + t. residual: the
    median distance (m) from the target's face samples to the template after ICP; frame:
    the target's Frame; flipped_residual: the next best candidate's (another nose tip or the
    other up/down sign); uncovered: the 90th percentile of the distances (m) from the template's
    face (its skin within FACE_COVER of the nose tip) to the target, the other way round."""
    R: np.ndarray
    t: np.ndarray
    residual: float
    frame: Frame
    flipped_residual: float
    uncovered: float

    def apply(self, P):
        return np.asarray(P) @ self.R.T + self.t


def kabsch(A, B, w=None, scale=False):
    """Rotation R (times a uniform scale when ``scale``; Umeyama), translation t minimising
    sum w |R A + t - B|^2 (A, B (n,3), w (n,))."""
    w = np.ones(len(A)) if w is None else w
    ca, cb = np.average(A, axis=0, weights=w), np.average(B, axis=0, weights=w)
    U, S, Vt = np.linalg.svd((w[:, None] * (A - ca)).T @ (B - cb))
    D = np.diag([1, 1, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    if scale:
        R *= (S * np.diag(D)).sum() / (w * ((A - ca) ** 2).sum(axis=1)).sum()
    return R, cb - R @ ca


def rigid_icp(P, V, F, R, t, iters=20, trim=2.5, weights=None, scale=False):
    """Trimmed point-to-surface rigid ICP of points P (n,3) onto the mesh (V, F), from R, t.
    Pairs farther than ``trim`` x the median distance are dropped; weights (n,) optional.
    With ``scale`` R also carries a uniform scale (similarity ICP).
    Returns R, t, median distance (m)."""
    med = np.inf
    weights = np.ones(len(P)) if weights is None else weights
    mesh = TriangleLocator(V, F)
    for _ in range(iters):
        Q = P @ R.T + t
        tri, w, d = mesh.closest(Q)
        med = float(np.median(d))
        keep = d <= trim * med + 1e-9
        C = barycentric_points(V, F, tri, w)
        dR, dt = kabsch(Q[keep], C[keep], weights[keep], scale)
        R, t = dR @ R, dR @ t + dt
        if np.linalg.norm(dR - np.eye(3)) < 1e-6 and np.linalg.norm(dt) < 1e-7:
            break
    return R, t, med


_TEMPLATE_FRAMES = {}
_TEMPLATE_FACES = {}


def template_frame(model):
    """The Frame of the template's own skin (cached per model object)."""
    key = id(model)
    if key not in _TEMPLATE_FRAMES:
        _TEMPLATE_FRAMES[key] = find_frame(model.neutral, model.triangles)
    return _TEMPLATE_FRAMES[key]


def template_face(model):
    """COVER_SAMPLES of the template's skin vertices (k,3) within FACE_COVER of its nose tip
    (cached per model object)."""
    key = id(model)
    if key not in _TEMPLATE_FACES:
        V = model.neutral
        ids = np.flatnonzero(np.linalg.norm(V - V[model.landmarks["nose_tip"]], axis=1) < FACE_COVER)
        _TEMPLATE_FACES[key] = V[np.random.default_rng(4).permutation(ids)[:COVER_SAMPLES]]
    return _TEMPLATE_FACES[key]


def uncovered(mesh, face, R, t):
    """The 90th percentile of the distances (m) from the template's face points (k,3, model
    frame) to the target (a ``TriangleLocator`` in target coordinates) under the pose
    x_model = R x + t: where the template's nose or lips stand over nothing, it is centimetres."""
    return float(np.percentile(mesh.closest((face - t) @ R)[2], 90))


def best_pose(residuals, uncovereds, n=1):
    """Indices of the ``n`` poses of least residual among those whose uncovered (each (k,), m)
    is within COVER_GAIN times the least: the scan's samples close to the template and the
    template's face on the scan. The residual alone lets a smooth region (the side of a head,
    a torso) lie on the template's cheeks and forehead as closely as a face does; the
    template's nose then stands over nothing."""
    r, u = np.asarray(residuals, float), np.asarray(uncovereds, float)
    ok = np.flatnonzero(u <= COVER_GAIN * u.min())
    return ok[np.argsort(r[ok])][:n]


def _piece_frames(V, F, share=0.02):
    """Unrefined Frames of the whole mesh and, when it has several large pieces (at least
    ``share`` of the largest's area: a head beside its stand or a second scan piece), of each
    piece on its own, whose symmetry plane the others do not tilt. Raises the first piece's
    MeshError when none has a nose."""
    comp = edge_components(F[:, [0, 1, 1, 2]], len(V))[F[:, 0]]
    area = np.bincount(comp, weights=triangle_areas(V, F))
    big = np.flatnonzero(area >= share * area.max())
    meshes = [F] + ([F[comp == k] for k in big] if len(big) > 1 else [])
    frames, error = [], None
    for Fk in meshes:
        try:
            frames += find_frames(V, Fk, refine=False)
        except MeshError as e:
            error = error or e
    if not frames:
        raise error
    return frames


def align_to_template(V, F, model, radius=0.09, n_samples=2000, quick=8):
    """Rigid alignment of a cleaned target (V (n,3) m, F) onto the template ``model``.

    For each of the target's Frames (``find_frames``: symmetry plane, a nose-tip candidate)
    and both up/down signs, the target points within ``radius`` of the nose tip are mapped
    through the template's frame and refined by ``quick`` ICP iterations; the FULL_ICP best
    poses are refined to convergence, and the best of those wins; its frame's symmetry plane
    is refined (``refine_frame``).

    Poses are chosen by ``best_pose``: the scan's samples to the template and the template's
    face to the scan.
    """
    tf = template_frame(model)
    mesh, face = TriangleLocator(V, F), template_face(model)

    def scored(P, R, t, iters):
        R, t, med = rigid_icp(P, model.neutral, model.triangles, R, t, iters=iters)
        return R, t, med, uncovered(mesh, face, R, t)

    trials = []
    for fr in _piece_frames(V, F):
        near = V[np.linalg.norm(V - fr.nose_tip, axis=1) < radius]
        P = _samples(near, n_samples, seed=2)
        for sg in (1, -1):
            Rt = np.diag([sg, sg, 1.0]) @ fr.R           # flip up (and left, to stay right-handed)
            # target -> frame coords (origin at the nose tip) -> template coords
            R0 = tf.R.T @ Rt
            t0 = tf.nose_tip - R0 @ fr.nose_tip
            trials.append((scored(P, R0, t0, quick), fr, P))
    order = best_pose([tr[0][2] for tr in trials], [tr[0][3] for tr in trials], FULL_ICP)
    full = [(scored(trials[k][2], *trials[k][0][:2], 20), trials[k][1]) for k in order]
    k = best_pose([f[0][2] for f in full], [f[0][3] for f in full])[0]
    (R, t, med, uncov), fr = full[k]
    fr = refine_frame(V, F, fr, shell_inertia(V, F)[0])
    nxt = min((f[0][2] for i, f in enumerate(full) if i != k), default=np.inf)
    return Alignment(R, t, med, fr, nxt, uncov)
