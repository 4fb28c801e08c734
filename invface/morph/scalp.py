"""Where a scan's scalp is hidden by hair, a crown or a cap.

Hair, a crown or a cap is no skin: snapped onto, it would become a swollen forehead or a
tall skull. Once the template's face is fitted to the scan by a similarity (A, t; ``units``),
the template's scalp carried by that similarity predicts where the scan's scalp should be,
to within the spread of adult crania about a face of that size. Each scan vertex over the
scalp (above the brows, and above the eyes behind the orbits) is measured along the
template's normal from that prediction (positive: outside).
The hidden region grows, over the scan's edges, from seed patches (at least ``SEED_AREA``
more than ``SEED`` outside and rough like hair, or more than ``CROWN`` outside and rising from
the skin at a rim, not an ear at the head's sides) through
vertices more than ``GROW`` outside (hair thins to nothing at the hairline, a crown meets the
forehead on a slope) and through the scalp behind the template's open back edge, where
nothing can be measured: its triangles are left out, and the cranium and skin there follow
the template carried by the face similarity, as for a partial scan
(``surface.morph_surface(carried=...)``).

Thresholds, measured on real heads (template r1, the scan aligned and scaled by its face):
bald scalps reach 14-17 mm outside (ICT-FaceKit's neutral, whose cranium is longer than the
template's, 99th percentile 14.0 mm; a mix of its identity shapes, 16.5 mm; Lee
Perry-Smith's shaved head 7.0 mm), but smoothly (roughness 0.1-0.2 mm there), and their
rough patches beyond ``SEED`` are an ear's rim (the template has no ears), under 0.4 cm^2.
Wider bald heads (ICT identity mixes at 1.5 sd) reach 28-46 mm, rising from the forehead as a
slope (at most 0.37 m per m from the nearest skin), and their ears stand 16-39 mm out, rough
(1.5-2.2 mm) over 3-6 cm^2, their nearest template points within 9-18 mm of its head
extremes. Demosthenes' sculpted hair reaches 24 mm with a roughness of 1.2-1.6 mm over patches
of 6-16 cm^2, each reaching 25-67 mm from the head extremes; Nefertiti's crown 166 mm, rising
from its rim at 0.72-0.82 m per m. Hair thinner than ``SEED`` everywhere, or as smooth as skin
and thinner than ``CROWN`` or as gently sloped as a cranium, is taken for skin.
"""
from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix
from scipy.spatial import cKDTree

from ..mesh.closest import closest_points
from ..mesh.triangles import edge_components, face_normals, triangle_areas

SEED = 0.016         # m outside the carried template scalp and ...
ROUGH = 0.0005       # m: ... this rough (hair), or ...
CROWN = 0.03         # m: ... this far outside (a crown, a helmet): not a cranium ...
SEED_AREA = 2e-4     # m^2: ... over a patch at least this large (2 cm^2)
GROW = 0.006         # m: the hidden region grows through vertices this far outside
ABOVE_BROWS = 0.01   # m: the scalp is what lies this far above the template's brows ...
BEHIND_ORBIT = 0.025  # m: ... or above the eye corners and this far behind them
ALONG_NORMAL = 0.9   # the offset counts where the scan point lies this square to the template
RIM_SLOPE = 0.6      # a smooth seed rises from the skin at least this steeply (m per m) to be a crown
EAR_ZONE = 0.02      # m: a rough seed patch this close to the template's head extremes is an ear


def scalp_offsets(Va, template, A, t):
    """Signed distance (n,) m of the aligned scan's vertices Va (n,3) from the template's skin
    carried by the face similarity (A (3,3), t (3,)), along its normal (positive: outside),
    measured in the template's frame; NaN off the scalp (``scalp_zone``) and where the
    nearest template point is on its open edge rather than square below the vertex. Also the
    template points (n,3) nearest each vertex and whether they are on the scalp (n,) bool."""
    TV, TF = template.neutral, template.triangles
    q = np.linalg.solve(A, (np.asarray(Va, float) - t).T).T
    tri, w, d = closest_points(q, TV, TF)
    c = np.einsum("nk,nkj->nj", w, TV[TF[tri]])
    n = face_normals(TV, TF)[tri]
    s = np.einsum("ij,ij->i", q - c, n / np.linalg.norm(n, axis=1, keepdims=True))
    zone = scalp_zone(c, template)
    return np.where(zone & (np.abs(s) >= ALONG_NORMAL * d), s, np.nan), c, zone


def scalp_zone(C, template):
    """Boolean (k,) of template points C (k,3) on the scalp: ``ABOVE_BROWS`` above the brows,
    and on the sides and back above the outer eye corners' height, ``BEHIND_ORBIT`` behind them
    (the temples, where a crown's band or hair comes down to the ears)."""
    TV, lm = template.neutral, template.landmarks
    brows = max(TV[lm["brow_L"], 1], TV[lm["brow_R"], 1]) + ABOVE_BROWS
    eye = TV[lm["eye_outer_L"]]
    return (C[:, 1] > brows) | ((C[:, 1] > eye[1]) & (C[:, 2] < eye[2] - BEHIND_ORBIT))


