"""NumPy archives (.npz): written compressed and atomically, read without pickle."""
from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from ..errors import InvfaceError
from .atomic import atomic_open


def savez(path, arrays, compressed=True):
    """Write the arrays {name: array} to ``path`` (.npz) atomically; returns the Path."""
    write = np.savez_compressed if compressed else np.savez
    with atomic_open(path, "wb") as fh:
        write(fh, **arrays)
    return Path(path)


def load_npz(path, error=InvfaceError, what="NumPy archive"):
    """The arrays of an .npz file as a dict {name: array} (read whole, no pickle); ``error``
    (an InvfaceError class) names the file when it is missing, truncated or not an archive."""
    path = Path(path)
    if not path.is_file():
        raise error(f"{path}: {what} not found")
    try:
        with np.load(path, allow_pickle=False) as data:
            return {k: data[k] for k in data.files}
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as e:
        raise error(f"{path}: not a readable {what} ({type(e).__name__}: {e}); the file is truncated "
                    "or corrupted: write it again") from None
