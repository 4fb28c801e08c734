"""Derive the built-in head's ARKit blendshapes from ICT-FaceKit (MIT), and write them to
``invface/template/data/arkit_ict.npz`` beside ICT-FaceKit's licence text.

    python scripts/derive_arkit_shapes.py [--ict ../shared/data/ict-facekit] [-o invface/template/data]

1. The built-in head (resolution 1, anatomy only) is morphed onto ICT-FaceKit's neutral with
   its 53 ARKit-style expressions imported, exactly as ``invface build-model --neutral
   neutral.obj --blendshapes DIR`` does (paper 001's morph; the jaw shapes' rigid jaw motion
   is split out into jaw parameters, morph.jaw).
2. The ICT actor shares the template's topology, vertex for vertex, so each expression's
   offsets are carried back onto the template per vertex, scaled by the ratio of the two
   faces' sizes (``morph.transfer.carry_offsets``).
3. The offsets fade to 0 within 3 cm outside the face (``face_falloff``).
4. ``browInnerUp_L`` and ``_R`` are summed into ARKit's single browInnerUp, and names are
   written in ARKit's spelling (``mouthSmile_L`` -> mouthSmileLeft).

The file holds the template's neutral and triangles at resolution 1 that the offsets belong
to (a template at another resolution carries them by closest point, ``template.arkit``),
the offsets in millimetres (float16) and each jaw shape's jaw parameters. The ICT data
itself is not copied.
"""
from __future__ import annotations

import argparse
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh

ROOT = Path(__file__).resolve().parents[1]
FALLOFF = 0.03          # m: the offsets fade to 0 this far from the face
sys.path.insert(0, str(ROOT))

from invface.io.arrays import savez                       # noqa: E402
from invface.io.meshes import read_mesh                   # noqa: E402
from invface.model.arkit import arkit_name                # noqa: E402
from invface.morph.build import build_model, face_vertices  # noqa: E402
from invface.morph.transfer import carry_offsets         # noqa: E402
from invface.template import build as build_template      # noqa: E402


def face_falloff(model, reach=FALLOFF):
    """Per-vertex weights (V,): 1 on the face (``morph.build.face_vertices``), falling smoothly
    to 0 at ``reach`` m from it. The actor's skin off the ICT scan (the back of the head, the
    neck below the scan) takes its offsets from a smooth extension that does not fade; an
    expression does not move the back of the head."""
    from scipy.spatial import cKDTree
    X = model.neutral
    d = cKDTree(X[face_vertices(model)]).query(X)[0]
    t = np.clip(1 - d / reach, 0, 1)
    return t * t * (3 - 2 * t)


def arkit_spelling(name):
    a = arkit_name(name)
    return a if a is not None else name


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ict", type=Path, default=ROOT.parent / "shared" / "data" / "ict-facekit")
    ap.add_argument("-o", "--out", type=Path, default=ROOT / "invface" / "template" / "data")
    a = ap.parse_args()
    if not (a.ict / "neutral.obj").exists():
        raise SystemExit(f"{a.ict}: ICT-FaceKit not found (neutral.obj, expressions.npz)")
    t0 = time.perf_counter()
    V, F = read_mesh(a.ict / "neutral.obj")
    ex = np.load(a.ict / "expressions.npz")
    names = [str(n) for n in ex["names"]]
    tpl = build_template(resolution=1.0, expressions=False)
    with tempfile.TemporaryDirectory() as tmp:
        for n, d in zip(names, ex["deltas"]):
            trimesh.Trimesh(V + d, F, process=False).export(Path(tmp) / f"{n}.obj")
        actor, res = build_model(a.ict / "neutral.obj", blendshapes=tmp, template=tpl, expressions="none",
                                 progress=lambda m: print(" ", m, flush=True))
    print(f"ICT actor built in {time.perf_counter() - t0:.0f} s; face to scan "
          f"{res.stats['face_to_scan_mm']['median']:.2f} mm median")

    D, s = carry_offsets(actor.blendshapes, actor.neutral, tpl.neutral, face_vertices(tpl))
    D *= face_falloff(tpl)[None, :, None]
    jaws = actor.meta["blendshape_jaw"]
    out_names, out_D, out_jaw = [], [], []
    for k, n in enumerate(actor.blendshape_names):
        an = arkit_spelling(n)
        if an in out_names:                    # browInnerUp_L + _R: ARKit's one browInnerUp
            i = out_names.index(an)
            out_D[i] = out_D[i] + D[k]
            out_jaw[i] = list(np.add(out_jaw[i], jaws[n]))
            continue
        out_names.append(an)
        out_D.append(D[k])
        out_jaw.append(list(jaws[n]))
    D = np.array(out_D)
    print(f"{len(out_names)} shapes; face scale template/ICT = {s:.3f}; largest offset "
          f"{np.abs(D).max() * 1000:.1f} mm")
    a.out.mkdir(parents=True, exist_ok=True)
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    savez(a.out / "arkit_ict.npz", dict(names=np.array(out_names), deltas_mm=(D * 1000).astype(np.float16),
          jaw=np.array(out_jaw, float), neutral=tpl.neutral.astype(np.float32),
          triangles=tpl.triangles.astype(np.int32), scale=np.float64(s),
          source=np.array(f"ICT-FaceKit Light via scripts/derive_arkit_shapes.py at {commit}")))
    shutil.copyfile(a.ict / "LICENSE", a.out / "LICENSE-ICT-FaceKit.txt")
    print(f"wrote {a.out / 'arkit_ict.npz'} ({(a.out / 'arkit_ict.npz').stat().st_size / 1e6:.1f} MB) "
          f"in {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
