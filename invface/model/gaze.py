"""The eyes' gaze: each eyeball turns in 2 DOF about its centre, driven by ARKit's eyeLook
controls, and the lids follow through those controls' sculpted shapes.

An eye's yaw turns it about the model's +Y (positive towards the actor's left, +X) and its
pitch about -X (positive up), so its line of sight is (cos p sin y, sin p, cos p cos y):

    yaw_L   = GAZE_RANGE["Out"] eyeLookOutLeft  - GAZE_RANGE["In"]  eyeLookInLeft
    yaw_R   = GAZE_RANGE["In"]  eyeLookInRight  - GAZE_RANGE["Out"] eyeLookOutRight
    pitch_e = GAZE_RANGE["Up"]  eyeLookUp<e>    - GAZE_RANGE["Down"] eyeLookDown<e>

so the angles are linear in the weights (``gaze_matrix``). 1.0 of a control is the eye turned
by its ``GAZE_RANGE`` (rad): down 0.48 rad, the pitch by which the carried ICT-FaceKit sculpt
of eyeLookDown turns the upper lid's margin about the eye's centre (the upper lid follows a
downward gaze one to one); up 0.44 rad (25 degrees), in and out 0.52 rad (30 degrees), the
eye's comfortable range (the sculpted lids follow those only partly: 0.22 and 0.15 rad).
The eyeball is a sphere, so the lids' sphere contacts (``sim.contact.eyeballs``) hold for
any gaze, and the simulation does not see it.
"""
from __future__ import annotations

import numpy as np

GAZE_RANGE = {"Up": 0.44, "Down": 0.48, "In": 0.52, "Out": 0.52}
EYES = (("L", "Left"), ("R", "Right"))
IRIS_RADIUS = 6.0e-3       # m: the limbus on the template's eyeball (``template.parts.eyeball``)


def fit_sphere(P):
    """Least-squares sphere (centre (3,), radius) through points P (n,3):
    |p|^2 = 2 c.p + (r^2 - |c|^2) solved for c and r."""
    P = np.asarray(P, float)
    A = np.concatenate([2 * P, np.ones((len(P), 1))], 1)
    sol = np.linalg.lstsq(A, np.einsum("ni,ni->n", P, P), rcond=None)[0]
    c = sol[:3]
    return c, float(np.sqrt(sol[3] + c @ c))


def gaze_matrix(names):
    """(4, K): (yaw_L, pitch_L, yaw_R, pitch_R) rad = A @ weights for blendshape names (K,); rows
    are 0 where the model has no eyeLook controls."""
    names = list(names)
    A = np.zeros((4, len(names)))
    sign_out = {"L": 1.0, "R": -1.0}           # looking out turns the left eye to +X, the right to -X
    for e, (s, side) in enumerate(EYES):
        for look, row, sign in (("Out", 0, sign_out[s]), ("In", 0, -sign_out[s]), ("Up", 1, 1.0), ("Down", 1, -1.0)):
            n = f"eyeLook{look}{side}"
            if n in names:
                A[2 * e + row, names.index(n)] = sign * GAZE_RANGE[look]
    return A


def eye_angles(names, weights):
    """{"L": (yaw, pitch), "R": (yaw, pitch)} rad of the eyes at blendshape weights (K,)."""
    a = gaze_matrix(names) @ np.asarray(weights, float)
    return {"L": (float(a[0]), float(a[1])), "R": (float(a[2]), float(a[3]))}


def eye_rotation(yaw, pitch):
    """(3,3): Ry(yaw) Rx(-pitch), turning +Z to the line of sight."""
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    Ry = np.array([[cy, 0, sy], [0, 1, 0], [-sy, 0, cy]])
    Rx = np.array([[1, 0, 0], [0, cp, sp], [0, -sp, cp]])
    return Ry @ Rx


def sight(yaw, pitch):
    """(line of sight (3,), its derivatives (2, 3) by yaw and pitch) for unit radius."""
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    d = np.array([cp * sy, sp, cp * cy])
    return d, np.array([[cp * cy, 0.0, -cp * sy], [-sp * sy, cp, -sp * cy]])


class Eyes:
    """A model's eyeballs: their centres and radii (from the parts named eye_L / eye_R at rest),
    the gaze matrix of its blendshapes, and the positions of the pupils' centres."""

    def __init__(self, model):
        self.sides = [s for s, _ in EYES if model.parts is not None and f"eye_{s}" in model.parts.names]
        self.spheres = {s: fit_sphere(model.parts.mesh(f"eye_{s}")[0]) for s in self.sides}
        self.A = gaze_matrix(model.blendshape_names)
        self.K = len(model.blendshape_names)

    @property
    def turns(self):
        """True when the model has both eyes and eyeLook controls."""
        return len(self.sides) == 2 and bool(np.any(self.A))

    def angles(self, p):
        """(4,) rad: (yaw_L, pitch_L, yaw_R, pitch_R) at parameters p (K+6,) or weights (K,)."""
        return self.A @ np.asarray(p, float)[:self.K]

    def turn_parts(self, parts, x, p):
        """The inner parts' positions x (P,3) with each eyeball turned about its centre by the
        gaze at p (a new array; x is the parts after the jaw, before the head pose)."""
        a = self.angles(p)
        x = np.array(x, float)
        for e, s in enumerate(("L", "R")):
            if s in self.sides and (a[2 * e] or a[2 * e + 1]):
                c, _ = self.spheres[s]
                sl = parts.part(f"eye_{s}")
                x[sl] = (x[sl] - c) @ eye_rotation(a[2 * e], a[2 * e + 1]).T + c
        return x

    def pupils(self, p):
        """(pupil centres (2,3) m of the L and R eyes, their derivatives (2, K+6, 3) by p):
        each eye's front pole, centre + radius x line of sight."""
        a = self.angles(p)
        X, J = np.zeros((2, 3)), np.zeros((2, self.K + 6, 3))
        for e, s in enumerate(("L", "R")):
            c, r = self.spheres[s]
            d, dd = sight(a[2 * e], a[2 * e + 1])
            X[e] = c + r * d
            J[e, :self.K] = r * (self.A[2 * e][:, None] * dd[0] + self.A[2 * e + 1][:, None] * dd[1])
        return X, J

    def iris_ring(self, p, n=16):
        """(2, n, 3) m: points on each eye's limbus (``IRIS_RADIUS`` from the pupil's axis) at p."""
        a = self.angles(p)
        t = np.linspace(0, 2 * np.pi, n, endpoint=False)
        out = np.zeros((2, n, 3))
        for e, s in enumerate(("L", "R")):
            c, r = self.spheres[s]
            h = np.sqrt(max(r * r - IRIS_RADIUS ** 2, 0.0))
            ring = np.stack([IRIS_RADIUS * np.cos(t), IRIS_RADIUS * np.sin(t), np.full(n, h)], 1)
            out[e] = c + ring @ eye_rotation(a[2 * e], a[2 * e + 1]).T
        return out
