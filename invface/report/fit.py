"""HTML reports of plate and scan fits: ``write_report(run_folder)``.

A run folder holds one fit (``fit.json`` + ``fit.npz``, written by
``fit.results.write_fit_files`` for ``fit.plate.write_plate_fit`` and
``fit.scan.write_scan_fit``) or several, one per sub-folder (the model kinds of one plate). The
page ``index.html`` shows, per fit: plate, render, a wipe (left plate, right render), the
per-pixel error heat map, the plate curves (green) and projected model curves (red), the 3D
error heat map on the mesh (vertex error against a known truth, or the scan distance; else the
motion from the neutral), bar charts of blendshape weights and muscle activations, the
convergence plot, timings and all parameters as JSON; and a comparison table of the fits
(vertex error, lip-region volume change, non-zero controls). Everything is a file next to the
page: it works offline.
"""
from __future__ import annotations

import html
import json
import os
import zipfile
from pathlib import Path

import numpy as np

from ..errors import InvfaceError
from ..io.atomic import write_text
from ..io.fitrecords import read_fit_json
from ..io.images import linear_to_srgb, save_figure, write_display_image


def _png(path, rgb):
    """Write a float RGB image in [0, 1] (already display-encoded) as PNG, atomically."""
    return write_display_image(path, rgb).name


def _heat(values, vmax):
    """Colour map (magma) of values / vmax in [0, 1] -> (..., 3)."""
    from matplotlib import colormaps
    return colormaps["magma"](np.clip(values / max(vmax, 1e-12), 0, 1))[..., :3]


def _figure(path, draw, size=(6, 3)):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    fig, ax = plt.subplots(figsize=size, dpi=110)
    draw(ax)
    fig.tight_layout()
    try:
        return save_figure(path, fig).name
    finally:
        plt.close(fig)


def _bars(path, values, title, unit):
    names = list(values)
    v = np.array([values[n] for n in names], float)

    def draw(ax):
        ax.bar(range(len(v)), v, color=np.where(v > 1e-2, "#c0392b", "#95a5a6"))
        ax.set_xticks(range(len(v)))
        ax.set_xticklabels(names, rotation=90, fontsize=6)
        ax.set_ylabel(unit)
        ax.set_title(f"{title} ({int(np.sum(v > 1e-2))} of {len(v)} above 0.01)", fontsize=9)
    return _figure(path, draw, (7, 3.2))


def _convergence(path, history):
    """Cost per log entry, one colour per stage (and per pass of the curve stage: the
    tracking pass and Eq. 15 weigh the controls differently, so their costs differ)."""
    colours = {"curves (pose)": "#7fb3d5", "curves": "#2980b9", "curves (controls)": "#2980b9",
               "shading-coarse": "#e59866", "shading": "#c0392b", "shading-simulation": "#8e44ad",
               "dogleg": "#2c3e50"}

    def draw(ax):
        series = {}
        for i, e in enumerate(history):
            if "cost" in e:
                label = e.get("stage") or "dogleg"
                label += f" ({e['pass']})" if "pass" in e else ""
                series.setdefault(label, []).append((i, max(e["cost"], 1e-12)))
        for label, pts in series.items():
            i, c = np.array(pts).T
            ax.plot(i, c, "o-", ms=2, color=colours.get(label), label=label)
        ax.set_yscale("log")
        ax.set_xlabel("log entry (stages in order)")
        ax.set_ylabel("cost")
        ax.legend(fontsize=7)
        ax.set_title("convergence", fontsize=9)
    return _figure(path, draw)


def _draw_curves(img, data, names, origin=(0, 0), scale=1, prefix=""):
    """Draw the plate's curves (green) and the model's (red) whose names start with ``prefix``
    onto the uint8 image ``img``, in place; curve px are first taken to ``img``'s pixels by
    the crop corner ``origin`` and the enlargement ``scale`` (pixel centres kept)."""
    import cv2
    for i, name in enumerate(names):
        for key, colour in ((f"curve_{i}", (40, 200, 40)), (f"model_curve_{i}", (220, 40, 40))):
            if key in data and name.startswith(prefix):
                q = ((data[key] - origin + 0.5) * scale - 0.5) * 4        # 2 bits of sub-pixel precision
                cv2.polylines(img, [np.round(q).astype(np.int32)], False, colour, 1, cv2.LINE_AA, shift=2)


