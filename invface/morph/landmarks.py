"""The 17 landmarks of paper 001 (sec. 6, Fig. 6) on a target aligned to the template.

The target is already in the model frame (orient.align_to_template): +Y up, +Z forward. Each
landmark starts from a prior, the template's landmark carried by a similarity fit of the
template's face (face_similarity) to the target's closest point, and is then found by the paper's rule for it:

- on the profile curve (mesh ∩ symmetry plane): the nose tip (most forward point), the nose
  bridge (the deepest point above the tip), the subnasale (the deepest point below the tip,
  measured behind the line from the tip to the upper lip), the upper and lower lip (most
  forward points either side of the stomion), the chin (the first down-and-forward extreme
  below the nose), the neck start (2 cm below the chin) and the top of the head (the highest
  point);
- the left/right extreme points of the head above the chin;
- priors for the bridge, stomion, subnasale, mouth corners and alar points are the template's
  moved by the offsets already found at the nose tip, bridge, stomion and chin, interpolated
  by height (a real face's proportions differ from the template's by 1-2 cm: on ICT-FaceKit's
  neutral the similarity-carried template eyes sit 17 mm too low);
- a rule that finds nothing (no chin below the nose, no mouth on the profile, no head sides)
  does not stop the build: the landmark falls back to its prior, and the build's summary
  names the landmark and the rule (issue 62); a chin found on a bottom cut is off the scan;
- eye corners, mouth corners and alar points by curvature-weighted local registration: the
  template's skin within 15 mm of the landmark, each vertex weighted by its fixed-stencil
  feature strength (sec. 6: curvature is what marks these features), is rigidly registered
  (trimmed ICP) onto the target from the global alignment, and the landmark moves with it.

Deviation: the paper finds corners as the high-curvature points nearest to corners of boxes
spanned by other landmarks. On the generated template the eye and mouth corners are the ends
of zero-width slits, which the 5 mm stencil smears (its curvature maximum lies 3-8 mm from
the slit end), and the box rule then depends on the box; registering the curvature-weighted
patch finds the same anatomical point on both meshes.
"""
from __future__ import annotations

import numpy as np
from scipy.signal import find_peaks
from scipy.spatial import cKDTree

from ..errors import MeshError
from ..mesh.closest import barycentric_points, closest_points
from ..mesh.sections import plane_sections
from ..mesh.triangles import boundary_edges, boundary_loops, edge_components, unique_edges
from .curvature import feature_strength
from .orient import rigid_icp

LANDMARKS = ("nose_tip", "nose_bridge", "subnasale", "top_of_head", "chin", "neck_start",
             "head_extreme_L", "head_extreme_R", "eye_inner_L", "eye_outer_L", "eye_inner_R",
             "eye_outer_R", "mouth_corner_L", "mouth_corner_R", "lip_upper", "lip_lower",
             "alar_L", "alar_R", "stomion")
EAR_CURVATURE = 140.0     # 1/m: paper 001 sec. 9.1, sum of absolute curvatures on the ears
EAR_REACH = 0.03          # m: an ear region comes this close to the head extreme (ICT: 22 mm)
EAR_SIZE = 0.03           # m: and spans at least this much (ICT's ears: 63 mm tall)
PATCH_RADIUS = 0.015      # m: template skin registered around eye/mouth corners and alar points
HEAD_OUTER = ("top_of_head", "head_extreme_L", "head_extreme_R")   # may be off a partial scan's edge
NECK_DROP = 0.02          # m: the neck start is this far below the chin on the profile
EDGE_DISTANCE = 0.001     # m: an outer landmark this close to the scan's open edge ...
PRIOR_GAP = 0.01          # m: ... whose template prior lies this far off the scan is off the scan
FALLBACK = "the template's landmark carried by the face similarity"
CHIN_SHARE = 0.25         # a chin candidate stands out at least this share of the largest one's prominence
CHIN_CLEAR = 0.01         # m: a chin stands out this much in the 45-degree support, or the 30-degree one decides
NOTCH_PROMINENCE = 0.0005  # m: a notch of the profile (the stomion, the chin-lip fold) at least this deep
OPENING_WIDTH = 0.6       # an opening narrower than this share of the carried corners' span is not
                          # the eye or the mouth (a scanner's hole), and gives no corners


