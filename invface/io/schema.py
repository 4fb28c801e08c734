"""Checked fields of a sidecar: a JSON object, or an NPZ archive's arrays read into a dict.

The readers of a user's or a run's files (cameras, calibrations, curve files, ground-truth
files, bundle headers, a run's fit.json and run.json) take their fields through ``Fields``, so a bad field is one line that
names the file, the field and what it should be, instead of a KeyError or a TypeError deep in
the code.
"""
from __future__ import annotations

import json

import numpy as np

from ..errors import InvfaceError

_MISSING = object()


class Fields:
    """The fields of ``data`` (a dict) read from ``source`` (the file's name, for messages).
    ``error``: the InvfaceError class raised; ``listing``: what the file's fields are, added to
    a missing field's message."""

    def __init__(self, data, source, error=InvfaceError, listing=""):
        if not isinstance(data, dict):
            raise error(f"{source}: must hold a JSON object ({{...}}), not {type(data).__name__}")
        self.data, self.source, self.error, self.listing = data, str(source), error, listing

    def __contains__(self, name):
        return name in self.data

    def require(self, *names):
        """Raise the missing-field error for the first of ``names`` the file lacks or holds as
        null."""
        for name in names:
            self._present(name, _MISSING)

    def fail(self, name, message):
        """Raise the error: '<source>: field '<name>' <message>'."""
        raise self.error(f"{self.source}: field '{name}' {message}")

    def _present(self, name, default):
        """(True, the field's value), or (False, ``default``) for a field the file lacks or
        holds as JSON null; a required field raises."""
        raw = self.data.get(name)
        if raw is not None:
            return True, raw
        if default is _MISSING:
            more = f" ({self.listing})" if self.listing else ""
            raise self.error(f"{self.source}: missing field '{name}'{more}")
        return False, default

    def _typed(self, name, default, kind, noun):
        """``_present``, with a present field's value required to be a ``kind`` (``noun``
        names it in the message)."""
        found, raw = self._present(name, default)
        if found and not isinstance(raw, kind):
            self.fail(name, f"is {type(raw).__name__}, not {noun}")
        return found, raw

    def array(self, name, shape=None, default=_MISSING, finite=True):
        """Field ``name`` as a float array; ``shape``: a tuple whose None entries match any
        size; ``finite``: refuse NaN and infinity. A missing field is ``default`` (returned
        as given) or an error."""
        found, raw = self._present(name, default)
        if not found:
            return raw
        try:
            a = np.asarray(raw, float)
        except (TypeError, ValueError):
            self.fail(name, "is not numeric")
        if shape is not None and (a.ndim != len(shape) or any(s not in (None, n) for s, n in zip(shape, a.shape))):
            want = "(" + ", ".join("n" if s is None else str(s) for s in shape) + ")"
            self.fail(name, f"has shape {a.shape}, expected {want}")
        if finite and not np.all(np.isfinite(a)):
            self.fail(name, "has non-finite values")
        return a

    def number(self, name, default=_MISSING, low=None, high=None, integer=False):
        """Field ``name`` as a float (an int with ``integer``), within [low, high] where given."""
        found, raw = self._present(name, default)
        if not found:
            return raw
        if isinstance(raw, bool) or not isinstance(raw, (int, float, np.integer, np.floating)) \
                or not np.isfinite(raw):
            self.fail(name, f"is {json.dumps(raw) if _jsonable(raw) else type(raw).__name__}, not a finite number")
        if integer and float(raw) != int(raw):
            self.fail(name, f"is {raw}, not a whole number")
        if (low is not None and raw < low) or (high is not None and raw > high):
            bounds = f"[{'-inf' if low is None else low}, {'inf' if high is None else high}]"
            self.fail(name, f"is {raw}, outside {bounds}")
        return int(raw) if integer else float(raw)

    def text(self, name, default=_MISSING, choices=None):
        """Field ``name`` as a string, one of ``choices`` where given."""
        found, raw = self._typed(name, default, str, "a string")
        if found and choices is not None and raw not in choices:
            self.fail(name, f"is '{raw}', not one of {', '.join(map(str, choices))}")
        return raw

    def mapping(self, name, default=_MISSING):
        """Field ``name`` as its own Fields (a JSON object inside this one)."""
        found, raw = self._typed(name, default, dict, "a JSON object")
        return Fields(raw, f"{self.source}: {name}", self.error) if found else raw

    def listing_of(self, name, default=_MISSING):
        """Field ``name`` as a list."""
        return self._typed(name, default, list, "a list")[1]

    def boolean(self, name, default=_MISSING):
        """Field ``name`` as true or false."""
        return self._typed(name, default, bool, "true or false")[1]

    def strings(self, name, default=_MISSING):
        """Field ``name`` as a list of strings."""
        found, raw = self._typed(name, default, list, "a list of strings")
        if found and not all(isinstance(v, str) for v in raw):
            self.fail(name, "holds an entry that is not a string")
        return raw

    def numbers(self, name, default=_MISSING):
        """Field ``name`` as {key: float}: a JSON object whose values are all finite numbers."""
        found, raw = self._typed(name, default, dict, "a JSON object of numbers")
        if not found:
            return raw
        inner = Fields(raw, f"{self.source}: {name}", self.error)
        for k, v in raw.items():
            if v is None:
                inner.fail(k, "is null, not a finite number")
        return {k: inner.number(k) for k in raw}

    def json(self, name, default=_MISSING):
        """Field ``name`` (a string, or an NPZ's 0-d string array) parsed as a JSON object,
        as its own Fields."""
        found, raw = self._present(name, default)
        if not found:
            return raw
        try:
            value = json.loads(str(raw))
        except ValueError as e:
            self.fail(name, f"is not valid JSON ({e})")
        if not isinstance(value, dict):
            self.fail(name, "is not a JSON object")
        return Fields(value, f"{self.source}: {name}", self.error)


def _jsonable(v):
    try:
        json.dumps(v)
        return True
    except (TypeError, ValueError):
        return False
