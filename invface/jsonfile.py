"""Small JSON files: reading inputs (cameras, activations, curves) with clear errors, and
writing results atomically."""
from __future__ import annotations

import json
import os
from pathlib import Path

from .errors import InvfaceError


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


def write_object(path, data):
    """Write ``data`` as indented JSON to ``path`` through a temporary file and a rename."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=1))
    os.replace(tmp, path)
