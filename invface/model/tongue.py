"""ARKit's tongueOut: the tongue slides out over the lower incisors, past the lips.

The tongue is an inner part on the jaw (``model.parts``), shaped at rest as the template
makes it. tongueOut w deforms it in the jaw's rest frame, before the jaw's skinning, so it
rides the jaw as before. Each tongue vertex moves by its share s of the tongue's length (0 at
the root, 1 at the tip, smoothstep between), times w:

    z += REACH s w                                          (forward, out of the mouth)
    y += s w (y_rest - y_mid) (THIN - 1) + s w (y_lift - y_mid)   (thinner, onto the incisors)
    x *= 1 + s w (NARROW - 1)                               (narrower)

with the tongue's middle height y_mid and y_lift the height at which its thinned underside lies
CLEARANCE above the lower incisors' edge: on the lower lip, which covers that edge when the jaw
opens. REACH is measured from the model itself: the tip goes
OUT_PAST_LIPS in front of the middle of the lower lip's inner edge at rest (the model curve
lip_inner_lower; without it, OUT_PAST_INCISORS in front of the lower incisors). All of it is
read from the model at rest, so a morphed actor's tongue reaches as far past its own lips. The tongue is not simulated: in the simulation kind the lips
do not touch it (no contact between the flesh and the inner parts but the eyeballs, the
teeth's bone and the jaw), and a fit cannot see it (the inner parts carry no gradient), so
tongueOut is played back, not fitted.
"""
from __future__ import annotations

import numpy as np

OUT_PAST_LIPS = 0.012         # m: the tip in front of the lower lip's inner edge at tongueOut 1
OUT_PAST_INCISORS = 0.027     # m: the same without a lip curve (the template's lip lies 15 mm in front)
THIN = 0.55                   # the protruded front's height, a share of the tongue's
NARROW = 0.75                 # its width, a share of the tongue's
CLEARANCE = 0.006             # m: the protruded underside above the lower incisors' edge: on the lower lip


class Tongue:
    """A model's tongue and lower incisors at rest, and the deformation of tongueOut."""

    def __init__(self, model):
        names = list(model.blendshape_names)
        self.k = names.index("tongueOut") if "tongueOut" in names else None
        parts = model.parts
        self.ok = self.k is not None and parts is not None and {"tongue", "lower_teeth"} <= set(parts.names)
        if not self.ok:
            return
        self.part = parts.part("tongue")
        T, L = parts.vertices[self.part], parts.vertices[parts.part("lower_teeth")]
        front = L[:, 2] > L[:, 2].max() - 0.004                  # the incisors: within 4 mm of the arch's front
        edge = L[front, 1].max()
        lo, hi = T.min(0), T.max(0)
        self.rest = T
        self.x_mid, self.y_mid = 0.5 * (lo[0] + hi[0]), 0.5 * (lo[1] + hi[1])
        self.s = _smoothstep((T[:, 2] - lo[2]) / max(hi[2] - lo[2], 1e-9))
        lip = model.curves.get("lip_inner_lower") if model.curves else None
        tip = model.neutral[np.asarray(lip)[len(lip) // 2], 2] + OUT_PAST_LIPS if lip is not None and len(lip) \
            else L[:, 2].max() + OUT_PAST_INCISORS
        self.reach = tip - hi[2]
        half = 0.5 * (hi[1] - lo[1]) * THIN
        self.lift = edge + CLEARANCE + half - self.y_mid

    def weight(self, p):
        """tongueOut's weight in p (K+6,) or weights (K,), clipped to [0, 1]; 0 without it."""
        return float(np.clip(np.asarray(p, float)[self.k], 0, 1)) if self.ok else 0.0

    def out(self, w):
        """The tongue's rest vertices (n, 3) m at tongueOut w, in the jaw's rest frame."""
        T = self.rest.copy()
        sw = self.s * w
        T[:, 2] += self.reach * sw
        T[:, 1] += sw * ((self.rest[:, 1] - self.y_mid) * (THIN - 1) + self.lift)
        T[:, 0] = self.x_mid + (self.rest[:, 0] - self.x_mid) * (1 + sw * (NARROW - 1))
        return T

    def rest_parts(self, vertices, p):
        """The inner parts' rest vertices (P, 3) with the tongue at p's tongueOut (a new array
        when it moves, ``vertices`` itself otherwise)."""
        w = self.weight(p)
        if w <= 0:
            return vertices
        x = np.array(vertices, float)
        x[self.part] = self.out(w)
        return x


def _smoothstep(t):
    t = np.clip(t, 0, 1)
    return t * t * (3 - 2 * t)