_TEMPLATE_POINTS = {}


def template_landmarks(model):
    """{name: (3,) point} of LANDMARKS on the template: its own landmarks, and the lip points
    (which it does not list) found by the same profile rules as on a target."""
    if id(model) not in _TEMPLATE_POINTS:
        found, _, _ = find_landmarks(model.neutral, model.triangles, model)
        pts = {k: model.neutral[v] for k, v in model.landmarks.items() if k in LANDMARKS}
        _TEMPLATE_POINTS[id(model)] = {k: pts.get(k, found[k]) for k in LANDMARKS}
    return _TEMPLATE_POINTS[id(model)]


def profile_curve(V, F, prior_tip, depth=0.16):
    """The front profile (n,3): the pieces of mesh ∩ plane x = 0 no more than ``depth`` behind
    the nose tip, each ordered bottom to top and joined in height order (an open mouth or
    eyes split the section into pieces)."""
    chains = plane_sections(V, F, np.zeros(3), np.array([1.0, 0, 0]))
    parts = []
    for c in chains:
        Q = c.points[c.points[:, 2] > prior_tip[2] - depth]
        if len(Q) < 2:
            continue
        parts.append(Q if Q[0, 1] < Q[-1, 1] else Q[::-1])
    if not parts:
        raise MeshError("the symmetry plane does not cut the front of the aligned target")
    parts.sort(key=lambda Q: Q[:, 1].mean())
    return np.concatenate(parts)


_PATCHES = {}


def _template_patch(model, vid, radius=PATCH_RADIUS):
    """Template skin points (n,3) within ``radius`` of vertex vid and their weights (n,)."""
    key = (id(model), vid)
    if key not in _PATCHES:
        Vt = model.neutral
        ids = np.flatnonzero(np.linalg.norm(Vt - Vt[vid], axis=1) < radius)
        w = feature_strength(Vt, model.triangles, ids)
        _PATCHES[key] = (Vt[ids], w / w.mean())
    return _PATCHES[key]


def face_similarity(model, V, F, radius=0.09, n=2000):
    """Similarity (A (3,3) = scale x rotation, t (3,)) of the template's face (skin within
    ``radius`` of its nose tip) onto the aligned target (V, F) by trimmed ICP. Real faces
    differ from the template in size by centimetres; the landmark priors and the patch
    registrations start from this map instead of the template's own positions."""
    Vt = model.neutral
    ids = np.flatnonzero(np.linalg.norm(Vt - Vt[model.landmarks["nose_tip"]], axis=1) < radius)
    ids = ids[np.random.default_rng(3).permutation(len(ids))[:n]]
    A, t, _ = rigid_icp(Vt[ids], V, F, np.eye(3), np.zeros(3), iters=40, scale=True)
    return A, t


def _register_patch(model, vid, V, F, A, t):
    """Template landmark vid carried onto the target (V, F; aligned) by curvature-weighted
    rigid ICP of its surrounding template patch, starting from the similarity (A, t)."""
    P, w = _template_patch(model, vid)
    R, t, _ = rigid_icp(P, V, F, A, t, iters=30, weights=w)
    q = R @ model.neutral[vid] + t
    tri, bw, _ = closest_points(q[None], V, F)
    return barycentric_points(V, F, tri, bw)[0]


def _opening(V, loops, center, radius, min_width=0.0):
    """Vertex ids of the boundary loop (an opening of the scan) whose centroid lies within
    ``radius`` of ``center`` (3,) and whose width (its x extent) is at least ``min_width``,
    the nearest one; None when there is none."""
    best, dist = None, radius
    for ids in loops:
        d = np.linalg.norm(V[ids].mean(axis=0) - center)
        if d < dist and len(ids) >= 6 and np.ptp(V[ids, 0]) >= min_width:
            best, dist = ids, d
    return best


