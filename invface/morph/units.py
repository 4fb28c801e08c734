"""A scan's unit and scale, decided by its face, not by its bounding box.

A bounding box measures whatever the scan holds: a bust's shoulders, a crown, a stand, a
stray piece. The face does not vary so much: adult faces are within about 15 % of each
other in size. So the builder first guesses a provisional scale from the box
(``provisional_scales``), aligns the template's face to the scan (``orient``), and measures
the scan's face against the template's by the similarity ICP of the face around the nose
(``landmarks.face_similarity``: scale sigma). The scan is rescaled by 1/sigma and aligned
again until sigma is within 5 % of 1. Then:

- if the metres per file unit so found are within a factor ``UNIT_TOLERANCE`` of metres,
  centimetres or millimetres, that is the file's unit, taken exactly (a face 15 % larger
  than the template's stays 15 % larger);
- otherwise the file has no physical unit (a photogrammetry reconstruction, a sculpt): it is
  scaled to the template's adult face, and the summary says so.

The model stays metric either way; ``model.scan_transform`` holds the scale.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..errors import MeshError
from .landmarks import face_similarity
from .orient import align_to_template, best_pose
from .target import UNITS, provisional_scales

UNIT_TOLERANCE = 1.35         # metres per unit within this factor of a unit: that unit
SCALE_SETTLED = 1.05          # the face's scale against the template's: done within 5 %
MAX_PASSES = 4


@dataclass
class Scaling:
    """How the scan's unit was decided: unit ('m', 'cm', 'mm' or 'none'), scale (metres per
    file unit), face_scale (the scan's face against the template's, after the choice), the
    provisional guess it started from, a one-line ``summary`` and ``similarity`` (A (3,3),
    t (3,)): the template's face mapped onto the aligned scan (landmarks.face_similarity)."""
    unit: str
    scale: float
    face_scale: float
    provisional: str
    summary: str
    similarity: tuple


def rescale(target, k):
    """The Target with its vertices (and metres per unit) multiplied by k."""
    return replace(target, vertices=target.vertices * k, scale=target.scale * k)


def _measure(target, template):
    """Align the target and measure its face: (Alignment, sigma = the face's scale against
    the template's, the similarity (A (3,3), t (3,)) of the template's face onto it)."""
    al = align_to_template(target.vertices, target.faces, template)
    A, t = face_similarity(template, al.apply(target.vertices), target.faces)
    return al, float(np.cbrt(np.linalg.det(A))), (A, t)


def _settle(target, template, first=None):
    """Rescale and align until the face matches the template's size, from ``first`` (the
    target's _measure, when done already): (target, its _measure)."""
    m = first or _measure(target, template)
    for _ in range(MAX_PASSES - 1):
        sigma = m[1]
        if not 0.2 < sigma < 5:
            raise MeshError(f"the template's face matches the scan only at {sigma:.2f} times its size")
        if abs(np.log(sigma)) < np.log(SCALE_SETTLED):
            break
        target = rescale(target, 1 / sigma)
        m = _measure(target, template)
    return target, m


def settle_unit(target, template, unit=None, progress=None):
    """Decide the unit of a cleaned Target (``target.clean`` with no unit: in provisional
    metres) from its face and align it. Returns (Target in metres, orient.Alignment, Scaling).

    unit: 'm', 'cm' or 'mm' given by the user (then only aligned)."""
    say = progress or (lambda m: None)
    if unit is not None:
        m = _measure(target, template)
        return target, m[0], Scaling(unit, target.scale, m[1], unit, f"unit {unit} (given)", m[2])
    raw = target.vertices / target.scale
    diag = float(np.linalg.norm(np.ptp(raw, axis=0)))
    tried, errors = [], []
    for guess, s in provisional_scales(raw):
        t = rescale(target, s / target.scale)
        try:
            m = None
            if guess != "none":          # a unit the box allows: kept when the face agrees
                m = _measure(t, template)
                if m[0].residual < 0.01 and abs(np.log(m[1])) < np.log(UNIT_TOLERANCE):
                    tried = [(guess, t, m)]
                    break
            t, m = _settle(t, template, m)
        except MeshError as e:
            errors.append((guess if guess != "none" else f"no unit at {s * diag:.2g} m across", str(e)))
            continue
        # every guess is tried and the closest face wins (orient.best_pose): a guess can align
        # the face well at the wrong scale (a turned bust's, 1.5 times too large, 0.5 mm
        # further than the right one)
        tried.append((guess, t, m))
    if not tried:
        raise MeshError(f"{target.name}: no face found at any scale tried ({', '.join(g for g, _ in errors)}); "
                        f"at the first: {errors[0][1]}")
    # a guess whose face never settled to the template's size (MAX_PASSES) aligned something
    # else than the face: the settled ones are chosen from first
    tried = [r for r in tried if abs(np.log(r[2][1])) < np.log(SCALE_SETTLED)] or tried
    guess, t, m = tried[best_pose([r[2][0].residual for r in tried], [r[2][0].uncovered for r in tried])[0]]
    per_unit = t.scale
    unit = next((u for u, s in UNITS.items() if abs(np.log(per_unit / s)) < np.log(UNIT_TOLERANCE)), "none")
    if unit == "none":
        summary = (f"no physical unit: its face is {per_unit * 1000:.4g} mm per file unit at the template's "
                   "adult size, so it was scaled to that")
    else:
        if per_unit != UNITS[unit]:
            t = rescale(t, UNITS[unit] / per_unit)
            m = _measure(t, template)
        summary = f"unit {unit}, found from the face (its face is {m[1]:.2f} x the template's)"
    say(summary)
    return t, m[0], Scaling(unit, t.scale, m[1], guess, summary, m[2])
