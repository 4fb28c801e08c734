"""Reading small JSON input files (cameras, activations, curves) with clear errors."""
from __future__ import annotations

import json
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
