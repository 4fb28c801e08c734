"""Fitting the face to a 3D scan: paper 000, Eq. 13.

    min_{w, theta, t}  || F* - x_R(w) ||^2 + lambda || w ||^2,   x_R = R(theta) x(w) + t

x(w) is either model (``FaceModel.surface_model(kind)``: the blendshape rig or the
blendshape-driven muscle simulation); its Jacobian comes from the rig's analytic derivative
or the simulation's tangent solves, and the solver is the box-constrained dogleg
(``dogleg.py``), blendshape weights in [0, 1]. lambda = 1e-6 as in the paper.

Two correspondence modes:

- ``correspondence``: the scan shares the model's topology (vertex count and order), as in
  the paper; residuals are the vertex differences.
- ``nearest``: any topology, symmetric point-to-plane ICP. Each model vertex is paired with
  its closest scan point (residual n . (x_R - y) along the scan normal) and each scan vertex
  with its closest model point (residual along the model normal there): the second set pulls
  model parts toward scan parts that no model vertex sees yet (a jaw opened by centimetres).
  Pairs that land on the other mesh's open boundary, or farther than the gate, are dropped;
  the gate starts at ``start_distance`` and halves each round down to ``max_distance``; pairs
  are refreshed between dogleg rounds until they stop changing. ICP only sees the scan within
  its gate, and a jaw opened by centimetres stalls it part way open (ICT-FaceKit's jawOpen:
  0.08 rad of the scan's 0.3). So, unless a start ``p0`` is given, the jaw's opening starts
  at the best of a coarse search: the hinge angle whose blendshape-rig surface has the least
  symmetric distance to the scan, each distance capped at ``max_distance``.
"""
from __future__ import annotations

import time
from contextlib import nullcontext
from dataclasses import dataclass, field

import numpy as np

from ..errors import InvfaceError
from ..mesh.closest import barycentric_points, closest_points
from ..mesh.triangles import boundary_vertices, face_normals
from ..model.controls import FitVector
from ..model.rig import JAW_LOWER, JAW_UPPER
from .dogleg import dogleg
from .lambdas import EQ13_LAMBDA
from ..model.pose import posed_jacobian, posed_surface
from .priors import regulariser
from .results import NamedControls, write_fit_files


@dataclass
class ScanFit(NamedControls):
    """Result: parameters p = (b, jaw), rigid pose, surfaces, per-vertex error, the log."""

    vector: FitVector
    p: np.ndarray
    rotation: np.ndarray
    translation: np.ndarray
    surface: np.ndarray            # x_R (V, 3) m, posed
    error: np.ndarray              # (V,) m: distance to the scan (NaN where unpaired)
    kind: str
    history: list = field(default_factory=list)
    status: str = ""
    activations: dict = field(default_factory=dict)   # muscle -> activation (simulation fits)
    seconds: float = 0.0

    def summary(self):
        """JSON-ready dict: weights by name, jaw, pose, activations, error statistics in mm."""
        e = self.error[np.isfinite(self.error)] * 1000
        return {"kind": self.kind, "status": self.status, "iterations": len(self.history),
                **self.vector.to_dict(self.z),
                "nonzero_weights": int(np.sum(self.p[self.vector.weights] > 1e-3)),
                "activations": {k: round(v, 6) for k, v in self.activations.items()},
                "error_mm": {"median": float(np.median(e)), "mean": float(e.mean()),
                             "max": float(e.max())}}


