"""Derivative benchmark for the driven simulation x(w) (issue 4).

    python bench/gradient.py [--resolution 1] [--fd]

Prints for the template: the Poisson precompute seconds (Eq. 10-11, all K blendshapes),
the forward solve (cold from rest and warm), the adjoint gradient of a surface loss
(Sensitivity set-up + the adjoint solve) after the cold solve and after a warm one, the
gradient/forward ratios, the full Jacobian (all K+6 controls by tangent solves); then the same
gradient for a model with twice as many blendshapes, to show that its cost does not grow with K.

``--fd`` checks the adjoint instead (issue 25): the gradient of L(p) = sum(g * surface(p))
(random g) against central differences of solves that each start from rest, on every control,
at mouthSmileLeft 0.3, mouthPucker 0.3, browInnerUp 0.2, jaw opened 0.05 rad (contacts on);
then the same controls solved warm from other states, against the cold surface.
"""
import argparse
import time

import numpy as np
from _common import timed

import invface
from invface.model import FitVector
from invface.sim.adjoint import Sensitivity, cold_finite_differences
from invface.sim.contact import TriangleContacts
from invface.sim.driven import DrivenSimulation
from invface.sim.poisson import track_displacements


def controls(ds):
    names = ds.parameter_names
    p = np.zeros(len(names))
    for n, v in (("mouthSmileLeft", 0.7), ("mouthSmileRight", 0.6), ("browInnerUp", 0.5),
                 ("cheekSquintLeft", 0.4), ("jaw_rx", 0.08)):
        p[names.index(n)] = v
    return p


def gradient_seconds(ds, p, gx, warm_from=None):
    """Seconds of one adjoint gradient right after a solve of p: cold, or warm from the state
    ``warm_from`` (a fit's case: a warm solve, then its gradient)."""
    r = ds.solve(p, warm=warm_from)
    t = time.perf_counter()
    S = Sensitivity(ds, r)
    g = S.surface_gradient(gx)
    return time.perf_counter() - t, r, g


def finite_difference_check(model):
    """Adjoint vs central differences of cold solves, per control (prints a table)."""
    ds = DrivenSimulation(model)
    p = model.parameters({"weights": {"mouthSmileLeft": 0.3, "mouthPucker": 0.3, "browInnerUp": 0.2},
                          "jaw": [0.05, 0, 0, 0, 0, 0]})
    r, t = timed(lambda: ds.solve(p, warm=None, rtol=1e-10))
    acting = ds.sim.contacts.of(TriangleContacts).acting(r.X, model.jaw_matrix(ds.split(p)[1]))
    print(f"  cold solve {t:.1f} s, {acting.sum()} contacts acting")
    gx = np.random.default_rng(0).standard_normal(model.neutral.shape)
    g = ds.surface_vjp(p, gx)
    fd = cold_finite_differences(ds, p, gx)
    err = np.abs(g - fd) / np.maximum(np.abs(fd), 1e-3 * np.abs(fd).max())
    for n, a, b, e in zip(ds.parameter_names, g, fd, err):
        print(f"    {n:24s} adjoint {a: .6e}  cold FD {b: .6e}  rel err {e:.1e}")
    print(f"  largest relative error {err.max():.1e} ({ds.parameter_names[int(err.argmax())]})")
    # path dependence: the same controls solved warm from other states reach the same surface
    cold = ds.surface_of(r)
    far = ds.solve(model.parameters({"weights": {"mouthSmileRight": 0.8, "jawOpen": 0.6},
                                     "jaw": [0.3, 0, 0, 0, -0.002, 0.002]}), warm=None)
    for label, start in (("the last finite-difference state", "last"), ("a wide smile with the jaw open", far)):
        d = np.linalg.norm(ds.surface_of(ds.solve(p, warm=start, rtol=1e-10)) - cold, axis=1)
        print(f"  warm from {label}: largest surface difference to the cold solve {d.max() * 1000:.2e} mm")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--resolution", type=float, default=1.0)
    ap.add_argument("--fd", action="store_true", help="check the adjoint against cold finite differences")
    a = ap.parse_args()
    model = invface.template.build(resolution=a.resolution)
    if a.fd:
        return finite_difference_check(model)
    K = len(model.blendshape_names)
    print(f"template resolution {a.resolution:g}: {len(model.tets)} tets, {len(model.neutral)} surface "
          f"vertices, K = {K} blendshapes")
    _, t_poisson = timed(lambda: track_displacements(model))
    print(f"  Poisson precompute (factorise + {3 * K} right-hand sides): {t_poisson:.2f} s")
    ds, t_setup = timed(lambda: DrivenSimulation(model))
    p = controls(ds)
    r, t_cold = timed(lambda: ds.solve(p, warm=None))
    p2 = p.copy()
    p2[0] += 0.05
    warm = [timed(lambda: ds.solve(p2, warm=r)) for _ in range(3)]
    rw, t_warm = warm[0][0], float(np.median([t for _, t in warm]))
    print(f"  set-up {t_setup:.2f} s; forward cold {t_cold:.2f} s ({r.sim.iterations} it), "
          f"warm {t_warm:.2f} s ({rw.sim.iterations} it, median of 3)")
    gx = np.random.default_rng(0).standard_normal(model.neutral.shape)
    t_grad_w = float(np.median([gradient_seconds(ds, p2, gx, warm_from=r)[0] for _ in range(3)]))
    t_grad, r, g = gradient_seconds(ds, p, gx)
    print(f"  adjoint gradient after the cold solve {t_grad * 1e3:.1f} ms (ratio to the cold solve "
          f"{t_grad / t_cold:.2f}, to the warm one {t_grad / t_warm:.2f}); after the warm solve "
          f"{t_grad_w * 1e3:.1f} ms, median of 3 (ratio to the warm solve {t_grad_w / t_warm:.2f})")
    S = Sensitivity(ds, r)
    S.res.sim.solver                                     # factorised already: Jacobian cost alone
    _, t_jac = timed(S.surface_jacobian)
    print(f"  full Jacobian ({len(p)} controls) {t_jac:.2f} s")

    big = model.replace(
        blendshape_names=model.blendshape_names + [n + "_copy" for n in model.blendshape_names],
        blendshapes=np.concatenate([model.blendshapes, 0.5 * model.blendshapes]),
        blendshape_activations=np.concatenate([model.blendshape_activations] * 2),
        track_displacements=np.concatenate([model.track_displacements, 0.5 * model.track_displacements]))
    ds2 = DrivenSimulation(big)
    vec = FitVector.of(model)
    p_big = FitVector.of(big).controls_vector(np.r_[p[vec.weights], np.zeros(K)], p[vec.jaw])
    t_grad2, _, g2 = gradient_seconds(ds2, p_big, gx)
    print(f"  with 2K = {2 * K} blendshapes: adjoint gradient {t_grad2:.2f} s (K: {t_grad:.2f} s); "
          f"same gradient on the first K: {np.abs(g2[:K] - g[:K]).max() / np.abs(g).max():.1e} rel")


if __name__ == "__main__":
    main()
