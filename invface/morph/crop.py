"""Crop what is not head from an aligned scan: shoulders, chest, clothing, a stand, the back
of a bust.

The template covers the face, the forehead and scalp to the crown, the sides of the head to
the ears and the neck to 2 cm below the chin. A scan's surface far outside that region has
nothing to morph onto, yet it decides the scan's inertia axes, its profile's lowest point and
its head extremes. Once the template's face is aligned (``orient``) and its similarity to the
scan is known (``landmarks.face_similarity``: A, t), the scan is cut to the template's box,
carried by that similarity and grown by ``MARGIN`` (hair, a larger head); of the pieces left,
the one holding the nose is kept, with any other of at least ``PIECE_SHARE`` of its area (a
face scanned in several pieces). Then a scalp hidden by hair, a crown or a cap is left out
(``scalp.hidden_scalp``) and the pieces are counted again: what was inside a crown falls
apart from the head.
"""
from __future__ import annotations

import numpy as np

from ..mesh.triangles import edge_components, triangle_areas
from .scalp import hidden_scalp
from .target import drop_faces

MARGIN = 0.035       # m around the template's box (template frame)
BELOW_CHIN = 0.05    # m: the neck is kept this far below the template's chin
PIECE_SHARE = 0.1    # pieces in the box with less area than this share of the head's go


def head_box(template):
    """(lo (3,), hi (3,)) m: the template skin's box grown by MARGIN, the neck kept to
    BELOW_CHIN under the chin, in the template's frame."""
    V = template.neutral
    lo, hi = V.min(0) - MARGIN, V.max(0) + MARGIN
    lo[1] = V[template.landmarks["chin"], 1] - BELOW_CHIN
    hi[2] = np.inf                                      # nothing in front of a face is cut
    return lo, hi


def crop_to_head(target, Va, template, A, t):
    """The Target without the triangles outside the head or over a hidden scalp: target (its
    Va (n,3) the aligned vertices in the model frame), A (3,3), t (3,) the similarity mapping
    the template's face onto it. Returns (the cropped Target with a note per cut, or
    ``target`` itself when nothing was cut; the hidden scalp's regions, a list of names)."""
    lo, hi = head_box(template)
    F = target.faces
    q = np.linalg.solve(A, (Va[F].mean(1) - t).T).T       # centroids, template frame
    nose = A @ template.neutral[template.landmarks["nose_tip"]] + t

    def head_pieces(keep):
        """Of the triangles ``keep``, the nose's piece and those of PIECE_SHARE of its area."""
        keep = keep.copy()
        if keep.any():
            Fk = F[keep]
            comp = edge_components(Fk[:, [0, 1, 1, 2]], len(Va))[Fk[:, 0]]
            area = np.bincount(comp, weights=triangle_areas(Va, Fk))
            head = comp[np.argmin(np.linalg.norm(Va[Fk].mean(1) - nose, axis=1))]
            keep[np.flatnonzero(keep)[area[comp] < PIECE_SHARE * area[head]]] = False
        return keep

    keep = head_pieces(((q >= lo) & (q <= hi)).all(1))
    # a scalp hidden on the head, then what fell apart from it (the inside of a crown)
    hair = np.zeros(len(F), bool)
    h, where, most = hidden_scalp(Va, F[keep], template, A, t)
    hair[np.flatnonzero(keep)[h]] = True
    if hair.any():
        keep = head_pieces(keep & ~hair)
    if keep.all():
        return target, []
    cut = ~keep & ~hair
    notes = ([f"hair or a crown over the scalp ({', '.join(where)}; up to {most * 1000:.0f} mm outside the "
               f"template's scalp): its {int(hair.sum())} triangles left out, the cranium and skin there follow "
               "the template carried by the face similarity"] if hair.any() else []) + \
            ([f"cropped {int(cut.sum())} triangles outside the head (shoulders, chest, a stand, the back of a "
              "bust or pieces apart from the face)"] if cut.any() else [])
    out = drop_faces(target, ~keep, notes[0])
    out.notes += notes[1:]
    return out, where
