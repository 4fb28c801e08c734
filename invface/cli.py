"""The ``invface`` command line. InvfaceErrors print as one line and exit with status 2."""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from .errors import InvfaceError


def _progress(msg):
    print(f"  .. {msg}", flush=True)


def _print_summary(model, seconds):
    s = model.summary()
    print(f"surface: {s['surface_vertices']} vertices, {s['surface_triangles']} triangles; "
          f"blendshapes: {s['blendshapes']}")
    print(f"flesh:   {s['vertices']} vertices, {s['tets']} tets, volume {s['volume_m3'] * 1e6:.0f} cm^3; "
          f"fixed: {s['fixed_cranium']} cranium, {s['fixed_jaw']} jaw")
    print(f"quality: min dihedral {s['min_dihedral_deg']:.2f} deg, max dihedral {s['max_dihedral_deg']:.1f} deg, "
          f"radius ratio min {s['min_radius_ratio']:.3f} / mean {s['mean_radius_ratio']:.3f}, inverted {s['inverted']}")
    print(f"muscles: {s['muscles']} ({s['muscle_tets']} muscle tets); landmarks: {s['landmarks']}; curves: {s['curves']}")
    print(f"time:    {seconds:.1f} s")


def cmd_build_model(args):
    from . import template
    from .model import FaceModel
    t0 = time.perf_counter()
    if args.neutral:
        raise InvfaceError("building a model from a scan (--neutral) needs the morph pipeline (paper 001), "
                           "which this version does not include yet; use --template")
    if args.template or not args.input:
        print(f"building the template head (resolution {args.resolution:g})", flush=True)
        model = template.build(resolution=args.resolution, force=args.force, progress=_progress)
    else:
        model = FaceModel.load(args.input)
    if args.output:
        model.save(args.output)
        print(f"wrote {args.output}")
    _print_summary(model, time.perf_counter() - t0)
    if args.preview:
        from .report.preview import write_previews
        paths = write_previews(model, args.preview)
        print(f"previews: {len(paths)} images in {args.preview} (contact sheet: {paths[-1]})")
    return 0


def cmd_demo(args):
    """Until fitting lands: build the template, pose the jaw, write previews."""
    from . import template
    from .report.preview import write_previews
    out = Path(args.out)
    t0 = time.perf_counter()
    print("invface demo: building the built-in anatomical head", flush=True)
    model = template.build(progress=_progress)
    _print_summary(model, time.perf_counter() - t0)
    model.save(out / "template_head.npz")
    paths = write_previews(model, out / "preview")
    (out / "summary.json").write_text(json.dumps(model.summary(), indent=2))
    print(f"wrote {out / 'template_head.npz'}, {len(paths)} preview images; open {paths[-1]}")
    return 0


def build_parser():
    p = argparse.ArgumentParser(prog="invface", description="Anatomically based, differentiable face capture.")
    sub = p.add_subparsers(dest="command", required=True)
    b = sub.add_parser("build-model", help="build (or inspect) a FaceModel bundle")
    b.add_argument("input", nargs="?", help="an existing bundle to summarise/preview")
    b.add_argument("--template", action="store_true", help="the built-in template head (default)")
    b.add_argument("--neutral", help="the actor's neutral scan (OBJ/PLY) to morph the template onto")
    b.add_argument("--resolution", type=float, default=1.0, help="template size factor (1 = ~35k tets)")
    b.add_argument("--force", action="store_true", help="regenerate instead of using the cache")
    b.add_argument("-o", "--output", help="write the bundle here (.npz)")
    b.add_argument("--preview", metavar="DIR", help="write preview images into DIR")
    b.set_defaults(func=cmd_build_model)
    d = sub.add_parser("demo", help="run the main job on the built-in model")
    d.add_argument("--out", default="reports/demo", help="output folder")
    d.set_defaults(func=cmd_demo)
    return p


def main(argv=None):
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except InvfaceError as e:
        print(f"invface: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
