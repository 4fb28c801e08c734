"""The exporter table: which writer makes a file of a given suffix, as trimesh's ``exchange``
has. ``export(path, data)`` picks the writer by the path's suffix; a new format is one entry
(``register``) and one writer module in this package.

| suffix                      | data                         | writer               |
|-----------------------------|------------------------------|----------------------|
| .obj .ply .stl .off         | (vertices (n,3), faces (f,3)) | meshes.write_mesh    |
| .png .jpg .jpeg .exr        | linear image (H, W, 3|4)     | images.write_image   |
| .json                       | a JSON-able object            | jsonfile.write_object|
| .npz                        | {name: array}                 | arrays.savez         |
| .csv                        | (header, rows)                | tables.write_csv     |
| .html .txt .xml .md         | str                           | atomic.write_text    |
| .usd .usda .usdc            | a take: {"frames", "triangles", "camera", "fps"} | usd.write_usd |
| .glb                        | a rig and its take (as ``usd.write_usd_rig``'s) | gltf.write_glb |

Named formats (``export(path, data, format=NAME)``), for files whose suffix says too little:

| format   | data                                                | writer                          |
|----------|-----------------------------------------------------|---------------------------------|
| livelink | {"frames": [...], "arkit_names": [...], "fps": f}   | livelink.write_livelink_csv     |
| usdskel  | a rig and its take (``usd.write_usd_rig``)           | usd.write_usd_rig               |
"""
from __future__ import annotations

from pathlib import Path

from ..errors import ConfigError

_TABLE = {}
_FORMATS = {}


def register(suffixes, writer):
    """Make ``writer(path, data, **options)`` the exporter of each suffix (".ext")."""
    for s in ([suffixes] if isinstance(suffixes, str) else suffixes):
        _TABLE[s.lower()] = writer


def register_format(name, writer):
    """Make ``writer(path, data, **options)`` the exporter of the named format."""
    _FORMATS[name] = writer


def suffixes():
    """The suffixes that ``export`` can write, sorted."""
    return sorted(_TABLE)


def exporter(path):
    """The writer for ``path``'s suffix; ConfigError naming the path and the known suffixes
    when there is none (a check callers make before long work)."""
    path = Path(path)
    writer = _TABLE.get(path.suffix.lower())
    if writer is None:
        raise ConfigError(f"{path}: cannot write '{path.suffix or '(no suffix)'}' files; use one of "
                          + ", ".join(suffixes()))
    return writer


def export(path, data, format=None, **options):
    """Write ``data`` to ``path`` with the exporter of its suffix, or of the named ``format``
    (see the tables above), atomically; returns the Path."""
    if format is not None and format not in _FORMATS:
        raise ConfigError(f"{path}: unknown export format '{format}'; use one of " + ", ".join(sorted(_FORMATS)))
    (_FORMATS[format] if format is not None else exporter(path))(Path(path), data, **options)
    return Path(path)


def _mesh(path, data, **_):
    from .meshes import write_mesh
    write_mesh(path, *data)


def _image(path, data, **options):
    from .images import write_image
    write_image(path, data, **options)


def _json(path, data, **options):
    from .jsonfile import write_object
    write_object(path, data, **options)


def _npz(path, data, **options):
    from .arrays import savez
    savez(path, data, **options)


def _csv(path, data, **_):
    from .tables import write_csv
    write_csv(path, *data)


def _text(path, data, **_):
    from .atomic import write_text
    write_text(path, data)


register((".obj", ".ply", ".stl", ".off"), _mesh)
register((".png", ".jpg", ".jpeg", ".exr"), _image)
register(".json", _json)
register(".npz", _npz)
register(".csv", _csv)
register((".html", ".txt", ".xml", ".md"), _text)


def _usd(path, data, **_):
    from .usd import write_usd
    write_usd(path, data)


register((".usd", ".usda", ".usdc"), _usd)


def _glb(path, data, **_):
    from .gltf import write_glb
    write_glb(path, data)


register(".glb", _glb)


def _livelink(path, data, **_):
    from .livelink import write_livelink_csv
    write_livelink_csv(path, data["frames"], data["arkit_names"], data.get("fps", 24.0))


register_format("livelink", _livelink)


def _usdskel(path, data, **_):
    from .usd import write_usd_rig
    write_usd_rig(path, data)


register_format("usdskel", _usdskel)
