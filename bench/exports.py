"""A fit run's exports read back by other code than invface's writers (issue 60).

    python bench/exports.py RUN [--json F]

RUN: a ``fit-plate`` output folder (a photo's or a clip's). Writes the USD take and the USD and
glTF rigs (``invface export RUN --format usd,usdskel,gltf``), then per kind prints:
- the USD take's camera: how far USD's own view and projection matrices put the mesh from
  invface's projection (px, max);
- the UsdSkel rig: how far ``UsdSkel.BakeSkinning`` puts each frame from the fitted surface
  (mm: median, 95th percentile, max); for the simulation kind this is what the flesh adds that
  a blendshape rig cannot carry;
- USD's own validators (``UsdValidation``): their findings on both files;
- the files' sizes.
The glTF rig is checked by the Khronos validator (npm ``gltf-validator``) where ``node`` has it.
"""
import argparse
import json
import shutil
import subprocess
from pathlib import Path

import numpy as np

from _common import add_json_option, write_json

import invface
from invface.render.camera import Camera


def usd_camera_px(stage_path, npz):
    from pxr import Usd, UsdGeom
    stage = Usd.Stage.Open(str(stage_path))
    times = UsdGeom.Mesh(stage.GetPrimAtPath("/Capture/Face")).GetPointsAttr().GetTimeSamples()
    gf = UsdGeom.Camera(stage.GetPrimAtPath("/Capture/Camera")).GetCamera(times[0])
    V, P = np.array(gf.frustum.ComputeViewMatrix()), np.array(gf.frustum.ComputeProjectionMatrix())
    pts = np.array(UsdGeom.Mesh(stage.GetPrimAtPath("/Capture/Face")).GetPointsAttr().Get(times[0]))
    h = np.c_[pts, np.ones(len(pts))] @ V @ P
    cam = Camera.from_dict(json.loads(str(npz["camera"])))
    ndc = h[:, :2] / h[:, 3:4]
    uv = np.c_[(ndc[:, 0] + 1) / 2 * cam.width - 0.5, (1 - ndc[:, 1]) / 2 * cam.height - 0.5]
    return float(np.abs(uv - cam.project(npz["surface"])[0]).max())


def rig_mm(stage_path, surfaces):
    """{time: per-vertex mm from the fitted surface} of the UsdSkel rig, baked by USD."""
    from pxr import Gf, Usd, UsdGeom, UsdSkel
    stage = Usd.Stage.Open(str(stage_path))
    t0, t1 = min(surfaces), max(surfaces)
    UsdSkel.BakeSkinning(UsdSkel.Root(stage.GetPrimAtPath("/Capture/Rig")), Gf.Interval(t0, t1))
    pts = UsdGeom.Mesh(stage.GetPrimAtPath("/Capture/Rig/Face")).GetPointsAttr()
    return np.concatenate([np.linalg.norm(np.array(pts.Get(t)) / 100.0 - x, axis=1) * 1000 for t, x in surfaces.items()])


def findings(path):
    from pxr import Usd, UsdValidation
    validators = UsdValidation.ValidationRegistry().GetOrLoadAllValidators()
    return [e.GetMessage() for e in UsdValidation.ValidationContext(validators).Validate(Usd.Stage.Open(str(path)))]


def khronos(path):
    node = shutil.which("node")
    script = ("const v=require('gltf-validator');const fs=require('fs');v.validateBytes(new Uint8Array("
              "fs.readFileSync(process.argv[1]))).then(r=>console.log(JSON.stringify({errors:r.issues.numErrors,"
              "warnings:r.issues.numWarnings})))")
    if node is None:
        return None
    r = subprocess.run([node, "-e", script, str(path)], capture_output=True, text=True)
    return json.loads(r.stdout) if r.returncode == 0 else None


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run", type=Path)
    add_json_option(ap)
    a = ap.parse_args()
    invface.export(a.run, formats=["usd", "usdskel", "gltf"])
    figures = {}
    for kind in ("blendshape", "simulation"):
        folders = sorted(a.run.glob(f"{kind}/fit.npz")) or sorted(a.run.glob(f"*/{kind}/fit.npz"))
        if not folders:
            continue
        fits = [(json.loads((f.parent / "fit.json").read_text()), np.load(f)) for f in folders]
        surfaces = {float(r.get("frame", i)): d["surface"] for i, (r, d) in enumerate(fits) if not r.get("flagged")}
        e = rig_mm(a.run / f"rig_{kind}.usd", surfaces)
        row = {"usd_camera_px_max": usd_camera_px(a.run / f"face_{kind}.usd", fits[0][1]),
               "rig_mm": {"median": float(np.median(e)), "p95": float(np.percentile(e, 95)), "max": float(e.max())},
               "usd_findings": len(findings(a.run / f"face_{kind}.usd")) + len(findings(a.run / f"rig_{kind}.usd")),
               "gltf_khronos": khronos(a.run / f"rig_{kind}.glb"),
               "bytes": {f.name: f.stat().st_size for f in (a.run / f"face_{kind}.usd", a.run / f"rig_{kind}.usd",
                                                             a.run / f"rig_{kind}.glb")}}
        figures[kind] = row
        print(f"{kind:10s} USD camera {row['usd_camera_px_max']:.1e} px; rig vs fit median {row['rig_mm']['median']:.2e} "
              f"p95 {row['rig_mm']['p95']:.2e} max {row['rig_mm']['max']:.2e} mm; USD findings {row['usd_findings']}; "
              f"glTF Khronos {row['gltf_khronos']}; bytes {row['bytes']}")
    write_json(a.json, {"run": str(a.run), "kinds": figures})


if __name__ == "__main__":
    main()
