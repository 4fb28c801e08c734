"""CSV tables, written atomically."""
from __future__ import annotations

import csv
import io

from .atomic import write_text


def write_csv(path, header, rows):
    """Write a CSV file: one ``header`` row (names), then ``rows`` (sequences of values);
    returns the Path."""
    buf = io.StringIO()
    w = csv.writer(buf)
    w.writerow(list(header))
    w.writerows(rows)
    return write_text(path, buf.getvalue())
