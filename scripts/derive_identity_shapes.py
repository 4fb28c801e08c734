"""Derive the built-in head's face-shape space from ICT-FaceKit's 20 identity shapes (MIT), and
write it to ``invface/template/data/identity_ict.npz`` beside ICT-FaceKit's licence text.

    python scripts/derive_identity_shapes.py [--ict ../shared/data/ict-facekit] [-o invface/template/data]

1. The built-in head (resolution 1, anatomy only) is morphed onto ICT-FaceKit's neutral with
   the 20 identity shapes imported as blendshapes, as ``invface build-model --neutral
   neutral.obj --blendshapes DIR`` does (paper 001's morph): the ICT actor shares the
   template's topology, vertex for vertex.
2. Each shape's offsets are carried back onto the template per vertex, scaled by the ratio of
   the two faces' sizes (``morph.transfer.carry_offsets``), as the ARKit shapes are
   (``scripts/derive_arkit_shapes.py``). Unlike an expression, an identity moves the whole
   head, so the offsets do not fade outside the face.

ICT-FaceKit's identity shapes are its PCA components scaled by their standard deviations: a
face of the space is the neutral plus sum_i c_i S_i with c ~ N(0, 1). The file holds the
template's neutral and triangles at resolution 1 that the offsets belong to, the offsets in
millimetres (float16), and each shape's RMS over the face. The ICT data itself is not copied.
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
sys.path.insert(0, str(ROOT))

from invface.io.arrays import savez                       # noqa: E402
from invface.io.meshes import read_mesh                   # noqa: E402
from invface.morph.build import build_model, face_vertices  # noqa: E402
from invface.morph.transfer import carry_offsets         # noqa: E402
from invface.template import build as build_template      # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--ict", type=Path, default=ROOT.parent / "shared" / "data" / "ict-facekit")
    ap.add_argument("-o", "--out", type=Path, default=ROOT / "invface" / "template" / "data")
    a = ap.parse_args()
    if not (a.ict / "identities.npz").exists():
        raise SystemExit(f"{a.ict}: ICT-FaceKit not found (neutral.obj, identities.npz)")
    t0 = time.perf_counter()
    V, F = read_mesh(a.ict / "neutral.obj")
    S = np.load(a.ict / "identities.npz")["deltas"]
    tpl = build_template(resolution=1.0, expressions=False)
    with tempfile.TemporaryDirectory() as tmp:
        for i, d in enumerate(S):
            trimesh.Trimesh(V + d, F, process=False).export(Path(tmp) / f"identity{i:02d}.obj")
        actor, res = build_model(a.ict / "neutral.obj", blendshapes=tmp, template=tpl, expressions="none",
                                 progress=lambda m: print(" ", m, flush=True))
    print(f"ICT actor built in {time.perf_counter() - t0:.0f} s; face to scan "
          f"{res.stats['face_to_scan_mm']['median']:.2f} mm median")
    order = np.argsort(actor.blendshape_names)
    face = face_vertices(tpl)
    D, s = carry_offsets(actor.blendshapes[order], actor.neutral, tpl.neutral, face)
    rms = np.sqrt((D[:, face] ** 2).sum(-1).mean(-1)) * 1000
    print(f"{len(D)} shapes; face scale template/ICT = {s:.3f}; RMS over the face {rms.round(2)} mm; "
          f"largest offset {np.abs(D).max() * 1000:.1f} mm")
    a.out.mkdir(parents=True, exist_ok=True)
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                            text=True).stdout.strip()
    out = a.out / "identity_ict.npz"
    savez(out, dict(deltas_mm=(D * 1000).astype(np.float16), face_rms_mm=rms, neutral=tpl.neutral.astype(np.float32),
                    triangles=tpl.triangles.astype(np.int32), scale=np.float64(s),
                    source=np.array(f"ICT-FaceKit Light identities via scripts/derive_identity_shapes.py at {commit}")))
    shutil.copyfile(a.ict / "LICENSE", a.out / "LICENSE-ICT-FaceKit.txt")
    print(f"wrote {out} ({out.stat().st_size / 1e6:.1f} MB) in {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    main()
