"""Numbered image sequences, as VFX delivers plates: ``shot.%04d.exr``, ``shot.####.dpx``,
``shot.@@@@.tif``, or a folder of numbered files.

In a pattern, a run of ``#`` or ``@`` stands for that many digits (Nuke's convention: ``####``
is four), ``%04d`` for four digits padded with zeros and ``%d`` for any number of digits. A
frame number wider than the padding matches too (frame 10000 of a ``####`` sequence).

    frames = find_sequence("plates/shot.####.dpx")      # [(1001, Path), (1002, Path), ...]
"""
from __future__ import annotations

import re
from pathlib import Path

from ..errors import ImageError

_HOLE = re.compile(r"%0?(\d*)d|#+|@+")
_NUMBERED = re.compile(r"^(.*?)(\d+)$")


def is_pattern(path):
    """Whether ``path``'s file name holds a frame-number placeholder."""
    return _HOLE.search(Path(path).name) is not None


def _hole(name):
    """(prefix, digits, suffix) of a pattern's file name; digits 0: any width."""
    holes = list(_HOLE.finditer(name))
    if len(holes) != 1:
        raise ImageError(f"{name}: a sequence pattern holds one frame number (####, @@@@ or %04d)")
    m = holes[0]
    text = m.group(0)
    digits = len(text) if text[0] in "#@" else int(m.group(1) or 0)
    return name[:m.start()], digits, name[m.end():]


def find_sequence(pattern):
    """The files of a numbered sequence, [(frame number, Path)] in frame order. Raises
    ImageError naming the pattern when its folder is missing or no file matches."""
    pattern = Path(pattern)
    prefix, digits, suffix = _hole(pattern.name)
    folder = pattern.parent
    if not folder.is_dir():
        raise ImageError(f"{pattern}: the folder {folder} does not exist")
    width = f"{{{digits},}}" if digits else "+"
    rx = re.compile(re.escape(prefix) + rf"(\d{width})" + re.escape(suffix) + "$")
    found = {}
    for f in folder.iterdir():
        m = rx.match(f.name)
        if m and (not digits or len(m.group(1)) == digits or not m.group(1).startswith("0")):
            found.setdefault(int(m.group(1)), f)
    if not found:
        raise ImageError(f"{pattern}: no file in {folder} matches this sequence pattern "
                         f"({prefix}{'#' * max(digits, 1)}{suffix})")
    return sorted(found.items())


def sequence_stem(pattern):
    """The name of a sequence without its frame number and the separator before it:
    ``shot`` for ``shot.####.dpx`` (its camera file is ``shot.json``)."""
    prefix, _, _ = _hole(Path(pattern).name)
    return prefix.rstrip("._- ") or "sequence"


def frame_numbers(paths):
    """The frame numbers of a folder's files (sorted by name) when every stem ends in digits
    after one common prefix and the numbers are distinct; None otherwise."""
    parts = [_NUMBERED.match(Path(p).stem) for p in paths]
    if not parts or not all(parts) or len({m.group(1) for m in parts}) != 1:
        return None
    numbers = [int(m.group(2)) for m in parts]
    return numbers if len(set(numbers)) == len(numbers) else None
