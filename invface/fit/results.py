"""Writing a fit's results for the report: ``fit.json`` (summary) and ``fit.npz`` (arrays)."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..jsonfile import write_object


class NamedControls:
    """The named views of a fit's result with ``vector`` (FitVector), controls ``p``,
    ``rotation`` and ``translation``: the fit vector z, weights by name, the jaw."""

    @property
    def z(self):
        """The fit vector (``FitVector``): controls and pose."""
        return self.vector.pack(self.p, self.rotation, self.translation)

    @property
    def weights(self):
        """{blendshape name: weight}."""
        return self.vector.weights_dict(self.p)

    @property
    def jaw(self):
        """(6,) jaw parameters."""
        return self.p[self.vector.jaw].copy()


def json_safe(o):
    """o with numpy scalars made Python numbers and non-finite floats None (valid JSON)."""
    if isinstance(o, dict):
        return {k: json_safe(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [json_safe(v) for v in o]
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    if isinstance(o, float) and not np.isfinite(o):
        return None
    return o


def write_fit_files(folder, summary, arrays):
    """Write ``folder/fit.npz`` (arrays) and ``folder/fit.json`` (summary), each through a
    temporary file and a rename; the report (``invface.report.fit``) reads them."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    tmp = folder / "fit.npz.tmp.npz"
    np.savez_compressed(tmp, **arrays)
    os.replace(tmp, folder / "fit.npz")
    write_object(folder / "fit.json", json_safe(summary))
    return folder / "fit.json"
