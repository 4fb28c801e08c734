"""The demo's front page: ``reports/demo/index.html`` links every picture and page the demo made
(the head's previews, the expression sheets of both kinds, the sample plates, the calibration
and the fit's report and exports), each with a line saying what it is."""
from __future__ import annotations

import html
import os
from pathlib import Path

from ..io.atomic import write_text

# (title, what it shows, [pictures shown], [files linked]; paths relative to the demo folder,
# globs allowed) in reading order
SECTIONS = (
    ("The built-in head", "The anatomical template the demo built: skin, skull, jaw, muscles and the "
     "flesh's tetrahedra, from the front and at three quarters (the contact sheet; each view is "
     "linked). The bundle is template_head.npz; summary.json lists its counts.",
     ["preview/contact_sheet.png"], ["template_head.npz", "summary.json", "preview/[!c]*.png"]),
    ("Its expressions", "Every control at 1.0, first by the blendshape rig (paper 000 Eq. 1-2), then "
     "through the blendshape-driven muscle simulation (Eq. 7-11).",
     ["expressions.png", "expressions_simulation.png"], []),
    ("Sample plates", "Plates rendered with known controls, pose, light and albedo; the .truth.json "
     "beside each one holds them.", ["plates/*.png"], []),
    ("Calibration", "Lighting and albedo solved on the neutral plate (Eq. 14): plate | render | 4x "
     "difference.", ["calib_compare.png"], ["calib.npz"]),
    ("The fit", "The simulation-made smile fitted by both model kinds (Eq. 15-16): open its report "
     "first. The exports beside it go to other tools: the Live Link Face CSV and the USD take.",
     ["fit-smile/blendshape/wipe.png", "fit-smile/simulation/wipe.png"],
     ["fit-smile/index.html", "fit-smile/arkit_*.csv", "fit-smile/face_*.usd"]),
)


def write_demo_index(out):
    """Write ``out/index.html`` for a demo folder: each section's files that exist, pictures
    shown, other files linked. Returns its path."""
    out = Path(out)
    parts = []
    for title, what, shown, linked in SECTIONS:
        shown, linked = ([os.path.relpath(p, out) for pattern in patterns for p in sorted(out.glob(pattern))]
                         for patterns in (shown, linked))
        if not shown and not linked:
            continue
        pics = "".join(f'<figure><a href="{html.escape(r)}"><img src="{html.escape(r)}" alt="{html.escape(r)}">'
                       f"</a><figcaption>{html.escape(r)}</figcaption></figure>" for r in shown)
        links = ", ".join(f'<a href="{html.escape(r)}">{html.escape(r)}</a>' for r in linked)
        parts.append(f"<h2>{html.escape(title)}</h2><p>{html.escape(what)}</p>"
                     + (f"<p>Files: {links}</p>" if links else "") + f"<div class=grid>{pics}</div>")
    page = ("<!doctype html><html><head><meta charset=utf-8><title>invface demo</title><style>"
            "body{font-family:sans-serif;margin:2em;max-width:1500px}.grid{display:flex;flex-wrap:wrap;gap:8px}"
            "figure{margin:0}figure img{max-width:480px;border:1px solid #ddd}figcaption{font-size:80%;color:#555}"
            "</style></head><body><h1>invface demo</h1><p>What <code>make demo</code> made, in the order to "
            "read it.</p>" + "".join(parts) + "</body></html>")
    return write_text(out / "index.html", page)