def _curves_overlay(path, plate_srgb, data):
    img = (np.clip(plate_srgb, 0, 1) * 255).astype(np.uint8).copy()
    _draw_curves(img, data, [str(n) for n in data.get("curve_names", [])])
    return _png(path, img / 255.0)


def _mouth_closeup(path, plate_srgb, render_srgb, data, width=400):
    """The mouth enlarged, plate | render, each with the plate's curves (green) and the
    model's (red): whether the detector or the model is off is seen here, not in the whole
    frame. None when the plate has no outer lip curves."""
    import cv2
    names = [str(n) for n in data.get("curve_names", [])]
    outer = [data[f"curve_{names.index(n)}"] for n in ("lip_outer_upper", "lip_outer_lower") if n in names]
    if len(outer) < 2:
        return None
    pts = np.concatenate(outer)
    lo, hi = pts.min(0), pts.max(0)
    pad = 0.25 * max(float(hi[0] - lo[0]), 1.0)
    h, w = plate_srgb.shape[:2]
    x0, y0 = (int(max(np.floor(v - pad), 0)) for v in lo)
    x1, y1 = int(min(np.ceil(hi[0] + pad), w - 1)) + 1, int(min(np.ceil(hi[1] + pad), h - 1)) + 1
    if x1 - x0 < 2 or y1 - y0 < 2:
        return None
    f = max(1, int(round(width / (x1 - x0))))
    panels = []
    for img in (plate_srgb, render_srgb):
        big = cv2.resize((np.clip(img[y0:y1, x0:x1], 0, 1) * 255).astype(np.uint8), None, fx=f, fy=f,
                         interpolation=cv2.INTER_CUBIC)
        _draw_curves(big, data, names, origin=(x0, y0), scale=f, prefix="lip")
        panels.append(big)
    gap = np.full((panels[0].shape[0], 4, 3), 255, np.uint8)
    return _png(path, np.concatenate([panels[0], gap, panels[1]], 1) / 255.0)


def _mesh_values(data):
    """(per-vertex mm (V,), label) of the 3D heat map: the vertex error against a truth, else
    the motion from the neutral."""
    x = data["surface"]
    if "vertex_error" in data:
        return data["vertex_error"] * 1000, "vertex error"
    return np.linalg.norm(x - x.mean(0) - (data["neutral"] - data["neutral"].mean(0)), axis=1) * 1000, \
        "motion from the neutral"


def _mesh_scale(e):
    """The heat map's top (mm): the values' 99th percentile, at least 0.5 mm."""
    return max(float(np.percentile(e[np.isfinite(e)], 99)), 0.5)


def _shared_mesh_scale(folders):
    """One 3D heat-map scale (mm) for the fits of a page (the kinds side by side), or None."""
    scales = []
    for f in folders:
        try:
            with np.load(Path(f) / "fit.npz", allow_pickle=False) as z:
                scales.append(_mesh_scale(_mesh_values({k: z[k] for k in ("surface", "neutral", "vertex_error")
                                                        if k in z.files})[0]))
        except (OSError, ValueError, KeyError, zipfile.BadZipFile, EOFError):
            continue                      # write_report names the unreadable folder itself
    return max(scales) if scales else None


def _mesh_heat(path, data, summary, vmax=None):
    """The 3D heat map (``_mesh_values``) rendered front on, black 0 to white ``vmax`` mm
    (default: its own ``_mesh_scale``)."""
    from ..render.preview import look_at_camera, render_meshes, to_srgb8
    x, F = data["surface"], data["triangles"]
    e, label = _mesh_values(data)
    vmax = _mesh_scale(e) if vmax is None else vmax
    colours = _heat(np.nan_to_num(e), vmax)
    c = x.mean(0)
    size = float(np.ptp(x, axis=0).max())
    cam = look_at_camera(c + [0, 0, 2.2 * size], c, width=360, height=360, spp=32)
    img = render_meshes([(x, F, colours)], cam, key_dir=(0, 0.3, 1.0))
    name = _png(path, to_srgb8(img) / 255.0)
    finite = e[np.isfinite(e)]
    summary["mesh_heat"] = {"label": label, "scale_mm": vmax, "median_mm": float(np.median(finite)),
                            "max_mm": float(finite.max())}
    return name


