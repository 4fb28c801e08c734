"""The one atomic writer: every file invface writes appears whole or not at all.

A writer gets a temporary path in the target's folder (same suffix, so writers that pick a
format by suffix still work), writes there, and the file is flushed to disk and renamed over
the target. On any failure, the rename's included, the temporary file is removed and the
target is left as it was.

    with atomic_path("out/fit.npz") as tmp:
        np.savez_compressed(tmp, **arrays)
"""
from __future__ import annotations

import contextlib
import os
import tempfile
from pathlib import Path


def _umask():
    """The process's umask (read by setting it and setting it back)."""
    mask = os.umask(0)
    os.umask(mask)
    return mask


_MODE = 0o666 & ~_umask()        # what open() would give a new file: mkstemp's own is 0600


def _fsync(path):
    """Flush a written file to disk (best effort: some file systems refuse fsync)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temporary Path beside ``path`` (hidden name, same suffix); when the block ends
    without an exception, fsync it and rename it over ``path``. The parent folder is created.
    On failure the temporary file is removed and the exception propagates."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}", dir=path.parent)
    os.close(fd)
    tmp = Path(tmp)
    try:
        yield tmp
        _fsync(tmp)
        os.chmod(tmp, _MODE)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


@contextlib.contextmanager
def atomic_open(path, mode="w", **kwargs):
    """``open`` a temporary file beside ``path`` for writing (``mode`` 'w' or 'wb'), renamed
    over ``path`` when the block ends without an exception (``atomic_path``)."""
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open writes whole files: mode 'w' or 'wb', not {mode!r}")
    with atomic_path(path) as tmp, open(tmp, mode, **kwargs) as fh:
        yield fh


def write_bytes(path, data):
    """Write ``data`` (bytes) to ``path`` atomically; returns the Path."""
    with atomic_open(path, "wb") as fh:
        fh.write(data)
    return Path(path)


def write_text(path, text):
    """Write ``text`` (UTF-8) to ``path`` atomically; returns the Path."""
    with atomic_open(path, "w", encoding="utf-8") as fh:
        fh.write(text)
    return Path(path)
