"""Scan fitting as a function that returns a result (paper 000, Eq. 13)."""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..fit.lambdas import EQ13_LAMBDA


@dataclass
class ScanResult:
    """A scan fit (``fit.scan.ScanFit``) with what it was run on: named weights, jaw, pose,
    muscle activations (simulation fits), per-vertex error and seconds. ``save(folder)``
    writes what ``invface fit-scan`` writes: fit.json, fit.npz, fitted.ply and index.html."""

    fit: object
    model: object
    scan: str
    mode: str
    lam: float
    unit: str = "m"
    unit_source: str = "given"

    weights = property(lambda self: self.fit.weights, doc="{blendshape name: weight}")
    jaw = property(lambda self: self.fit.jaw, doc="(6,) jaw parameters")
    rotation = property(lambda self: self.fit.rotation, doc="(3,) rad, Euler XYZ")
    translation = property(lambda self: self.fit.translation, doc="(3,) m")
    activations = property(lambda self: self.fit.activations, doc="{muscle: activation} (simulation fits)")
    surface = property(lambda self: self.fit.surface, doc="posed fitted surface (V, 3) m")
    seconds = property(lambda self: self.fit.seconds, doc="seconds of the fit")

    @property
    def error_mm(self):
        """{median, mean, max} of the per-vertex distance to the scan, mm."""
        return self.fit.summary()["error_mm"]

    def _run(self):
        """What fit.json records beside the fit's own summary."""
        return dict(scan=self.scan, mode=self.mode, lam=self.lam, seconds=self.seconds, scan_unit=self.unit,
                    scan_unit_source=self.unit_source)

    def summary(self):
        """The fit.json dictionary."""
        return dict(self.fit.summary(), history=self.fit.history, **self._run())

    def save(self, folder):
        """Write fit.json, fit.npz, fitted.ply (each atomically) and the report; returns the page."""
        from ..fit.scan import write_scan_fit
        from ..io.meshes import write_mesh
        from ..report.fit import write_report
        folder = Path(folder)
        write_scan_fit(folder, self.model, self.fit, **self._run())
        write_mesh(folder / "fitted.ply", self.fit.surface, self.model.triangles)
        return write_report(folder, title=f"invface scan fit: {Path(self.scan).name}")

    def describe(self):
        """Lines for a terminal."""
        s, e = self.summary(), self.error_mm
        lines = [f"scan unit: {self.unit} ({self.unit_source})",
                 f"{self.fit.kind} fit: {s['iterations']} iterations ({self.fit.status}), {self.seconds:.1f} s; "
                 f"error median {e['median']:.3f} mm, max {e['max']:.3f} mm; {s['nonzero_weights']} non-zero weights",
                 "largest weights: " + ", ".join(f"{k} {v:.3f}" for k, v in
                                                 sorted(self.weights.items(), key=lambda kv: -kv[1])[:5])]
        if self.activations:
            top = sorted(self.activations.items(), key=lambda kv: -kv[1])[:5]
            lines.append("strongest muscles: " + ", ".join(f"{k} {v:.3f}" for k, v in top))
        return lines


def fit_scan(scan, model=None, kind="blendshape", mode="correspondence", lam=EQ13_LAMBDA, max_iter=50,
             unit=None, progress=None, **options):
    """Fit controls and rigid pose of a model to a 3D scan (Eq. 13). scan: an OBJ/PLY path
    or (vertices (S, 3), triangles (G, 3)), in the model's frame; unit: the scan's unit
    ("m", "cm" or "mm"; default: found from its size, as ``build-model`` does, and reported
    on the result); model: a FaceModel, a bundle path or None (the built-in template); kind:
    "blendshape" or "simulation"; mode: "correspondence" (the model's topology) or "nearest"
    (any mesh); progress: each dogleg iteration's log entry. Other options go to
    ``fit.scan.fit_scan``. Returns a ScanResult."""
    from ..errors import ConfigError, MeshError
    from ..fit.scan import fit_scan as fit
    from ..io.meshes import read_mesh
    from ..morph.target import UNITS, detect_unit
    from .models import load_model
    model = load_model(model)
    if isinstance(scan, (str, Path)):
        name, (V, F) = str(scan), read_mesh(scan)
    else:
        name, (V, F) = "scan", (np.asarray(scan[0], float), None if scan[1] is None else np.asarray(scan[1]))
    bad = ~np.all(np.isfinite(V), axis=1)
    if bad.any():           # before the unit: a NaN's bounding box is no size
        raise MeshError(f"{name}: {int(bad.sum())} of its {len(V)} vertices are not finite (NaN or inf), e.g. "
                        f"vertex {int(np.flatnonzero(bad)[0])}: repair or remove them and export the scan again")
    if unit is None:
        unit, source = detect_unit(V, name)[0], "found from its size"
    elif unit not in UNITS:
        raise ConfigError(f"unknown scan unit {unit!r}: use one of {', '.join(UNITS)}")
    else:
        source = "given"
    result = fit(model, V * UNITS[unit], F, kind=kind, mode=mode, lam=lam, max_iter=max_iter, progress=progress,
                 **options)
    return ScanResult(result, model, name, mode, lam, unit, source)