def _face_crop(data, shape, margin=0.25):
    """(row slice, column slice) around the fitted face when it fills under half the plate
    (a photo's face is often small), else the whole plate."""
    from ..render.camera import Camera
    h, w = shape
    uv, _ = Camera.from_dict(json.loads(str(data["camera"]))).project(data["surface"])
    lo, hi = uv.min(0), uv.max(0)
    pad = margin * (hi - lo).max()
    lo, hi = np.maximum(lo - pad, 0).astype(int), np.minimum(hi + pad + 1, [w, h]).astype(int)
    if np.prod(hi - lo) > 0.5 * w * h or np.any(hi <= lo):
        return slice(None), slice(None)
    return slice(lo[1], hi[1]), slice(lo[0], hi[0])


def _fit_images(folder, quick=False, heat_scale=None):
    """Pictures of one fit folder; returns (summary dict, {caption: file}). quick: the plate,
    render, wipe, error and curve pictures only (no 3D heat map or charts, 60 % of a curves-only
    frame's time in a sequence); heat_scale: the 3D heat map's top in mm (the page's shared one)."""
    folder = Path(folder)
    summary = read_fit_json(folder / "fit.json", required=("kind", "weights"))
    pics = {}
    with np.load(folder / "fit.npz", allow_pickle=False) as z:
        data = {k: z[k] for k in z.files}
    if "plate" in data:
        rows, cols = _face_crop(data, data["plate"].shape[:2])
        if rows != slice(None):
            for k in [k for k in data if k.startswith(("curve_", "model_curve_")) and k[-1].isdigit()]:
                data[k] = data[k] - [cols.start, rows.start]
        plate, render = linear_to_srgb(data["plate"][rows, cols]), linear_to_srgb(data["render"][rows, cols])
        pics["plate"] = _png(folder / "plate.png", plate)
        pics["render"] = _png(folder / "render.png", render)
        w = plate.shape[1] // 2
        wipe = np.concatenate([plate[:, :w], render[:, w:]], 1)
        wipe[:, w - 1:w + 1] = [1, 1, 0]
        pics["wipe (plate | render)"] = _png(folder / "wipe.png", wipe)
        err = np.abs(data["render"] - data["plate"]).mean(-1)
        where = ""
        if "mask" in data:
            err, where = err * data["mask"], ", inside the face mask"
        err = err[rows, cols]
        scale = max(float(np.percentile(err, 99.5)), 1e-3)
        pics[f"per-pixel error (linear, black 0, white {scale:.3f}{where})"] = _png(folder / "error.png",
                                                                                  _heat(err, scale))
        pics["curves: plate (green), model (red)"] = _curves_overlay(folder / "curves.png", plate, data)
        mouth = _mouth_closeup(folder / "mouth.png", plate, render, data)
        if mouth:
            pics["the mouth, plate | render: plate curves (green), model (red)"] = mouth
    if quick:
        return summary, pics
    pics["3D heat map"] = _mesh_heat(folder / "mesh_error.png", data, summary, heat_scale)
    pics["blendshape weights"] = _bars(folder / "weights.png", summary["weights"], "blendshape weights", "weight")
    if summary.get("activations"):
        pics["muscle activations"] = _bars(folder / "activations.png", summary["activations"],
                                           "muscle activations", "activation")
    if summary.get("history"):
        pics["convergence"] = _convergence(folder / "convergence.png", summary["history"])
    return summary, pics


def _has(summary, key):
    """Whether fit.json holds a value (not null: a number that was not finite) for ``key``."""
    return summary.get(key) is not None