class _Objective:
    """z = (p, theta (3,), t (3,)) (``FitVector``) -> residual and Jacobian of Eq. 13."""

    def __init__(self, surface_model, lam, vec):
        self.sm, self.lam, self.vec = surface_model, lam, vec
        self.pairs = None                  # (vertex ids, scan points, scan normals) in nearest mode
        self.back = None                   # (model triangles' vertex ids, barycentrics, scan points, model normals)

    def posed(self, z):
        return posed_surface(self.sm, z, self.vec)

    def __call__(self, z, target=None):
        xr, Jall = posed_jacobian(self.sm, z, self.vec)
        if self.pairs is None:
            r = (xr - target).ravel()
            J = Jall.reshape(len(Jall), -1).T
        else:
            vid, y, n = self.pairs
            r = np.einsum("ij,ij->i", xr[vid] - y, n)
            J = np.einsum("kij,ij->ik", Jall[:, vid], n)
            if self.back is not None and len(self.back[0]):
                tv, b, yb, nb = self.back
                rb = np.einsum("ij,ij->i", np.einsum("ia,iaj->ij", b, xr[tv]) - yb, nb)
                Jb = sum(b[:, a, None] * np.einsum("kij,ij->ik", Jall[:, tv[:, a]], nb) for a in range(3))
                r, J = np.r_[r, rb], np.vstack([J, Jb])
        reg, Jreg = regulariser(z, self.vec, self.lam)
        return np.r_[r, reg], np.vstack([J, Jreg])


JAW_SEARCH = np.arange(0.0, JAW_UPPER[0] + 1e-9, 0.1)     # rad: hinge openings tried, then +-0.05


def capped_distance(model_surface, triangles, scan, scan_faces, cap, model_border, scan_border):
    """Symmetric nearest-point distance (m^2) between a posed model surface (V,3) and a scan
    (S,3): the squared distance from each model vertex to the scan plus that from each scan
    vertex to the model, each capped at ``cap`` (m), pairs landing on the other mesh's open
    boundary left out."""
    q, _, _, _, edge = _closest(scan, scan_faces, model_surface, scan_border)
    qb, _, _, _, edgeb = _closest(model_surface, triangles, scan, model_border)
    d = np.r_[np.linalg.norm(model_surface - q, axis=1)[~edge],
              np.linalg.norm(scan - qb, axis=1)[~edgeb]]
    return float(np.sum(np.minimum(d, cap) ** 2))


def search_jaw(model, z, scan, scan_faces, cap, model_border, scan_border):
    """The hinge opening (rad) for z = (p, theta, t) that brings the blendshape rig closest to
    the scan (``capped_distance``): JAW_SEARCH, then +-0.05 rad about the best."""
    sm, vec = model.surface_model("blendshape"), FitVector.of(model)

    def cost(h):
        return capped_distance(posed_surface(sm, vec.with_hinge(z, h), vec)[1], model.triangles, scan,
                               scan_faces, cap, model_border, scan_border)

    costs = {float(h): cost(h) for h in JAW_SEARCH}
    best = min(costs, key=costs.get)
    for h in (best - 0.05, best + 0.05):
        if JAW_LOWER[0] <= h <= JAW_UPPER[0]:
            costs[h] = cost(h)
    return min(costs, key=costs.get)


def _closest(V, F, points, border=None):
    """Closest points (N,3) on the mesh (V, F), its unit face normals there (N,3), the
    triangles (N,) and barycentrics (N,3), and whether each lies on an open boundary edge
    (N,) (``border``: boolean (n,) of the mesh's boundary vertices)."""
    tri, bary, _ = closest_points(points, V, F)
    q = barycentric_points(V, F, tri, bary)
    n = face_normals(V, F[tri])
    edge = np.zeros(len(points), bool) if border is None else (border[F[tri]] | (bary < 1e-9)).all(1)
    return q, n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-30), tri, bary, edge


