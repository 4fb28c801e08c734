"""The template's eyes (issue 29): the fissure at rest, a blink in both model kinds, the lid
ring alone, and the lids' sliding contact.

    python bench/eyes.py [--resolution 1]

Prints the fissure height (mm, between the middles of the eye_L lid curves) at rest, with
eyeBlinkLeft at 0.5 and 1 in the rig and in the simulation (and the right eye's in the
simulation), with the palpebral orbicularis alone at full activation (no tracks), and how many
lid vertices slide on the eyeballs.
"""
import argparse
import time

import numpy as np

import invface
from invface.sim.contact import EyeballContacts
from invface.sim.quasistatic import Simulator


def fissure(model, x, side="L"):
    up, lo = model.curves[f"eye_{side}_upper"], model.curves[f"eye_{side}_lower"]
    return 1000 * np.linalg.norm(x[up[len(up) // 2]] - x[lo[len(lo) // 2]])


def main(resolution):
    m = invface.template.build(resolution=resolution)
    print(f"resolution {resolution}: fissure at rest {fissure(m, m.neutral):.2f} mm")
    for w in (0.5, 1.0):
        rig = m.surface({"eyeBlinkLeft": w}, kind="blendshape")
        t = time.perf_counter()
        sim = m.surface({"eyeBlinkLeft": w}, kind="simulation")
        print(f"  eyeBlinkLeft {w}: rig {fissure(m, rig):.2f} mm, simulation {fissure(m, sim):.2f} mm "
              f"({time.perf_counter() - t:.1f} s), right eye {fissure(m, sim, 'R'):.2f} mm")
    s = Simulator(m)
    a = np.zeros(len(s.muscle_names))
    a[s.muscle_names.index("orbicularis_oculi_palpebralis_L")] = 1.0
    r = s.solve(a)
    print(f"  palpebral orbicularis alone at 1.0: {fissure(m, m.embedded_surface(r.X)):.2f} mm "
          f"({r.iterations} Newton iterations)")
    print(f"  lid vertices paired with the eyeballs: {len(s.contacts.of(EyeballContacts))}; "
          f"cranium-fixed vertices {len(m.fixed_cranium)}")


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--resolution", type=float, default=1.0)
    main(ap.parse_args().resolution)
