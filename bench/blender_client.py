"""A real client reads the take (issue 60): Blender, as the Python module ``bpy`` in a virtual
environment of its own (bpy pins NumPy 1.x), imports a run's ``face_<kind>.usd``, checks the
face's vertex count and one frame's positions against the fit's surface, and renders that frame
through the solved camera with Cycles on the CPU, over the plate card.

    python bench/blender_client.py RUN [--kind blendshape] [--venv DIR] [--png OUT.png]
                                       [--json bench/figures/blender_client.json]

RUN is a fit-plate output folder of one photo. The environment (default
``~/.cache/invface/bpy-venv``) is made and ``bpy==4.5.15`` (Blender 4.5 LTS, Python 3.11
wheels) installed into it on first use.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import venv
from pathlib import Path

import numpy as np

from _common import write_json

BPY = "bpy==4.5.15"
HERE = Path(__file__).resolve().parent


def blender_python(folder):
    """The Python of a virtual environment with bpy, made and filled on first use."""
    py = folder / "bin" / "python"
    if not py.is_file():
        print(f"making {folder} with {BPY} (once; about 400 MB)", flush=True)
        venv.create(folder, with_pip=True)
    if subprocess.call([str(py), "-c", "import bpy"], stderr=subprocess.DEVNULL) != 0:
        subprocess.check_call([str(py), "-m", "pip", "install", "-q", BPY])
    return py


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("run", type=Path)
    ap.add_argument("--kind", default="blendshape")
    ap.add_argument("--venv", type=Path, default=Path.home() / ".cache" / "invface" / "bpy-venv")
    ap.add_argument("--png", type=Path)
    ap.add_argument("--json", type=Path)
    a = ap.parse_args()
    usd, npz = a.run / f"face_{a.kind}.usd", a.run / a.kind / "fit.npz"
    if not usd.is_file() or not npz.is_file():
        sys.exit(f"{a.run}: no face_{a.kind}.usd and {a.kind}/fit.npz here: give a fit-plate folder of one photo")
    with np.load(npz) as d:
        cam = json.loads(str(d["camera"]))
        points = d["surface"]
    fit = json.loads((a.run / a.kind / "fit.json").read_text())
    png = a.png or a.run / f"blender_{a.kind}.png"
    with tempfile.TemporaryDirectory() as tmp:
        expected, report = Path(tmp) / "expected.npz", Path(tmp) / "report.json"
        np.savez(expected, points=points, frame=int(fit.get("frame", 0)), width=cam["width"], height=cam["height"])
        py = blender_python(a.venv)
        env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
        r = subprocess.run([str(py), str(HERE / "_blender_inner.py"), str(usd), str(expected), str(png.resolve()),
                            str(report)], capture_output=True, text=True, env=env)
        if r.returncode != 0:
            sys.exit(f"Blender failed: {r.stderr[-2000:]}")
        out = json.loads(report.read_text())
    out.update(usd=str(usd), png=str(png))
    print(f"Blender {out['blender']}: {out['vertices']} vertices (the fit: {out['expected_vertices']}); frame "
          f"{fit.get('frame', 0)} within {out['max_m'] * 1e3:.2e} mm of the fit's surface (median "
          f"{out['median_m'] * 1e3:.2e} mm); camera {out['camera']['lens_mm']:.2f} mm on a "
          f"{out['camera']['sensor_mm']:.0f} mm back; rendered {png}")
    write_json(a.json, out)


if __name__ == "__main__":
    main()
