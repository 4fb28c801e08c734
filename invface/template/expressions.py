"""Expression blendshapes simulated from muscle activations (paper 000 Sec. 4), the head's
kinematic blinks, and the activation-length curves' calibration.

The built-in head's shapes are sculpted (``arkit_shapes``); its blinks are made here
(``add_blinks``). ``ACTION_UNITS`` are the FACS-style units the head had before, simulated on
an actor's own anatomy by ``build-model --expressions simulate``. Each is a set of muscle
activations (and, for jaw open, a jaw rotation). It is simulated with the quasistatic muscle model, the render skin is read off
the flesh through the embedding, and the blendshape delta is the pre-skinning displacement:
for shapes with a jaw rotation the jaw's linear blend skinning is undone per vertex, so that
Eq. 1 with the same jaw parameters and weight 1 reproduces the simulated skin exactly.
"""
from __future__ import annotations

import numpy as np

# name: ({muscle base name: activation}, sides, jaw (6,) or None)
# sides 'L'/'R' activate only that side of paired muscles, 'LR' both; midline muscles always.
ACTION_UNITS = {
    "browInnerUp_L": ({"frontalis_medialis": 0.8}, "L", None),                       # AU1
    "browInnerUp_R": ({"frontalis_medialis": 0.8}, "R", None),
    "browOuterUp_L": ({"frontalis_lateralis": 0.8}, "L", None),                      # AU2
    "browOuterUp_R": ({"frontalis_lateralis": 0.8}, "R", None),
    "browDown": ({"corrugator_supercilii": 0.8, "procerus": 0.7}, "LR", None),        # AU4
    "cheekRaise": ({"orbicularis_oculi": 0.5, "zygomaticus_minor": 0.3}, "LR", None),  # AU6
    "noseWrinkle": ({"levator_labii_superioris_alaeque_nasi": 0.8, "nasalis": 0.6,
                     "procerus": 0.5}, "LR", None),                                     # AU9
    "upperLipRaise": ({"levator_labii_superioris": 0.8}, "LR", None),                # AU10
    "lipCornerPull_L": ({"zygomaticus_major": 0.8}, "L", None),                       # AU12
    "lipCornerPull_R": ({"zygomaticus_major": 0.8}, "R", None),
    "dimpler": ({"buccinator": 0.8}, "LR", None),                                    # AU14
    "lipCornerDepress_L": ({"depressor_anguli_oris": 0.8}, "L", None),                # AU15
    "lipCornerDepress_R": ({"depressor_anguli_oris": 0.8}, "R", None),
    "lowerLipDepress": ({"depressor_labii_inferioris": 0.8}, "LR", None),             # AU16
    "chinRaise": ({"mentalis": 0.8}, "LR", None),                                    # AU17
    "lipPucker": ({"orbicularis_oris": 0.7}, "LR", None),                            # AU18
    "lipStretch": ({"risorius": 0.8, "platysma": 0.5}, "LR", None),                  # AU20
    "lipFunnel": ({"orbicularis_oris": 0.45, "levator_labii_superioris": 0.3,
                   "depressor_labii_inferioris": 0.3}, "LR", None),                    # AU22
    "lipPress": ({"orbicularis_oris": 0.5, "mentalis": 0.3}, "LR", None),             # AU24
    "lipsPart": ({"depressor_labii_inferioris": 0.5, "levator_labii_superioris": 0.4},
                 "LR", [0.03, 0, 0, 0, 0, 0]),                                         # AU25
    "jawOpen": ({}, "LR", [0.22, 0, 0, 0, 0, 0]),                                     # AU26/27
}


# The lids' closing (AU45) is not simulated: the open lids are the flesh's stress-free rest
# state, and closing them stretches the upper lid over 10 mm of eyeball, which the lids'
# muscle ring does not do against the elastic flesh (it narrowed the fissure from 9.9 to
# 7.5 mm at full activation, and a ring's inward pull vanishes as its arcs straighten).
# Each blink is the lids rotated back over the eyeball onto the closed slit they were opened
# from (eyelids.open_lids), with the palpebral ring's activation recorded for Eq. 9's curve;
# the simulation follows it through the palpebral tracks (Eq. 5).
BLINKS = {"eyeBlinkLeft": ({"orbicularis_oculi_palpebralis": 0.8}, "L", None),
          "eyeBlinkRight": ({"orbicularis_oculi_palpebralis": 0.8}, "R", None)}


def add_blinks(model, closed):
    """Append the BLINKS shapes to a model's blendshapes (in place): closed (V,3) m is the
    render skin with the lids closed (before ``eyelids.open_lids``); eyeBlinkLeft moves the
    vertices with x > 0 onto it, eyeBlinkRight those with x < 0."""
    x = model.neutral
    delta = np.asarray(closed, float) - x
    names, deltas, acts = [], [], []
    for name, unit in BLINKS.items():
        side = x[:, 0] > 0 if unit[1] == "L" else x[:, 0] < 0
        names.append(name)
        deltas.append(np.where(side[:, None], delta, 0.0))
        acts.append(activations_for(unit, model.muscles))
    model.blendshape_names = list(model.blendshape_names) + names
    model.blendshapes = np.concatenate([model.blendshapes, np.array(deltas)])
    model.blendshape_activations = np.concatenate([model.blendshape_activations, np.array(acts)])
    stats = {n: {"kinematic": True, "max_displacement_mm": float(np.linalg.norm(d, axis=1).max() * 1000)}
             for n, d in zip(names, deltas)}
    model.meta = {**model.meta,
                  "blendshape_jaw": {**model.meta.get("blendshape_jaw", {}), **{n: [0.0] * 6 for n in names}},
                  "blendshape_sims": {**model.meta.get("blendshape_sims", {}), **stats}}
    return model


