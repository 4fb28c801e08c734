"""CSV tables, written atomically."""
from __future__ import annotations

import csv
import io

from .atomic import write_text


def write_csv(path, header, rows, lineterminator="\r\n"):
    """Write a CSV file: one ``header`` row (names), then ``rows`` (sequences of values), lines
    ended by ``lineterminator`` (the csv module's default); returns the Path."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator=lineterminator)
    w.writerow(list(header))
    w.writerows(rows)
    return write_text(path, buf.getvalue())