def regions(C, template):
    """Names of the scalp regions the template points C (k,3) lie in: forehead, top, back,
    left side, right side (the actor's left is +x)."""
    TV, lm = template.neutral, template.landmarks
    front = TV[lm["eye_outer_L"], 2] - 0.01
    back = TV[lm["top_of_head"], 2] - 0.03
    side = 0.75 * TV[lm["head_extreme_L"], 0]
    where = {"forehead": C[:, 2] > front, "back": C[:, 2] < back,
             "left side": C[:, 0] > side, "right side": C[:, 0] < -side}
    where["top"] = ~np.any(list(where.values()), axis=0)
    return [k for k in ("forehead", "top", "left side", "right side", "back") if where[k].sum() >= 3]


def roughness(P, s, inner=0.01, outer=0.015, spacing=0.002):
    """Roughness (k,) m of an offset field s (k,) m over points P (k,3) m: the RMS, within
    ``outer`` of each point, of the offsets less their mean within ``inner``. Scanned or
    sculpted hair is rough (Demosthenes: 1.2-1.6 mm where it is thickest); a scalp or a cap is
    smooth (ICT-FaceKit's heads: 0.1-0.2 mm). Measured on the points thinned to one per
    ``spacing`` cell (a dense scan's balls would hold thousands), each point taking its cell's."""
    _, first, cell = np.unique(np.floor(P / spacing).astype(np.int64), axis=0, return_index=True,
                               return_inverse=True)
    Q, sq = P[first], s[first]
    tree = cKDTree(Q)

    def ball_mean(values, r):
        lists = tree.query_ball_point(Q, r)
        n = np.array([len(l) for l in lists])
        M = csr_matrix((np.ones(n.sum()), (np.repeat(np.arange(len(Q)), n), np.concatenate(lists))),
                       shape=(len(Q), len(Q)))
        return M @ values / n
    return np.sqrt(ball_mean((sq - ball_mean(sq, inner)) ** 2, outer))[cell.ravel()]


def _rises_steeply(Va, s, measured):
    """Boolean (n,) of the vertices of Va (n,3) whose offset s (n,) m rises from the skin (the
    nearest measured vertex less than GROW outside) by at least ``RIM_SLOPE`` m per metre
    between them: a crown or a helmet stands on the head at a rim, a large cranium rises from
    the forehead as a gentle slope."""
    skin = np.flatnonzero(measured & (s < GROW))
    if not len(skin):
        return np.ones(len(s), bool)
    d, j = cKDTree(Va[skin]).query(Va)
    return s - s[skin[j]] >= RIM_SLOPE * d


def _ear_patches(C, label, seed, template):
    """Boolean (n,) of the seed vertices whose patch (``label``) lies wholly where an ear
    stands out: their template points C (n,3) within ``EAR_ZONE`` of the template's head
    extremes (the template has no ears; a real ear's rim is rough and, on a wide head, more
    than SEED outside)."""
    ext = template.neutral[[template.landmarks["head_extreme_L"], template.landmarks["head_extreme_R"]]]
    near = np.min(np.linalg.norm(C[:, None] - ext[None], axis=2), axis=1) < EAR_ZONE
    far = np.bincount(label[seed & ~near], minlength=len(C)) > 0        # patches reaching beyond
    return seed & ~far[label]


def hidden_scalp(Va, F, template, A, t):
    """Triangles (f,) bool of the aligned scan (Va (n,3), F (f,3)) over a hidden scalp, the
    regions they cover (list of names) and the largest offset (m) among them."""
    s, C, zone = scalp_offsets(Va, template, A, t)
    measured = np.isfinite(s)
    beyond = ~measured & zone                      # over the scalp, past the template's open edge
    s = np.nan_to_num(s)
    # seeds: more than SEED outside and rough like hair, or more than CROWN outside; in
    # connected patches of at least SEED_AREA (an ear's rim is not)
    seed = s > SEED
    if not seed.any():
        return np.zeros(len(F), bool), [], 0.0
    rough = np.zeros(len(s))
    rough[measured] = roughness(Va[measured], s[measured])
    seed &= ((s > CROWN) & _rises_steeply(Va, s, measured)) | (rough > ROUGH)
    Fs = F[seed[F].all(1)]
    label = edge_components(Fs[:, [0, 1, 1, 2]], len(Va))
    area = np.bincount(label[Fs[:, 0]], weights=triangle_areas(Va, Fs), minlength=len(Va))
    seed &= (area[label] >= SEED_AREA) & ~_ear_patches(C, label, seed, template)
    if not seed.any():
        return np.zeros(len(F), bool), [], 0.0
    grow = (s > GROW) | beyond
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    label = edge_components(E[grow[E].all(1)], len(Va))
    hidden = grow & np.isin(label, label[seed])
    return hidden[F].any(1), regions(C[hidden], template), float(s[hidden].max())
