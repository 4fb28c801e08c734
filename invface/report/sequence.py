"""HTML report of a plate sequence: ``write_sequence_report(run_folder)``.

``invface fit-plate FOLDER`` fits each frame into ``run/<frame>/<kind>/`` (each frame with its
own page, ``report.fit.write_report``). This page puts the frames side by side: per model
kind, the blendshape weights, jaw rotation and muscle activations over the frames as curves
(the controls an animator would receive), the per-frame figures (curve and image RMS,
vertex error against a known truth, lip volume change, seconds) and each frame's wipe,
linked to its own page.
"""
from __future__ import annotations

import html
from pathlib import Path

import numpy as np

from ..errors import InvfaceError
from ..io.atomic import write_text
from ..io.fitrecords import read_fit_json
from .fit import COMPARE, _figure, identity_section
from .runs import run_notes

ACTIVE = 0.05        # a control is drawn when it exceeds this in some frame


def sequence_frames(run):
    """{frame folder name: {kind: fit folder}} of a sequence run folder, frames in name order
    (empty when ``run`` is not a sequence: no ``<frame>/<kind>/fit.json``)."""
    frames = {}
    for f in sorted(Path(run).glob("*/*/fit.json")):
        frames.setdefault(f.parent.parent.name, {})[f.parent.name] = f.parent
    return frames


def _curves_over_frames(path, frames, series, title, ylabel):
    """Line plot of {name: (n_frames,)} over the frames (names on the axis when they fit);
    only the series above ACTIVE."""
    shown = {k: v for k, v in series.items() if np.nanmax(np.abs(v)) > ACTIVE}

    def draw(ax):
        from matplotlib import colormaps
        ax.set_prop_cycle(color=colormaps["tab20"](np.arange(20)))
        for name, v in shown.items():
            ax.plot(np.arange(len(v)), v, "o-", ms=3, lw=1.2, label=name)
        ax.set_xticks(np.arange(len(frames)))
        ax.set_xticklabels(frames if len(frames) <= 24 else [str(i) if i % 10 == 0 else "" for i in range(len(frames))],
                           rotation=30 if len(frames) <= 24 else 0, fontsize=7, ha="right" if len(frames) <= 24 else "center")
        ax.set_xlabel("frame")
        ax.set_ylabel(ylabel)
        ax.set_title(f"{title} ({len(shown)} of {len(series)} above {ACTIVE})", fontsize=9)
        if shown:
            ax.legend(fontsize=6, ncol=2, loc="upper left", bbox_to_anchor=(1.01, 1.0))
    return _figure(path, draw, (8, 3.2))


def write_sequence_report(run, title=None):
    """Write ``run/index.html`` for a sequence run folder. Returns its path."""
    run = Path(run)
    frames = sequence_frames(run)
    if not frames:
        raise InvfaceError(f"{run}: no <frame>/<kind>/fit.json here; run fit-plate on a folder of frames first")
    names = list(frames)
    kinds = sorted({k for f in frames.values() for k in f})
    summaries = {}
    for frame, fits in frames.items():
        for kind, folder in fits.items():
            summaries[frame, kind] = read_fit_json(folder / "fit.json")
    sections = []
    for kind in kinds:
        have = [f for f in names if (f, kind) in summaries]

        def series(key):
            keys = sorted({k for f in have for k in summaries[f, kind].get(key, {})})
            return {k: np.array([summaries[f, kind].get(key, {}).get(k, np.nan) for f in have]) for k in keys}
        weights = series("weights")
        weights["jaw rotation (rad)"] = np.array([summaries[f, kind].get("jaw", [np.nan])[0] for f in have])
        figs = {"blendshape weights and jaw over the frames":
                _curves_over_frames(run / f"weights_{kind}.png", have, weights, f"{kind} model: controls", "weight")}
        acts = series("activations")
        if acts:
            figs["muscle activations over the frames"] = _curves_over_frames(
                run / f"activations_{kind}.png", have, acts, f"{kind} model: muscle activations", "activation")
        pics = "".join(f'<figure><img src="{html.escape(p)}" alt="{html.escape(c)}"><figcaption>{html.escape(c)}'
                       "</figcaption></figure>" for c, p in figs.items())
        head = "<th>frame</th>" + "".join(f"<th>{html.escape(n)}</th>" for n, _ in COMPARE[1:]) + "<th>flagged</th>"
        rows = "".join(
            f'<tr><td><a href="{html.escape(f)}/index.html">{html.escape(f)}</a></td>'
            + "".join(f"<td>{html.escape(str(fn(summaries[f, kind])))}</td>" for _, fn in COMPARE[1:])
            + f"<td>{html.escape(summaries[f, kind].get('flagged', ''))}</td></tr>"
            for f in have)
        flagged = [f for f in have if summaries[f, kind].get("flagged")]
        if flagged:
            pics += (f"<p class=note>{len(flagged)} of {len(have)} frames flagged as implausible: "
                     + html.escape(", ".join(flagged[:10])) + (" ..." if len(flagged) > 10 else "")
                     + ". The curves file gives them controls interpolated from their neighbours.</p>")
        strip = "".join(
            f'<figure><a href="{html.escape(f)}/index.html"><img class=thumb src="{html.escape(f"{f}/{kind}/wipe.png")}" '
            f'alt="{html.escape(f)}: plate | render | wipe">'
            f"</a><figcaption>{html.escape(f)}</figcaption></figure>"
            for f in have if (run / f / kind / "wipe.png").is_file())
        video = run / f"overlay_{kind}.mp4"
        if video.is_file():          # H.264 (io.video): the page plays it
            pics = (f'<figure><video controls muted loop src="{html.escape(video.name)}" style="max-width:720px">'
                    f'</video><figcaption>{html.escape(video.name)}: plate | render | wipe, frame by frame'
                    "</figcaption></figure>") + pics
        sections.append(f"<h2>{html.escape(kind)} model</h2><div class=grid>{pics}</div>"
                        f"<table><tr>{head}</tr>{rows}</table><div class=grid>{strip}</div>")
    files = ", ".join(f'<a href="{html.escape(p.name)}">{html.escape(p.name)}</a>'
                      for p in [run / "curves.csv", run / "curves.json", *sorted(run.glob("overlay_*.mp4")),
                                *sorted(run.glob("arkit_*.csv")), *sorted(run.glob("face_*.usd")),
                                *sorted(run.glob("rig_*.usd")), *sorted(run.glob("rig_*.glb"))]
                      if p.is_file())
    title = title or f"invface sequence fit: {run.name} ({len(names)} frames)"
    page = (f"<!doctype html><html><head><meta charset=utf-8><title>{html.escape(title)}</title><style>"
            "body{font-family:sans-serif;margin:2em;max-width:1500px}table{border-collapse:collapse;margin:1em 0}"
            "td,th{border:1px solid #ccc;padding:4px 8px;font-size:90%}.grid{display:flex;flex-wrap:wrap;gap:8px}"
            "figure{margin:0}figure img{max-width:720px;border:1px solid #ddd}img.thumb{max-width:200px}"
            "figcaption{font-size:80%;color:#555}.note{background:#fff6d5;padding:6px}</style></head><body>"
            f"<h1>{html.escape(title)}</h1><p>Each frame is warm-started from the previous one's solution; "
            "frame names link to the frame's own report.</p>"
            + (f"<p>Files: {files}</p>" if files else "")
            + "".join(f"<p class=note>{html.escape(n)}</p>" for n in run_notes(run))
            + identity_section(run) + "".join(sections) + "</body></html>")
    return write_text(run / "index.html", page)
