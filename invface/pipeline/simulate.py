"""Posing the model by simulation as a function that returns a result: by muscle
activations (and jaw), or by blendshape weights through the blendshape-driven muscle
tracks (paper 000 Sec. 6)."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import InvfaceError


@dataclass
class Simulation:
    """A solved pose: skin x (V, 3) m, the solve's report, the muscle activations (given, or
    read out of the tracks when driven by weights), the flesh's relative volume change and
    the skin's displacement from the neutral (V,) m."""

    surface: np.ndarray
    report: str
    activations: dict
    volume_change: float
    displacement: np.ndarray
    driven: bool
    result: object = field(repr=False, default=None)

    def describe(self, top=8):
        """Lines for a terminal."""
        d = self.displacement
        lines = []
        if self.driven:
            act = sorted(((v, k) for k, v in self.activations.items() if v > 0.01), reverse=True)[:top]
            lines.append("muscle activations from the tracks: " + (", ".join(f"{k} {v:.2f}" for v, k in act) or "none"))
        lines += [self.report, f"skin displacement: max {d.max() * 1000:.2f} mm, mean {d.mean() * 1000:.2f} mm; "
                               f"flesh volume change {self.volume_change * 100:+.3f} %"]
        return lines


def simulate(model, activations=None, jaw=None, weights=None, progress=None):
    """Solve the quasistatic flesh (Eq. 3-6) for muscle ``activations`` {muscle: a in [0, 1]}
    and ``jaw`` (6,) (rad, m), or for blendshape ``weights`` {name: w} (with the jaw) through
    the muscle tracks (Eq. 7-11), whose activations are then reported. progress(iteration,
    relative residual) per Newton step. Returns a Simulation."""
    from ..sim.quasistatic import Simulator
    if weights:
        if activations:
            raise InvfaceError("give muscle activations or blendshape weights, not both: with weights the "
                               "activations follow from the tracks")
        ds = model.surface_model("simulation")
        p = model.parameters({"weights": weights, "jaw": np.zeros(6) if jaw is None else jaw})
        r = ds.solve(p, warm=None, progress=progress)
        res, sim, x = r.sim, ds.sim, ds.surface_of(r)
        acts = {m.name: float(a) for m, a in zip(model.muscles, r.tracks.activations)}
    else:
        sim = Simulator(model)
        res = sim.solve(activations or {}, jaw=jaw, progress=progress)
        x = sim.surface(res)
        acts = {k: float(v) for k, v in (activations or {}).items()}
    return Simulation(x, res.report(), acts, sim.volume_change(res), np.linalg.norm(x - model.neutral, axis=1),
                      bool(weights), res)