def _front_depth(P, ys, max_step=0.005):
    """For each height ys (k,), the frontmost z where the profile polyline P (n,3) crosses
    it (segments longer than ``max_step``, the joins between pieces, are skipped)."""
    a, b = P[:-1], P[1:]
    seg = np.linalg.norm(b - a, axis=1) < max_step
    a, b = a[seg], b[seg]
    lo, hi = np.minimum(a[:, 1], b[:, 1]), np.maximum(a[:, 1], b[:, 1])
    dy = np.where(hi > lo, b[:, 1] - a[:, 1], 1.0)
    s = np.clip((ys[:, None] - a[None, :, 1]) / dy[None], 0, 1)
    zc = a[None, :, 2] + s * (b[None, :, 2] - a[None, :, 2])
    inside = (ys[:, None] >= lo[None] - 1e-9) & (ys[:, None] <= hi[None] + 1e-9)
    return np.where(inside, zc, -np.inf).max(axis=1)


def _on_outline(P, ids):
    """The profile indices ``ids`` on the face's outline: the frontmost profile point at their
    height (``_front_depth``), not a piece of the profile behind it (inside a nostril)."""
    return ids[P[ids, 2] >= _front_depth(P, P[ids, 1]) - 1e-4]


def _ears(V, F, ids, threshold=EAR_CURVATURE, grow=0.01):
    """Mask over vertex ids (k,) of the ears: the paper's (sec. 9.1) sum of absolute
    curvatures above ``threshold`` (1/m) on the outer third of the head's width, grown by
    ``grow`` (m). The template has no ears; a scan's ears must not set the head's width."""
    out = ids[np.abs(V[ids, 0]) > 0.66 * np.abs(V[ids, 0]).max()]
    if len(out) == 0:
        return np.zeros(len(ids), bool)
    curved = out[feature_strength(V, F, out) > threshold]
    if len(curved) == 0:
        return np.zeros(len(ids), bool)
    d, _ = cKDTree(V[curved]).query(V[ids])
    return d < grow


def ear_boxes(V, F, L, grow=0.005):
    """Bounding boxes (k,2,3) (min, max corners, m) of the scan's ears (paper 001 sec. 9.1):
    connected high-curvature regions on the outer third of the head between the chin and the
    top of the head (landmarks L), grown by ``grow``, that reach within EAR_REACH of that
    side's head extreme (the paper's path back to the extreme) and span at least EAR_SIZE
    (smaller regions are discarded); one box per side that has one. The template has no
    ears: the surface morph neither snaps onto nor snaps inside these boxes. (Without the
    reach and size tests, a cheekbone and a jaw angle sharpened by a smooth identity change
    spanned a box over 38 % of the head in the template round trip.)"""
    ids = np.flatnonzero((V[:, 1] > L["chin"][1]) & (V[:, 1] < L["top_of_head"][1]))
    ear = ids[_ears(V, F, ids, grow=grow)]
    mask = np.zeros(len(V), bool)
    mask[ear] = True
    E = unique_edges(F)[0]
    label = edge_components(E[mask[E].all(1)], len(V))[ear]
    regions = [V[ear[label == c]] for c in np.unique(label)]
    boxes = []
    for side, name in ((1, "head_extreme_L"), (-1, "head_extreme_R")):
        parts = [P for P in regions if np.sign(P[:, 0].mean()) == side and np.ptp(P, axis=0).max() >= EAR_SIZE
                 and np.linalg.norm(P - L[name], axis=1).min() < EAR_REACH]
        if parts:
            P = np.concatenate(parts)
            boxes.append([P.min(0), P.max(0)])
    return np.array(boxes).reshape(-1, 2, 3)


def _support(P, down, prior, angle, prominence):
    """The support point in the direction ``angle`` (rad) below forward among the profile
    indices ``down``: the local maximum of z cos(angle) - y sin(angle) nearest the ``prior``
    (3,) of those whose prominence is at least CHIN_SHARE of the largest one's. Returns its
    index into P and its prominence (m; 0 where there is no local maximum and the largest
    value is taken)."""
    f = P[down, 2] * np.cos(angle) - P[down, 1] * np.sin(angle)
    peaks, props = find_peaks(f, prominence=prominence)
    if not len(peaks):
        return int(down[np.argmax(f)]), 0.0
    # a lower lip is a small bump on the way down, the chin and a neck's base large ones: on a
    # face longer below the mouth than the template the lip lies nearer the carried chin
    keep = props["prominences"] >= CHIN_SHARE * props["prominences"].max()
    peaks, prominences = peaks[keep], props["prominences"][keep]
    k = np.argmin(np.linalg.norm(P[down[peaks]] - prior, axis=1))
    return int(down[peaks[k]]), float(prominences[k])


