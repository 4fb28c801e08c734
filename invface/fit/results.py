"""Writing a fit's results for the report: ``fit.json`` (summary) and ``fit.npz`` (arrays)."""
from __future__ import annotations

from pathlib import Path


from ..io.arrays import savez
from ..io.jsonfile import json_safe, write_object


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


def write_fit_files(folder, summary, arrays):
    """Write ``folder/fit.npz`` (arrays) and ``folder/fit.json`` (summary), each through a
    temporary file and a rename; the report (``invface.report.fit``) reads them."""
    folder = Path(folder)
    savez(folder / "fit.npz", arrays)
    write_object(folder / "fit.json", json_safe(summary))
    return folder / "fit.json"
