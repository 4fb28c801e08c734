"""Models as functions that return results: the built-in template, an actor built from a
scan (paper 001), a bundle loaded from disk."""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path


def load_model(model=None, resolution=1.0, progress=None):
    """A FaceModel from a FaceModel (returned as is), a bundle path, or None (the built-in
    template at ``resolution``, cached)."""
    from .. import template
    from ..model import FaceModel
    if isinstance(model, FaceModel):
        return model
    if model is not None:
        return FaceModel.load(model)
    return template.build(resolution=resolution, progress=_messages(progress))


def _messages(progress):
    """A str callback (the builders' progress) that sends {"message": text} events."""
    return None if progress is None else (lambda msg: progress({"message": msg}))


@dataclass
class ModelBuild:
    """A built model: ``model`` (FaceModel), ``stats`` of the morph (unit, scale, symmetry,
    alignment, skin-to-scan distances; empty for the template), ``seconds`` per stage,
    the morph's result (for its preview sheet) and the template it was morphed from.
    ``save(path, preview=None)`` writes the bundle (and preview images); seconds["total"] is
    the whole build's."""

    model: object
    stats: dict = field(default_factory=dict)
    seconds: dict = field(default_factory=dict)
    morph: object = None
    template: object = None

    def save(self, path, preview=None):
        """Write the bundle atomically; with ``preview`` (a folder) also the preview sheets
        (and the morph sheet for a morphed model). Returns the paths written."""
        from ..report.preview import write_previews
        written = []
        if path is not None:
            self.model.save(path)
            written.append(Path(path))
        if preview is not None:
            if self.morph is not None:
                from ..report.morph import write_morph_preview
                written.append(write_morph_preview(self.model, self.morph, preview, template=self.template))
            written += write_previews(self.model, preview)
        return written

    def describe(self):
        """Lines for a terminal: the morph's figures (morphed models) and the model summary."""
        lines = []
        st = self.stats
        if st:
            lines.append(f"scan {st.get('unit_summary', 'unit ' + st['unit'])} (x{st['scale']:g} to metres); "
                         f"symmetry error {st['symmetry_error_mm']:.2f} mm; alignment residual "
                         f"{st['alignment_residual_mm']:.2f} mm")
            f = st.get("face_to_scan_mm")          # older bundles lack it
            if f:
                lines.append(f"face skin to scan: median {f['median']:.2f} mm, 95th percentile {f['p95']:.2f} mm, "
                             f"max {f['max']:.2f} mm; {100 * st['snapped_fraction']:.1f}% of the template skin "
                             "snapped onto the scan")
            lines += [f"cleaning: {n}" for n in st.get("cleaning", [])]
            lines += [f"warning: landmark {f['landmark']}: {f['rule']}; it fell back to {f['fallback']}"
                      for f in st.get("landmark_fallbacks", [])]
        s = self.model.summary()
        lines += [f"surface: {s['surface_vertices']} vertices, {s['surface_triangles']} triangles; "
                  f"blendshapes: {s['blendshapes']}; skin embedding: {s['skin_embedding']}",
                  f"flesh:   {s['vertices']} vertices, {s['tets']} tets, volume {s['volume_m3'] * 1e6:.0f} cm^3; "
                  f"fixed: {s['fixed_cranium']} cranium, {s['fixed_jaw']} jaw",
                  f"quality: min dihedral {s['min_dihedral_deg']:.2f} deg, max dihedral {s['max_dihedral_deg']:.1f} deg, "
                  f"radius ratio min {s['min_radius_ratio']:.3f} / mean {s['mean_radius_ratio']:.3f}, "
                  f"inverted {s['inverted']}",
                  f"muscles: {s['muscles']} ({s['muscle_tets']} muscle tets); landmarks: {s['landmarks']}; "
                  f"curves: {s['curves']}",
                  f"time:    {self.seconds.get('total', 0.0):.1f} s"]
        return lines


def build_model(neutral=None, blendshapes=None, unit=None, expressions="copy", resolution=1.0, force=False,
                progress=None):
    """An anatomical FaceModel: with ``neutral`` (an OBJ/PLY scan of the actor's neutral
    face) the template morphed onto it (paper 001; ``blendshapes``: a folder of the actor's
    shapes, ``unit``: "m", "cm" or "mm", default found from the scan; ``expressions``:
    "copy" (the template's ARKit shapes), "simulate" (its FACS-style action units) or "none",
    without blendshapes); without it the built-in template at
    ``resolution`` (``force``: regenerate, not from the cache). progress: {"message": text}
    events. Returns a ModelBuild."""
    from .. import template
    t0 = time.perf_counter()
    say = _messages(progress)
    if neutral is None:
        model = template.build(resolution=resolution, force=force, progress=say)
        return ModelBuild(model, seconds={"total": time.perf_counter() - t0})
    from ..morph.build import build_model as morph
    tpl = template.build(resolution=resolution, progress=say)
    model, result = morph(neutral, blendshapes=blendshapes, template=tpl, unit=unit, expressions=expressions,
                          progress=say)
    return ModelBuild(model, stats=result.stats, seconds={**result.seconds, "total": time.perf_counter() - t0},
                      morph=result, template=tpl)
