"""ARKit's 52 controls (model.arkit): names, the built-in head's ARKit controls and the jaw, the
map from the older FACS-style controls, aliases in both directions, and the arkit dict every
fit.json carries."""
import numpy as np
import pytest

from invface.errors import ControlsError
from invface.model import FitVector
from invface.model.arkit import (ARKIT_NAMES, LEGACY, OPPOSITES, arkit_name, arkit_values, drives,
                                 opposite_pairs, translate, unsupported)
from invface.model.rig import JAW_UPPER


def test_the_52_names():
    assert len(ARKIT_NAMES) == 52 == len(set(ARKIT_NAMES))
    assert ARKIT_NAMES[0] == "eyeBlinkLeft" and ARKIT_NAMES[-1] == "tongueOut"    # Live Link Face's order
    assert all(t in ARKIT_NAMES for twins in LEGACY.values() for t in twins)


def test_names_are_read_in_every_style():
    assert arkit_name("mouthSmileLeft") == "mouthSmileLeft"
    assert arkit_name("mouthSmile_L") == "mouthSmileLeft" and arkit_name("eyeLookIn_R") == "eyeLookInRight"
    assert arkit_name("browInnerUp_L") == arkit_name("browInnerUp_R") == "browInnerUp"   # ICT splits it
    assert arkit_name("lipCornerPull_R") == "mouthSmileRight"
    assert arkit_name("browDown") is None and drives("browDown") == ("browDownLeft", "browDownRight")
    assert arkit_name("lipsPart") is None and drives("lipsPart") == ()
    assert drives("jawOpen") == ()          # ARKit's jawOpen reads the jaw bone, not a shape


def test_opposite_controls_are_paired_in_every_naming_style():
    """The prior's opposite pairs (eye up / down, blink / wide, smile / frown, ...) are found by
    ARKit, ICT-style and FACS-style names; one legacy control can sit in two pairs."""
    assert all(a in ARKIT_NAMES and b in ARKIT_NAMES for a, b in OPPOSITES)
    arkit = [n for n in ARKIT_NAMES if not n.startswith("jaw")]
    found = {(arkit[i], arkit[j]) for i, j in opposite_pairs(arkit)}
    assert found == set(OPPOSITES)
    ict = ["eyeLookUp_L", "eyeLookDown_L", "eyeLookUp_R", "mouthSmile_R", "mouthFrown_R", "mouthLeft"]
    assert {(ict[i], ict[j]) for i, j in opposite_pairs(ict)} == {("eyeLookUp_L", "eyeLookDown_L"),
                                                                  ("mouthSmile_R", "mouthFrown_R")}
    legacy = ["browDown", "browOuterUp_L", "browOuterUp_R", "eyeBlink_L"]
    assert {(legacy[i], legacy[j]) for i, j in opposite_pairs(legacy)} == {("browDown", "browOuterUp_L"),
                                                                          ("browDown", "browOuterUp_R")}


def test_the_prior_charges_a_pair_set_together_and_not_one_alone():
    """A face makes one control of an opposite pair at a time: the pair's rows are 0 with one
    set, between the smaller weight and twice it with both (in the prior's units), and their
    Jacobian matches finite differences."""
    from invface.fit.priors import OPPOSITE_PRIOR, opposite_rows, regulariser
    vec = FitVector([n for n in ARKIT_NAMES if not n.startswith("jaw")])
    up, down = vec.blendshape_names.index("eyeLookUpLeft"), vec.blendshape_names.index("eyeLookDownLeft")
    z = np.zeros(vec.size)
    z[up] = 0.8
    assert np.allclose(opposite_rows(z, vec, 1.0)[0], 0)
    z[down] = 0.3
    r = opposite_rows(z, vec, 1.0)[0] / np.sqrt(OPPOSITE_PRIOR)
    assert np.count_nonzero(r) == 1 and 0.3 < r.max() < 2 * 0.3
    z = np.random.default_rng(3).uniform(0, 1, vec.size)
    r, J = regulariser(z, vec, 400.0, relief=np.full(vec.P, 0.02))
    assert len(r) == vec.P + len(OPPOSITES)
    for k in range(vec.K):
        e = np.zeros(vec.size)
        e[k] = 1e-6
        fd = (regulariser(z + e, vec, 400.0, relief=np.full(vec.P, 0.02))[0]
              - regulariser(z - e, vec, 400.0, relief=np.full(vec.P, 0.02))[0]) / 2e-6
        assert np.allclose(fd, J[:, k], atol=1e-6), vec.blendshape_names[k]