def activations_for(unit, muscles):
    """Activation vector (M,) for action-unit spec (acts, sides, jaw) over ``muscles``."""
    acts, sides, _ = unit
    a = np.zeros(len(muscles))
    for i, m in enumerate(muscles):
        base = m.name[:-2] if m.side in ("L", "R") else m.name
        if base in acts and (m.side == "M" or m.side in sides):
            a[i] = acts[base]
    return a


def unskin(x, weights, M):
    """Invert linear blend skinning per vertex: p with (1-w) p + w (R p + t) = x; x (V,3)."""
    R, t = M[:3, :3], M[:3, 3]
    A = (1 - weights)[:, None, None] * np.eye(3) + weights[:, None, None] * R
    return np.linalg.solve(A, (x - weights[:, None] * t)[..., None])[..., 0]


def simulate_blendshapes(model, units=None, progress=None):
    """Simulate the action units on ``model`` and store them as its blendshapes (in place).

    Sets blendshape_names, blendshapes (K,V,3), blendshape_activations (K,M) and
    meta['blendshape_jaw'] (jaw parameters paired with each shape). Returns the model.
    """
    from ..sim.quasistatic import Simulator

    units = units or ACTION_UNITS
    sim = Simulator(model)
    names, deltas, acts, jaws, stats = [], [], [], [], {}
    items = list(units.items())
    for i, (name, unit) in enumerate(items):
        if progress:
            progress(f"expression {i + 1}/{len(items)}: {name}")
        a = activations_for(unit, model.muscles)
        jaw = np.zeros(6) if unit[2] is None else np.asarray(unit[2], float)
        res = sim.solve(a, jaw=jaw)
        x = model.embedded_surface(res.X)
        pre = unskin(x, model.jaw_weights, model.jaw_matrix(jaw)) if np.any(jaw) else x
        names.append(name)
        deltas.append(pre - model.neutral)
        acts.append(a)
        jaws.append(jaw.tolist())
        stats[name] = {"iterations": res.iterations, "seconds": round(sum(res.seconds.values()), 2),
                       "volume_change": sim.volume_change(res),
                       "max_displacement_mm": float(np.linalg.norm(x - model.neutral, axis=1).max() * 1000)}
    model.blendshape_names = names
    model.blendshapes = np.array(deltas)
    model.blendshape_activations = np.array(acts)
    model.meta = {**model.meta, "blendshape_jaw": dict(zip(names, jaws)), "blendshape_sims": stats}
    return model


SLACK_MAX = 0.3       # the largest slack (centre-line shortening with no activation) tried
MIN_RAMP = 0.04       # the least shortening between activation 0 and 1: da/dL <= 1 / (MIN_RAMP L0)
GRID_STEP = 0.0025    # the grid of slacks and full-activation shortenings


def activation_ramp(strain, targets, min_ramp=MIN_RAMP):
    """The ramp a = clip((e - e0) / (e1 - e0), 0, 1) of centre-line shortening e = 1 - L/L0
    that fits ``targets`` best in least squares: strain and targets (N,) over N samples.
    Returns (e0, e1): the slack e0, up to which the muscle stays passive, and the shortening e1
    of full activation, e1 - e0 >= min_ramp."""
    e0 = np.arange(0.0, SLACK_MAX + 1e-9, GRID_STEP)
    width = np.arange(min_ramp, min_ramp + SLACK_MAX + 1e-9, GRID_STEP)
    a = np.clip((strain[None, None, :] - e0[:, None, None]) / width[None, :, None], 0, 1)
    sse = ((a - targets) ** 2).sum(-1)
    i, j = np.unravel_index(np.argmin(sse), sse.shape)      # the first minimum: least slack
    return float(e0[i]), float(e0[i] + width[j])


LEVELS = (0.25, 0.5, 0.75, 1.0)    # the weights each shape is calibrated at


def calibrate_activation_curves(model, levels=LEVELS):
    """Fit each muscle's activation-length curve (Eq. 9) to the model's own shapes (in place).

    Each shape k at weight w in ``levels``, with w times its jaw (Eq. 8), shortens muscle m's
    centre line to L/L0 = 1 - e, and is taken to engage m at w A_km (A:
    ``model.blendshape_activations``, what made the shape or what it is taken to engage). The
    curve is the ramp of ``activation_ramp`` fitted to those pairs over every shape, the shapes
    that do not engage m included: a muscle carried along by its neighbours in another shape
    stays passive up to its slack, so a fit's activations name the muscles that make the
    expression, as paper 000's Fig. 6 reads them. A muscle that no shape engages gets a slack
    beyond every shape's shortening. Needs model.track_displacements. Returns the slacks (M,).
    """
    from ..sim.tracks import MuscleTracks

    tr = MuscleTracks(model, model.track_displacements, np.ones(len(model.rest_positions), bool), 1.0)
    jaws = model.meta.get("blendshape_jaw", {})
    K = len(model.blendshape_names)
    L0 = np.array([m.rest_length for m in model.muscles])
    strain, target = [], []
    for k, name in enumerate(model.blendshape_names):
        jaw = np.asarray(jaws.get(name, np.zeros(6)), float)
        for w in levels:
            b = np.zeros(K)
            b[k] = w
            strain.append(1 - tr.evaluate(b, model.jaw_matrix(w * jaw)).lengths / L0)
            target.append(w * model.blendshape_activations[k])
    strain, target = np.array(strain), np.array(target)
    slacks = np.zeros(len(model.muscles))
    for i, m in enumerate(model.muscles):
        e0, e1 = activation_ramp(strain[:, i], target[:, i])
        slacks[i] = e0
        m.activation_curve = np.array([[1 - e1, 1.0], [1 - e0, 0.0], [1.5, 0.0]])
    return slacks