COMPARE = (("model", lambda s: s["kind"]),
           ("vertex error median / max (mm)", lambda s: (f"{s['truth']['median_mm']:.3f} / {s['truth']['max_mm']:.2f}"
                                                       if "truth" in s else "-")),
           ("median error in depth / in the image plane / shape only (mm)",
            lambda s: (f"{s['truth']['depth_median_mm']:.3f} / {s['truth']['in_plane_median_mm']:.3f} / "
                       f"{s['truth']['shape_median_mm']:.3f}" if "depth_median_mm" in s.get("truth", {}) else "-")),
           ("lip volume change", lambda s: f"{100 * s['lip_volume_change']:+.2f} %" if _has(s, "lip_volume_change") else "-"),
           ("non-zero weights", lambda s: s.get("nonzero_weights", "-")),
           ("active muscles", lambda s: s.get("active_muscles", "-") if s.get("activations") else "-"),
           ("curve RMS (px)", lambda s: f"{s['curve_rms_px']:.2f}" if _has(s, "curve_rms_px") else "-"),
           ("image RMS (linear)", lambda s: f"{s['image_rms']:.4f}" if _has(s, "image_rms") else "-"),
           ("image RMS in the mouth / its opening / the eyes",
            lambda s: " / ".join(f"{s['image_rms_by_region'][k]:.4f}" if k in s.get("image_rms_by_region", {}) else "-"
                                 for k in ("mouth", "opening", "eyes"))),
           ("seconds", lambda s: _seconds(s.get("seconds", 0))))


# why a solver stopped (``fit.dogleg``'s statuses, the scan fit's), in words for the page
STOP_WORDS = {"cost": "the cost stopped falling (its relative change fell below the tolerance)",
              "gradient": "the gradient vanished: a minimum",
              "step": "the steps became negligible",
              "radius": "no step lowered the cost any more (the trust region shrank to its floor)",
              "max_iter": "it reached its iteration limit (--iterations, --max-iter)",
              "converged": "converged"}
STAGE_WORDS = {"curves": "the curve stage (Eq. 15)", "shading-coarse": "shape from shading at half resolution",
               "shading": "shape from shading (Eq. 16)", "shading-simulation": "shape from shading (Eq. 16)"}


def status_in_words(status):
    """fit.json's "status" ("curves: cost; shading: radius") as a sentence: each stage and
    why it stopped."""
    parts = []
    for item in str(status or "").split(";"):
        stage, _, why = (s.strip() for s in item.partition(": "))
        name = STAGE_WORDS.get(stage, stage)
        if why in STOP_WORDS:
            parts.append(f"{name} stopped because {STOP_WORDS[why]}")
        elif stage:
            parts.append(f"{name}: {why}" if why else name)
    text = "; ".join(parts)
    return text[:1].upper() + text[1:]


def truth_table(summary, threshold=0.02):
    """HTML: the plate's true controls beside the fitted ones (a synthetic plate's truth file,
    named in fit.json's "truth"), for every control either sets above ``threshold``, and the
    head's pose; "" without a readable truth."""
    path = (summary.get("truth") or {}).get("file")
    try:
        truth = json.loads(Path(path).read_text()) if path else None
    except (OSError, ValueError):
        return ""
    if not isinstance(truth, dict) or not isinstance(truth.get("weights"), dict):
        return ""
    true_w, fit_w = truth["weights"], summary.get("weights", {})
    names = sorted({n for n, v in {**true_w, **fit_w}.items() if abs(float(v)) > threshold},
                   key=lambda n: -abs(float(true_w.get(n, 0))))
    rows = [(n, float(true_w.get(n, 0)), float(fit_w.get(n, 0))) for n in names]
    for key, unit, scale in (("rotation", "rad", 1.0), ("translation", "mm", 1000.0)):
        if key in truth and key in summary:
            for axis, t, f in zip("xyz", truth[key], summary[key]):
                rows.append((f"head {key} {axis} ({unit})", scale * float(t), scale * float(f)))
    body = "".join(f"<tr><td>{html.escape(n)}</td><td>{t:.3f}</td><td>{f:.3f}</td><td>{f - t:+.3f}</td></tr>"
                   for n, t, f in rows)
    return ("<details open><summary>the plate's truth beside the fit (weights in [0, 1] unless a unit is "
            f"given)</summary><table><tr><th>control</th><th>true</th><th>fitted</th><th>fitted - true</th></tr>"
            f"{body}</table></details>")


def _seconds(sec):
    """'total (stage s, ...)' of a {stage: s, "total": s} dict, or one number."""
    if not isinstance(sec, dict):
        return f"{sec:.1f}"
    stages = ", ".join(f"{k} {v:.1f}" for k, v in sec.items() if k != "total")
    return f"{sec['total']:.1f} ({stages})" if "total" in sec else stages