def _subnasale(P, tip, stom, cand):
    """The subnasale among the profile indices ``cand`` (on the face's outline near its prior):
    the one deepest behind the line from the nose tip (index ``tip``) to the upper lip's most
    forward point between the stomion (index ``stom``) and the candidates, the vertex of the
    nasolabial angle, where the profile runs parallel to that line. Paper 001 (sec. 6) takes
    the local minimum of the profile's forward distance next to the tip; the forward direction
    here is the normal of that line. On faces whose turn from the columella to the lip is
    rounded, the sharpest concave corner at a 2 mm scale is the upper lip's deepest point,
    8-9 mm below the junction that ICT-FaceKit annotates."""
    idx, y, z = np.arange(len(P)), P[:, 1], P[:, 2]
    lip = idx[(idx > stom) & (idx < tip) & (y > y[stom]) & (y < y[cand].min())]
    lip = lip[np.argmax(z[lip])] if len(lip) else cand[np.argmin(y[cand])]
    u = P[lip, 1:] - P[tip, 1:]
    r = P[cand, 1:] - P[tip, 1:]
    return cand[np.argmax(u[0] * r[:, 1] - u[1] * r[:, 0])]       # (y, z) cross: > 0 behind the line


def _chin(P, tip, prior, drop=0.03, prominence=0.002):
    """Index of the chin on the profile P (n,3, bottom to top): going down from the nose tip
    (at least ``drop`` below it), the support point in the down-and-forward direction (45
    degrees; the gnathion, where the surface turns from facing forward to facing down) nearest
    the ``prior`` chin (3,) (the template's, carried by the face similarity) of the prominent
    ones (``_support``). A full lower lip is such a maximum 3 cm above it (an ICT-FaceKit
    identity's was taken for the chin when the first maximum was), and a scan with a neck
    flares forward again at the neck's base below it. Where the underside of the chin runs
    near 45 degrees down a neck, no maximum there stands out by ``CHIN_CLEAR`` and the best one
    may be a wrinkle of the neck: the support 30 degrees below forward, where it stands out
    more, is the chin. (Where the 45-degree support has no maximum at all, the profile ends
    at the chin: a scan cut there, which ``find_landmarks`` judges by the cut's edge.)"""
    down = np.arange(tip, -1, -1)
    down = down[P[down, 1] < P[tip, 1] - drop]
    if len(down) < 3:
        raise MeshError("the profile ends below the nose: no chin found")
    chin, clear = _support(P, down, prior, np.pi / 4, prominence)
    if 0 < clear < CHIN_CLEAR:
        forward, clear_forward = _support(P, down, prior, np.pi / 6, prominence)
        if clear_forward > clear:
            return forward
    return chin


