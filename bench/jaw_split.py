"""Imported jaw blendshapes: how much of each is the jaw, and how well the muscle simulation
follows the rest (ICT-FaceKit, ../shared/data/ict-facekit).

    python bench/jaw_split.py [--resolution 0.3] [--shapes jawOpen,jawLeft,jawForward,mouthSmile_L]

Writes the ICT neutral's blendshapes as OBJ files (neutral + delta, the user's route), builds
an actor with ``build-model --blendshapes`` semantics, and prints per shape: the split jaw
(rotation in degrees, translation in mm), the mean offset over the fitted skin before and
after the split, and the distance of the driven simulation at (shape = 1, its jaw) to the
imported shape (mean / median / 95th percentile over the vertices the shape moves by > 1 mm).
Each line also gives the deepest penetration of the solved state's contacts (flesh on flesh,
on the cranium, on the jaw), and the creases of the simulated skin: how far each vertex lies
off its neighbours' mean beyond the imported shape's own (99.9th percentile / max, mm), with
the model's smooth skin embedding and with the barycentric one it replaced.
``--no-contact`` adds the simulation without collision penalties.
The template's own jawOpen is given for comparison. With ``--unsplit`` each jaw shape is
also simulated as imported (the whole offset as the blendshape, jaw closed; the muscle
tracks recomputed), as the builder did before the split.
"""
from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
from _common import SHARED
import trimesh

import invface
from invface.mesh.embedding import barycentric_matrix, embedding_matrix
from invface.io.meshes import read_mesh
from invface.mesh.triangles import umbrella
from invface.morph.build import build_model
from invface.sim.contact import TriangleContacts
from invface.sim.driven import DrivenSimulation

ICT = SHARED / "ict-facekit"


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--resolution", type=float, default=0.3, help="template size factor")
    ap.add_argument("--shapes", default="jawOpen,jawLeft,jawForward,mouthSmile_L")
    ap.add_argument("--unsplit", action="store_true", help="also simulate the jaw shapes unsplit")
    ap.add_argument("--no-contact", action="store_true", help="also simulate without collision penalties")
    a = ap.parse_args()
    if not (ICT / "neutral.obj").exists():
        raise SystemExit(f"{ICT}: ICT-FaceKit data not found")
    V, F = read_mesh(ICT / "neutral.obj")
    ex = np.load(ICT / "expressions.npz")
    names = a.shapes.split(",")
    tpl = invface.template.build(resolution=a.resolution, expressions=False)
    with tempfile.TemporaryDirectory() as tmp:
        for n in names:
            d = ex["deltas"][list(ex["names"]).index(n)]
            trimesh.Trimesh(V + d, F, process=False).export(Path(tmp) / f"{n}.obj")
        t0 = time.perf_counter()
        model, res = build_model(ICT / "neutral.obj", blendshapes=tmp, template=tpl, expressions="none")
    print(f"built in {time.perf_counter() - t0:.1f} s")
    t0 = time.perf_counter()
    W = embedding_matrix(model.rest_positions, model.tets, model.neutral, model.embed_tets, model.embed_weights,
                         model.meta["skin_embedding"])
    print(f"skin embedding {model.meta['skin_embedding']}: {W.nnz / W.shape[0]:.1f} weights per skin vertex, "
          f"{time.perf_counter() - t0:.2f} s to make (as on each load)")
    split, targets = res.stats["jaw_split"], {}
    sim = DrivenSimulation(model)
    free = DrivenSimulation(model, contact=False) if a.no_contact else None
    for n in names:
        j = np.array(model.meta["blendshape_jaw"][n])
        p = model.parameters({"weights": {n: 1.0}, "jaw": j})
        target = model.surface_model("blendshape").surface(p)
        moved = np.linalg.norm(target - model.neutral, axis=1) > 0.001
        t0 = time.perf_counter()
        r = sim.solve(p)
        sec = time.perf_counter() - t0
        e = np.linalg.norm(sim.surface_of(r) - target, axis=1)[moved] * 1000
        s = split.get(n)
        head = (f"jaw {np.degrees(j[:3]).round(1).tolist()} deg, {(j[3:] * 1000).round(1).tolist()} mm; mean "
                f"offset {s['mean_before_mm']:.2f} -> {s['mean_after_mm']:.2f} mm" if s else "not a jaw shape")
        print(f"{n}: {head}; simulation vs imported {e.mean():.2f} / {np.median(e):.2f} / "
              f"{np.quantile(e, 0.95):.2f} mm ({sec:.1f} s); {deepest(sim, r)}; {creases(model, r.X, target)}")
        if a.no_contact:
            e = np.linalg.norm(free.surface(p) - target, axis=1)[moved] * 1000
            print(f"    without contacts: {e.mean():.2f} / {np.median(e):.2f} / {np.quantile(e, 0.95):.2f} mm")
        if s:
            targets[n] = target
    own = invface.template.build(resolution=a.resolution)          # with its simulated expressions
    p = own.parameters({"weights": {"jawOpen": 1.0}, "jaw": own.meta["blendshape_jaw"]["jawOpen"]})
    own_sim = DrivenSimulation(own)
    print(f"the template's own jawOpen (simulated when it was built): {deepest(own_sim, own_sim.solve(p))}")
    for n, target in targets.items() if a.unsplit else ():
        print(f"{n} unsplit: {unsplit(model, n, target)}")


def deepest(ds, result):
    """The deepest penetration (mm) of the acting contacts of a DrivenSimulation's solved
    state: flesh on flesh, flesh on the cranium (upper teeth), flesh on the jaw (lower teeth)."""
    c = ds.sim.contacts.of(TriangleContacts)
    if c is None or not len(c):
        return "no contacts"
    M = ds.model.jaw_matrix(ds.split(result.p)[1])
    g = np.where(c.acting(result.X, M), -c.gaps(result.X, M) * 1000, 0.0)
    return "deepest contact " + ", ".join(f"{k} {g[m].max(initial=0):.1f}" for k, m in c.kinds().items()) + " mm"


def creases(model, X, target):
    """The simulated skin's creases: the umbrella Laplacian |mean of neighbours - x| (mm) of
    the embedded surface beyond that of ``target``, 99.9th percentile / max, for the model's
    embedding and for the barycentric one (embed_tets/embed_weights)."""
    out, own = [], umbrella(target, model.triangles)
    for W in (model.embedding_matrix(), barycentric_matrix(model.tets, model.embed_tets, model.embed_weights, len(X))):
        c = (umbrella(W @ X, model.triangles) - own) * 1000
        out.append(f"{np.quantile(c, 0.999):.2f} / {c.max():.2f}")
    return f"creases {out[0]} mm (barycentric {out[1]} mm)"


def unsplit(model, name, target):
    """The simulation of shape ``name`` imported whole (jaw closed): its error, or the failure.
    Changes ``model``'s blendshape and tracks in place."""
    from invface.errors import InvfaceError
    from invface.sim.poisson import track_displacements
    k = model.blendshape_names.index(name)
    m = model
    m.blendshapes[k] = target - m.neutral
    m.track_displacements = track_displacements(m)
    p = m.parameters({name: 1.0})
    try:
        x = DrivenSimulation(m).surface(p)
    except InvfaceError as e:
        return f"failed ({str(e).splitlines()[0][:90]})"
    moved = np.linalg.norm(target - m.neutral, axis=1) > 0.001
    err = np.linalg.norm(x - target, axis=1)[moved] * 1000
    return f"simulation vs imported {err.mean():.2f} / {np.median(err):.2f} mm"


if __name__ == "__main__":
    main()
