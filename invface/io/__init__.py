"""Files in and out: every reader and writer of a file in invface lives here.

- ``atomic``: the one atomic writer (temporary file beside the target, fsync, rename; the
  temporary file removed on failure). Nothing outside this package renames files or opens one
  for writing; ``tests/test_architecture.py`` checks it.
- ``exporters``: the table of writers by file suffix (``export(path, data)``).
- ``jsonfile``, ``arrays`` (.npz), ``tables`` (.csv), ``meshes``, ``images``, ``video``: one
  module per kind of file.

This package sits below everything but ``invface.errors``: it imports no other part of invface.
"""
from .atomic import atomic_open, atomic_path, write_bytes, write_text
from .exporters import export, exporter

__all__ = ["atomic_open", "atomic_path", "write_bytes", "write_text", "export", "exporter"]

from .._lazy import submodules as _submodules  # noqa: E402

__getattr__ = _submodules(__name__, __path__)