def find_landmarks(V, F, model):
    """Landmarks {name: (3,) point in the model frame} on an aligned target (V (n,3) m in the
    model frame, F), the names of those off the scan (a tuple), and the rules that found
    nothing ({landmark: what the rule could not find}). Raises MeshError only when the
    alignment itself failed: the profile misses the front of the face or the nose.

    A rule that finds nothing (no chin below the nose on a cropped scan, no mouth on a
    profile with a hole at the lips, no head sides) does not stop the build: its landmark
    falls back to the template's, carried by the face similarity and moved by the offsets
    already found (``fallback``), and its curves are left out of the morph like those of a
    landmark off the scan.

    Partial scans (paper 001 sec. 8.1, a front-of-face scan): the top of the head or a head
    extreme found on the scan's open edge (within EDGE_DISTANCE) while the template's
    landmark, carried by the face similarity, lies more than PRIOR_GAP off the scan marks
    where the scan stops, not where the head does (a wide head's extremes can sit on the
    edge of a full scan: those stay); so does a neck start that the profile cannot reach
    (the scan ends less than half NECK_DROP below the chin; the template itself ends at
    its neck start, so no edge test there). Such a landmark keeps that prior, and its curves
    are left out of the morph (``build_model``), which completes the head from the template."""
    A, t = face_similarity(model, V, F)
    carried = {k: A @ model.neutral[v] + t for k, v in model.landmarks.items() if k in LANDMARKS}
    # priors: the carried landmarks projected onto the target surface (gap: how far off it)
    tri, w, gap = closest_points(np.array(list(carried.values())), V, F)
    prior = dict(zip(carried, barycentric_points(V, F, tri, w)))
    gap = dict(zip(carried, gap))
    P = profile_curve(V, F, prior["nose_tip"])
    search = _ProfileSearch(V, F, P, prior, carried, gap)
    L, fell = search.L, search.fell
    search.nose()
    chin = search.chin()
    loops = boundary_loops(F)

    def corners(inner, outer, a, b):
        """Both corners of an eye or the mouth: the x-extremes of the scan's opening there
        when it has one (open eyes, parted lips) as wide as the carried corners' span, near
        the corners' priors moved with landmarks a and b or else near the priors themselves;
        without one, the registered template patches."""
        p, q = search.reanchor(inner, a, b), search.reanchor(outer, a, b)
        span = np.linalg.norm(p - q)
        hole = None
        for c in (0.5 * (p + q), 0.5 * (prior[inner] + prior[outer])):    # moved with a, b, else as carried
            hole = hole if hole is not None else _opening(V, loops, c, 0.5 * span + 0.005,
                                                           min_width=OPENING_WIDTH * span)
        if hole is not None:
            # eye: inner/outer = nearest/farthest from the symmetry plane; mouth: left/right
            ax = np.abs(V[hole, 0]) if p[0] * q[0] > 0 else V[hole, 0] * np.sign(q[0] - p[0])
            L[inner], L[outer] = V[hole[np.argmin(ax)]], V[hole[np.argmax(ax)]]
            return
        for name, pt in ((inner, p), (outer, q)):
            L[name] = _register_patch(model, model.landmarks[name], V, F, A, t + pt - prior[name])

    corners("eye_inner_L", "eye_outer_L", "nose_bridge", "nose_bridge")
    corners("eye_inner_R", "eye_outer_R", "nose_bridge", "nose_bridge")
    L["stomion"] = search.reanchor("stomion", "nose_tip", "chin")     # the prior; found below
    for name in ("alar_L", "alar_R"):
        shift = search.reanchor(name, "nose_tip", "stomion") - prior[name]
        L[name] = _register_patch(model, model.landmarks[name], V, F, A, t + shift)
    corners("mouth_corner_L", "mouth_corner_R", "stomion", "stomion")
    search.mouth(chin)
    if "stomion" not in fell:       # the corners again, from the stomion found on the profile
        corners("mouth_corner_L", "mouth_corner_R", "stomion", "stomion")
    search.neck_and_top(chin)
    search.head_sides()
    outer = _off_scan(V, F, L, gap)
    if L["neck_start"][1] > L["chin"][1] - 0.5 * NECK_DROP:           # the profile ends above it
        outer.append("neck_start")
    for k in outer:
        L[k] = carried[k]
    return {k: np.asarray(L[k], float) for k in LANDMARKS}, tuple(search.off + outer), dict(fell)


