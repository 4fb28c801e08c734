"""Subpackages whose modules are reachable as attributes, imported on first use
(``invface.render.renderer`` after a bare ``import invface``): a package's ``__init__`` sets
``__getattr__ = submodules(__name__, __path__)``."""
from __future__ import annotations


def submodules(package, path):
    """A module ``__getattr__`` that imports ``package``'s submodule of the asked name (only the
    names of its real submodules: a missing dependency inside one is not hidden as a missing
    attribute)."""
    import importlib
    import pkgutil
    names = {m.name for m in pkgutil.iter_modules(path)}

    def __getattr__(attr):
        if attr in names:
            return importlib.import_module(f"{package}.{attr}")
        raise AttributeError(f"module {package!r} has no attribute {attr!r}")
    return __getattr__