def fit_scan(model, scan_vertices, scan_faces=None, kind="blendshape", mode="correspondence",
             lam=EQ13_LAMBDA, p0=None, rotation=None, translation=None, max_iter=50,
             max_distance=0.01, start_distance=0.03, rounds=8, progress=None):
    """Fit controls and rigid pose of ``model`` to a scan (metres). Returns a ScanFit.

    scan_vertices (S,3); scan_faces (G,3) (needed in ``nearest`` mode); kind: "blendshape"
    or "simulation"; p0 (K+6,) start (default neutral, in nearest mode with
    the jaw opening from ``search_jaw``); rotation/translation: start pose."""
    t0 = time.perf_counter()
    S = np.asarray(scan_vertices, float)
    V = len(model.neutral)
    if mode not in ("correspondence", "nearest"):
        raise InvfaceError(f"unknown correspondence mode '{mode}': use 'correspondence' or 'nearest'")
    if not np.all(np.isfinite(S)):
        raise InvfaceError("scan has non-finite vertex positions")
    if mode == "correspondence" and S.shape != (V, 3):
        raise InvfaceError(f"scan has {len(S)} vertices but the model has {V}: correspondence mode "
                           "needs the model's topology; use --mode nearest for other meshes")
    if mode == "nearest" and scan_faces is None:
        raise InvfaceError("nearest mode needs the scan's triangles")
    sm, vec = model.surface_model(kind), FitVector.of(model)
    z = vec.pack(p0, rotation, translation)
    lo, hi = vec.bounds()
    obj = _Objective(sm, lam, vec)
    history = []

    if mode == "correspondence":
        # every solve cold, from rest: the surface is a function of the controls alone, as
        # the scan's (a warm start from a smile found another lip contact state). Nearest
        # mode keeps warm starts from the last solve: anchoring each round at its start
        # state makes a fit several times slower for a negligible gain, and its pairs change
        # every round anyway.
        with sm.starting_from("rest") if kind == "simulation" else nullcontext():
            res = dogleg(lambda zz: obj(zz, S), z, lo, hi, max_iter=max_iter, progress=progress)
        z, history, status = res.x, res.history, res.status
    else:
        F, Fm = np.asarray(scan_faces), model.triangles
        scan_border, model_border = boundary_vertices(F, len(S)), boundary_vertices(Fm, V)
        if p0 is None:
            z = vec.with_hinge(z, search_jaw(model, z, S, F, max_distance, model_border, scan_border))
        status, last = "rounds", None
        for rnd in range(rounds):
            gate = max(max_distance, start_distance * 0.5 ** rnd)
            _, xr = obj.posed(z)
            q, n, tri, _, edge = _closest(S, F, xr, scan_border)
            vid = np.flatnonzero((np.linalg.norm(xr - q, axis=1) < gate) & ~edge)
            if len(vid) < 20:
                raise InvfaceError(f"only {len(vid)} model vertices lie within {gate * 1000:.0f} mm "
                                   "of the scan: align the scan to the model first (metres, +Y up, +Z front)")
            obj.pairs = (vid, q[vid], n[vid])
            qb, nb, trib, bb, edgeb = _closest(xr, Fm, S, model_border)
            sid = np.flatnonzero((np.linalg.norm(S - qb, axis=1) < gate) & ~edgeb)
            obj.back = (Fm[trib[sid]], bb[sid], S[sid], nb[sid])
            res = dogleg(obj, z, lo, hi, max_iter=max_iter, progress=progress)
            z = res.x
            history += [dict(h, round=rnd) for h in res.history]
            key = np.r_[tri[vid], trib[sid]]
            if (gate == max_distance and last is not None and len(key) == len(last)
                    and np.mean(key != last) < 0.01):
                status = "converged"
                break
            last = key
    _, xr = obj.posed(z)
    if mode == "correspondence":
        err = np.linalg.norm(xr - S, axis=1)
    else:
        q = _closest(S, np.asarray(scan_faces), xr)[0]
        err = np.linalg.norm(xr - q, axis=1)
    p, rot, tr = vec.unpack(z)
    acts = {}
    if kind == "simulation":
        a = sm.result_at(p).tracks.activations
        acts = {m.name: float(v) for m, v in zip(model.muscles, a)}
    return ScanFit(vector=vec, p=p, rotation=rot, translation=tr, surface=xr, error=err,
                   kind=kind, history=history, status=status, activations=acts,
                   seconds=time.perf_counter() - t0)


def write_scan_fit(folder, model, fit, **extra):
    """Write ``fit.json`` (the fit's summary, its history and ``extra``) and ``fit.npz``
    (posed surface, neutral, per-vertex error (V,) m, controls) into ``folder``, each through
    a temporary file; the report (``invface.report.fit``) reads them. Returns the summary."""
    summary = dict(fit.summary(), history=fit.history, **extra)
    write_fit_files(folder, summary, dict(surface=fit.surface, triangles=model.triangles,
                                          neutral=model.neutral, vertex_error=fit.error, p=fit.p))
    return summary
