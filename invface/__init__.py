"""invface: anatomically based, differentiable face capture.

Public API (stable names)::

    import invface
    model = invface.FaceModel.load("head.npz")
    model = invface.template.build(resolution=1.0)
    x = model.surface(w, kind="blendshape")

    # the workflow (invface.pipeline), each returning a result with .save(...)
    build = invface.build_model(neutral="actor.obj")       # .model, .save("actor.npz")
    calib = invface.calibrate("neutral.png", model=model)  # Eq. 14
    fit = invface.fit_plate("smile.png", calib, model=model, kinds="both")   # Eq. 15-16
    scan = invface.fit_scan("scan.ply", model=model)       # Eq. 13
"""
from ._env import configure_llvm as _configure_llvm, limit_openblas_threads as _limit_openblas_threads

_configure_llvm()
_limit_openblas_threads()

from .errors import InvfaceError  # noqa: E402
from .model import FaceModel, Muscle, Controls, FitVector, register_surface_model  # noqa: E402

# the blendshape-driven muscle simulation (paper 000 Sec. 6), imported on first use
register_surface_model("simulation", "invface.sim.driven:DrivenSimulation")

from . import template  # noqa: E402

__version__ = "0.1.0"
# the session layer's functions (invface.pipeline), imported on first use: importing invface
# stays light, and the renderer and simulation load only when a fit needs them
_PIPELINE = ("build_model", "fit_scan", "fit_plate", "calibrate", "simulate", "export")
__all__ = ["FaceModel", "Muscle", "Controls", "FitVector", "InvfaceError", "template", "__version__", *_PIPELINE]


# the subpackages, imported on first use as attributes (``invface.pipeline.find_curves``): a bare
# ``import invface`` loads neither Mitsuba nor the simulation
_SUBPACKAGES = ("bridge", "fit", "io", "measure", "mesh", "model", "morph", "pipeline", "render", "report", "sim",
                "template")


def __getattr__(name):
    import importlib
    if name in _PIPELINE:
        return getattr(importlib.import_module(".pipeline", __name__), name)
    if name in _SUBPACKAGES:
        return importlib.import_module(f".{name}", __name__)
    raise AttributeError(f"module 'invface' has no attribute {name!r}")