class _ProfileSearch:
    """The profile rules of ``find_landmarks`` on the profile P (n,3, bottom to top) of an
    aligned target (V, F), from the priors ({name: (3,)}: the carried template landmarks
    projected onto the target; ``carried``: before the projection; ``gap``: how far off the
    target, m). Fills ``L`` {name: (3,)}, ``fell`` {name: the rule's failure} for the
    landmarks that fell back, and ``off``: those found off a cropped scan."""

    def __init__(self, V, F, P, prior, carried, gap):
        self.V, self.F, self.P, self.prior, self.carried, self.gap = V, F, P, prior, carried, gap
        self.idx = np.arange(len(P))
        self.L, self.fell, self.off = {}, {}, []

    def window(self, center, r):
        return np.linalg.norm(self.P - center, axis=1) < r

    def reanchor(self, name, a, b):
        """prior[name] moved by the found-minus-prior offsets of landmarks a and b,
        interpolated by height: real faces differ from the template's proportions."""
        prior, L = self.prior, self.L
        ya, yb = prior[a][1], prior[b][1]
        r = 0.0 if a == b else float(np.clip((prior[name][1] - ya) / (yb - ya), 0, 1))
        return prior[name] + (1 - r) * (L[a] - prior[a]) + r * (L[b] - prior[b])

    def fallback(self, name, point, rule):
        """Landmark ``name`` set to ``point`` (3,) (the template's, carried and reanchored)
        projected onto the target when it lies within PRIOR_GAP of it, else left where it
        is (off a cropped scan); ``rule`` is recorded. Returns the profile index nearest it."""
        tri, w, d = closest_points(point[None], self.V, self.F)
        if d[0] < PRIOR_GAP:
            self.L[name] = barycentric_points(self.V, self.F, tri, w)[0]
        else:
            self._off_the_scan(name, point)
        self.fell[name] = rule
        return int(np.argmin(np.linalg.norm(self.P - self.L[name], axis=1)))

    def _off_the_scan(self, name, point):
        """Landmark ``name`` at ``point`` (3,) off the scan; its prior becomes the carried
        landmark itself (not its projection onto the scan's edge), so that the offsets the
        other priors are moved by (``reanchor``) are those of the face, not of the crop."""
        self.L[name] = point
        if name in self.carried:
            self.prior[name] = self.carried[name]

    def nose(self):
        """The nose tip and the bridge (the deepest point above the tip). The tip is, of the
        forward bumps of the face's outline near its prior, the one nearest the prior, else the
        most forward point there (none near the prior: the alignment failed). On a face whose
        upper lip stands further forward than its nose, the most forward point is the lip. The
        outline is the frontmost profile point at each height (``_front_depth``): the plane
        also cuts the inside of the nostrils, in pieces of the profile behind it."""
        P, idx, L = self.P, self.idx, self.L
        near_tip = self.window(self.prior["nose_tip"], 0.03)
        if not near_tip.any():
            raise MeshError("the profile curve misses the nose: the alignment to the template failed")
        ids = _on_outline(P, idx[near_tip])
        up = ids[np.argsort(P[ids, 1], kind="stable")]
        bumps, _ = find_peaks(P[up, 2], prominence=NOTCH_PROMINENCE)
        self.tip = (up[bumps[np.argmin(np.linalg.norm(P[up[bumps]] - self.prior["nose_tip"], axis=1))]]
                    if len(bumps) else up[np.argmax(P[up, 2])])
        L["nose_tip"] = P[self.tip]
        above = (idx > self.tip) & self.window(self.reanchor("nose_bridge", "nose_tip", "nose_tip"), 0.015)
        if above.any():
            L["nose_bridge"] = P[idx[above][np.argmin(P[above, 2])]]
        else:
            self.fallback("nose_bridge", self.reanchor("nose_bridge", "nose_tip", "nose_tip"),
                          "no nose bridge above the nose tip on the profile")

    def chin(self):
        """The chin (``_chin``) and its profile index. A chin found on the scan's open edge
        while the carried one lies off the scan is where a scan cut below the mouth stops: the
        chin is off the scan (``off``) and takes the carried one, moved with the nose tip. A
        profile that ends too close below the nose for the rule falls back to the same."""
        carried = self.carried["chin"] + self.L["nose_tip"] - self.prior["nose_tip"]
        try:
            chin = _chin(self.P, self.tip, self.prior["chin"])
        except MeshError as e:
            return self.fallback("chin", carried, str(e))
        ends = self.P[:, 1].min() > self.P[chin, 1] - 0.5 * NECK_DROP       # no profile below it
        on_edge = _edge_distance(self.V, self.F, self.P[chin][None])[0] < EDGE_DISTANCE
        if ends and on_edge and self.gap["chin"] > PRIOR_GAP:
            self.off.append("chin")
            self._off_the_scan("chin", carried)
        else:
            self.L["chin"] = self.P[chin]
        return chin

    def mouth(self, chin):
        """The stomion (the highest notch of the profile seen from the front near the mouth
        corners' height, else its deepest point there: with the corners placed low the window
        reaches the chin-lip fold, a deeper notch below the lower lip), the subnasale
        (``_subnasale``) and the lips (the most forward points either side of the stomion)."""
        P, idx, L, tip = self.P, self.idx, self.L, self.tip
        y, z = P[:, 1], P[:, 2]
        my = 0.5 * (L["mouth_corner_L"][1] + L["mouth_corner_R"][1])
        # the candidates on the outline: an open mouth's inner lips and cavity, at the same
        # heights, do not count
        cand = _on_outline(P, idx[(idx < tip) & (idx > chin) & (np.abs(y - my) < 0.006)])
        if len(cand):
            front = _front_depth(P[chin:tip + 1], y[cand])
            up = np.argsort(y[cand])                   # bottom to top
            notches, _ = find_peaks(-front[up], prominence=NOTCH_PROMINENCE)
            stom = cand[up[notches[-1]]] if len(notches) else cand[np.argmin(front)]
            L["stomion"] = P[stom]
        else:
            stom = self.fallback("stomion", L["stomion"],
                                 "no mouth found on the profile at the height of the mouth corners")
        sub_prior = self.reanchor("subnasale", "nose_tip", "stomion")
        between = ((idx < tip) & (idx > stom) & (y > L["stomion"][1] + 0.006) & self.window(sub_prior, 0.01))
        cand = _on_outline(P, idx[between])                 # not inside the nostrils
        if len(cand):
            sub = _subnasale(P, tip, stom, cand)
            L["subnasale"] = P[sub]
        else:
            sub = self.fallback("subnasale", sub_prior, "no concave corner between the nose tip and the mouth "
                                "on the profile")
        for name, side in (("lip_upper", (idx > stom) & (idx < sub)), ("lip_lower", (idx < stom) & (idx > chin))):
            if "stomion" in self.fell:
                self.fallback(name, L["stomion"], "the stomion fell back: the lip is taken at it")
            elif side.any():
                L[name] = P[idx[side][np.argmax(z[side])]]
            else:
                self.fallback(name, L["stomion"], f"no profile between the stomion and the "
                              f"{'subnasale' if name == 'lip_upper' else 'chin'}: the lip is the stomion")

    def neck_and_top(self, chin):
        """The neck start (NECK_DROP below the chin on the profile) and the top of the head."""
        P, idx = self.P, self.idx
        neck = idx[idx <= chin]
        self.L["neck_start"] = P[neck[np.argmin(np.abs(P[neck, 1] - (self.L["chin"][1] - NECK_DROP)))]]
        self.L["top_of_head"] = P[np.argmax(P[:, 1])]

    def head_sides(self):
        """The left/right extremes of the head above the chin at the carried extremes' height,
        the ears left out."""
        V, F, L = self.V, self.F, self.L
        band = (V[:, 1] > L["chin"][1]) & (np.abs(V[:, 1] - self.prior["head_extreme_L"][1]) < 0.03)
        bid = np.flatnonzero(band)
        bid = bid[~_ears(V, F, bid)]
        if not len(bid):
            for name in ("head_extreme_L", "head_extreme_R"):
                self.fallback(name, self.carried[name], "no head sides found above the chin")
            return
        L["head_extreme_L"] = V[bid[np.argmax(V[bid, 0])]]
        L["head_extreme_R"] = V[bid[np.argmin(V[bid, 0])]]


def _edge_distance(V, F, Q):
    """(k,) m: each point Q (k,3) from the open edge of the scan (V, F); inf without one."""
    E = boundary_edges(F)
    if not len(E):
        return np.full(len(Q), np.inf)
    a, ab = V[E[:, 0]], V[E[:, 1]] - V[E[:, 0]]                  # open-edge segments
    Q = np.asarray(Q, float)[:, None]
    s = np.clip(np.einsum("ij,nij->ni", ab, Q - a) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-30), 0, 1)
    return np.linalg.norm(a + s[..., None] * ab - Q, axis=2).min(1)


def _off_scan(V, F, L, gap):
    """HEAD_OUTER landmarks (in ``L``) within EDGE_DISTANCE of the scan's (V, F) open edge
    whose carried template landmark lies more than PRIOR_GAP off the scan (``gap`` {name: m}):
    where a partial scan stops, not where the head does."""
    d = _edge_distance(V, F, np.array([L[k] for k in HEAD_OUTER]))
    return [k for k, dk in zip(HEAD_OUTER, d) if dk < EDGE_DISTANCE and gap[k] > PRIOR_GAP]
