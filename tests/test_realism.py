import json

import numpy as np

from conftest import ICT, load_ict_neutral
from invface.measure.proportions import MEASURES, multipie_points, proportions


def test_template_proportions_match_a_real_head(default_model):
    """Ten facial proportions within 15 % of the ICT-FaceKit neutral (prints the table)."""
    V = load_ict_neutral()
    lm = np.array(json.loads((ICT / "landmarks.json").read_text())["landmarks_68_multipie"])
    ref = proportions(multipie_points(V, lm))
    m = default_model
    mine = proportions({k: m.neutral[v] for k, v in m.landmarks.items()})
    print(f"\n{'measure':42s} {'ICT':>8s} {'template':>9s} {'diff':>7s}")
    worst = 0.0
    for k in MEASURES:
        d = mine[k] / ref[k] - 1
        worst = max(worst, abs(d))
        print(f"{k:42s} {ref[k] * 1000:6.1f}mm {mine[k] * 1000:7.1f}mm {100 * d:+6.1f}%")
    assert worst < 0.15
