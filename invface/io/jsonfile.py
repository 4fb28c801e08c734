"""JSON files: reading inputs (cameras, activations, curves, sidecars) with errors that name the
file, and writing results atomically."""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from ..errors import InvfaceError
from .atomic import write_text


def read_object(path, error=InvfaceError, what="JSON file"):
    """The JSON object (dict) in ``path``; ``error`` (an InvfaceError class) names the file
    when it is missing, unreadable, not JSON or not an object."""
    path = Path(path)
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        raise error(f"{path}: {what} not found") from None
    except (OSError, ValueError) as e:
        raise error(f"{path}: not a readable {what} ({e})") from None
    if not isinstance(data, dict):
        raise error(f"{path}: a {what} must hold a JSON object")
    return data


def json_safe(o):
    """o with numpy scalars and arrays made Python numbers and lists, and non-finite floats
    None (valid JSON)."""
    if isinstance(o, dict):
        return {k: json_safe(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [json_safe(v) for v in o]
    if isinstance(o, np.ndarray):
        return json_safe(o.tolist())
    if isinstance(o, (np.floating, np.integer, np.bool_)):
        o = o.item()
    if isinstance(o, float) and not np.isfinite(o):
        return None
    return o


def write_object(path, data, indent=1):
    """Write ``data`` (JSON-able) as indented JSON to ``path`` atomically; returns the Path."""
    return write_text(path, json.dumps(data, indent=indent))