def identity_section(run):
    """The run's identity figure (``report.identity``), when the run adapted the model: a
    heading, the picture and its caption; '' otherwise."""
    from .identity import NAME
    if not (Path(run) / NAME).is_file():
        return ""
    return ("<h2>the actor's identity</h2><figure><img src=\"" + NAME + "\" alt=\"identity\"><figcaption>the adapted "
            "head coloured by how far it moved from the model it came from, and the face-shape space's "
            "coefficients</figcaption></figure>")


def write_report(run, title=None, quick=False):
    """Write ``run/index.html`` for the fit(s) in ``run``. Returns its path. quick: the
    pictures of ``_fit_images(quick=True)`` (a sequence's frame pages; ``invface report``
    on the frame's folder adds the rest)."""
    run = Path(run)
    folders = [run] if (run / "fit.json").is_file() else sorted(p.parent for p in run.glob("*/fit.json"))
    if not folders:
        raise InvfaceError(f"{run}: no fit.json here or in its sub-folders; run fit-plate or fit-scan first")
    sections, rows = [], []
    scale = None if quick else _shared_mesh_scale(folders)       # the kinds' heat maps compare
    for f in folders:
        try:
            summary, pics = _fit_images(f, quick, scale)
        except (OSError, ValueError, KeyError, zipfile.BadZipFile, EOFError) as e:
            raise InvfaceError(f"{f}: unreadable fit result, fit.json or fit.npz truncated or corrupt "
                               f"({type(e).__name__}: {e}); fit again") from None
        rel = os.path.relpath(f, run)
        rows.append(summary)
        figs = "".join(f'<figure><img src="{html.escape(os.path.join(rel, p))}" alt="{html.escape(c)}">'
                       f"<figcaption>{html.escape(c)}</figcaption></figure>" for c, p in pics.items())
        notes = "".join(f"<p class=note>{html.escape(n)}</p>" for n in summary.get("notes", []))
        heat = summary.get("mesh_heat", {})
        space = summary.get("plate_colorspace")
        status = f"{html.escape(status_in_words(summary.get('status', '')))}; " + (
            f"plate read as {html.escape(space)}; " if space else "") + (
            f"3D heat map: {html.escape(heat.get('label', ''))}, scale 0-{heat.get('scale_mm', 0):.2f} mm, "
            f"median {heat.get('median_mm', 0):.3f} mm" if not quick else
            f"the 3D heat map and the charts: <code>invface report {html.escape(str(run))}</code>")
        sections.append(
            f"<h2>{html.escape(summary['kind'])} model</h2>{notes}<p>{status}</p>"
            f"<div class=grid>{figs}</div>{truth_table(summary)}"
            f"<details><summary>all parameters (JSON)</summary><pre>{html.escape(json.dumps({k: v for k, v in summary.items() if k != 'history'}, indent=1))}</pre></details>")
    head = "".join(f"<th>{html.escape(n)}</th>" for n, _ in COMPARE)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(str(fn(s)))}</td>" for _, fn in COMPARE) + "</tr>" for s in rows)
    title = title or f"invface fit report: {run.name}"
    from .runs import run_notes
    missing = run_notes(run) if (run / "run.json").is_file() else run_notes(run.parent, run.name)
    body += "".join(f"<tr><td colspan={len(COMPARE)} class=note>{html.escape(n)}</td></tr>" for n in missing)
    sections.insert(0, identity_section(run))
    page = (f"<!doctype html><html><head><meta charset=utf-8><title>{html.escape(title)}</title><style>"
            "body{font-family:sans-serif;margin:2em;max-width:1500px}table{border-collapse:collapse}"
            "td,th{border:1px solid #ccc;padding:4px 8px;font-size:90%}.grid{display:flex;flex-wrap:wrap;gap:8px}"
            "figure{margin:0}figure img{max-width:480px;border:1px solid #ddd}figcaption{font-size:80%;color:#555}"
            ".note{background:#fff6d5;padding:6px}</style></head><body>"
            f"<h1>{html.escape(title)}</h1><table><tr>{head}</tr>{body}</table>{''.join(sections)}</body></html>")
    return write_text(run / "index.html", page)