def test_values_of_the_built_in_heads_controls_and_jaw(small_expressive_model):
    m = small_expressive_model
    vec = FitVector.of(m)
    p = m.parameters({"weights": {"mouthSmileLeft": 0.7, "browInnerUp": 0.4, "mouthRollLower": 0.9,
                                  "jawOpen": 0.8},
                      "jaw": [0.3, 0.05, 0.0, 0.004, 0.0, -0.002]})
    a = arkit_values(m.blendshape_names, p[vec.weights], p[vec.jaw])
    assert list(a) == list(ARKIT_NAMES) and all(0.0 <= v <= 1.0 for v in a.values())
    assert a["mouthSmileLeft"] == 0.7 and a["mouthSmileRight"] == 0.0 and a["mouthRollLower"] == 0.9
    assert a["browInnerUp"] == pytest.approx(0.4)
    # the jaw's four read the jaw bone, whatever the weight of the soft tissue's jawOpen shape
    assert a["jawOpen"] == pytest.approx(0.3 / JAW_UPPER[0]) and a["jawLeft"] == pytest.approx(0.004 / 0.008)
    assert a["jawRight"] == 0.0 and a["jawForward"] == 0.0          # clipped at 0: it moved back
    missing = unsupported(m.blendshape_names)
    assert missing == []
    d = vec.to_dict(p.tolist() + [0.0] * 6)
    assert d["arkit"] == a and d["arkit_unsupported"] == missing


def test_values_of_an_actor_built_with_the_old_facs_style_controls():
    """A bundle built before the ARKit shapes (or with --expressions simulate) speaks ARKit
    through LEGACY: one to one, one to two, two to one, and lipsPart as an extra."""
    names = list(LEGACY) + ["lipsPart", "jawOpen"]
    w = np.zeros(len(names))
    for n, v in {"lipCornerPull_L": 0.7, "browInnerUp_L": 0.4, "browDown": 0.5, "lipsPart": 0.9}.items():
        w[names.index(n)] = v
    a = arkit_values(names, w, np.zeros(6))
    assert a["mouthSmileLeft"] == 0.7 and a["browInnerUp"] == pytest.approx(0.2)     # the mean of its halves
    assert a["browDownLeft"] == a["browDownRight"] == 0.5
    assert a["mouthLowerDownLeft"] == 0.0                       # lipsPart stays an extra
    assert {"tongueOut", "eyeLookInLeft", "mouthRollLower", "cheekPuff"} <= set(unsupported(names))


def test_aliases_in_both_directions(small_expressive_model):
    m = small_expressive_model
    assert np.array_equal(m.parameters({"mouthSmileLeft": 0.7, "browInnerUp": 0.4}),
                          m.parameters({"lipCornerPull_L": 0.7, "browInnerUp_L": 0.4, "browInnerUp_R": 0.4}))
    assert translate({"mouthSmile_L": 0.5}, m.blendshape_names) == {"mouthSmileLeft": 0.5}
    # a model with the old names reads ARKit's
    old = list(LEGACY)
    assert translate({"browDownLeft": 0.6, "browDownRight": 0.2}, old) == {"browDown": pytest.approx(0.4)}
    assert translate({"mouthSmile_L": 0.5}, old) == {"lipCornerPull_L": 0.5}
    # the ARKit-named head reads the old names (old fit.json files)
    assert translate({"lipCornerPull_R": 0.3, "browDown": 0.5, "browInnerUp_L": 0.2, "browInnerUp_R": 0.4},
                     m.blendshape_names) == {"mouthSmileRight": 0.3, "browDownLeft": 0.5, "browDownRight": 0.5,
                                             "browInnerUp": pytest.approx(0.3)}
    with pytest.raises(ControlsError, match="unknown blendshape 'smile'.*ARKit"):
        m.parameters({"smile": 1.0})
    with pytest.raises(ControlsError, match="unknown blendshape 'jawLeft'"):     # a jaw DOF there, not a shape
        translate({"jawLeft": 1.0}, old)


def test_a_sequences_curves_carry_the_arkit_columns():
    from invface.pipeline.outputs import curve_rows
    recs = [{"_name": f"f{i}", "frame": i, "time": i / 24, "weights": {"lipCornerPull_L": 0.1 * i},
             "arkit": {"mouthSmileLeft": 0.1 * i, "jawOpen": 0.2}, "flagged": "x" if i == 1 else ""} for i in range(3)]
    rows = curve_rows(recs)
    assert [r["arkit_jawOpen"] for r in rows] == [0.2, 0.2, 0.2]
    assert rows[1]["arkit_mouthSmileLeft"] == pytest.approx(0.1)     # a flagged frame: from its neighbours
