"""Rows of bench/RESULTS.md's table from the JSON figures benches write (``--json PATH``).

    python bench/summary.py fit_forward.json real_photos.json ...

Each file holds {command, commit, date, figures} (``_common.write_json``); each row gives the
bench, its figures flattened to "name value" pairs (numbers rounded to 3 significant digits),
the command, and the commit and date, as the table's columns.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path


def flatten(figures, prefix=""):
    """[(dotted name, value)] of the leaves of nested dicts and lists."""
    out = []
    if isinstance(figures, dict):
        for k, v in figures.items():
            out += flatten(v, f"{prefix}{k}.")
    elif isinstance(figures, list):
        for i, v in enumerate(figures):
            name = v.get("plate") or v.get("name") or v.get("photo") if isinstance(v, dict) else None
            tag = f"{name}/{v.get('kind')}" if name and isinstance(v, dict) and v.get("kind") else name or str(i)
            out += flatten({k: x for k, x in v.items() if k not in ("plate", "name", "photo", "kind")}
                           if isinstance(v, dict) else v, f"{prefix}{tag}.")
    else:
        out.append((prefix.rstrip("."), figures))
    return out


def row(path):
    """One markdown table row for a figures file."""
    rec = json.loads(Path(path).read_text())
    pairs = "; ".join(f"{k} {v:.3g}" if isinstance(v, (int, float)) and not isinstance(v, bool) else f"{k} {v}"
                      for k, v in flatten(rec.get("figures", {})))
    bench = rec.get("command", "?").split()[1] if len(rec.get("command", "").split()) > 1 else "?"
    return f"| {bench} | {pairs} | `{rec.get('command', '?')}` | {rec.get('commit', '?')}, {rec.get('date', '?')} |"


def main(argv):
    if not argv:
        print(__doc__)
        return 2
    print("| bench | figures | command | commit, date |")
    print("|---|---|---|---|")
    for p in argv:
        print(row(p))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
