"""What every bench shares: timing, peak memory, the shared data, and its figures as JSON.

    from _common import add_json_option, peak_rss_mib, shared, steps_per_frame, timed, write_json

Benches run as scripts (``python bench/NAME.py``), so this module is imported by its own name.
"""
from __future__ import annotations

import json
import resource
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
SHARED = REPO.parent / "shared" / "data"          # the project's shared data, beside the clone


def shared(*parts, what="this benchmark's data"):
    """The path ``../shared/data/<parts>``; when it is absent, print why the bench skips and exit
    with 0 (the data is not part of invface and may not be on every machine)."""
    path = SHARED.joinpath(*parts)
    if not path.exists():
        print(f"skipped: {what} not found at {path} (the shared data beside the clone)")
        sys.exit(0)
    return path


def timed(fn, repeat=1):
    """(fn()'s last result, mean seconds per call over ``repeat`` calls)."""
    t = time.perf_counter()
    for _ in range(repeat):
        out = fn()
    return out, (time.perf_counter() - t) / repeat


def peak_rss_mib():
    """This process's peak resident memory so far (MiB; Linux reports ru_maxrss in KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def steps_per_frame(records):
    """{stage: mean accepted steps a frame} over fit records (fit.json's, with their
    ``history``; runs made before the ``work`` record have it too), stages in first-seen order."""
    import numpy as np

    from invface.fit.plate import accepted_steps
    per_frame = [accepted_steps(r.get("history", [])) for r in records]
    stages = dict.fromkeys(s for f in per_frame for s in f)
    return {s: float(np.mean([f.get(s, 0) for f in per_frame])) for s in stages}


def add_json_option(parser):
    """Add ``--json PATH`` to a bench's argparse parser."""
    parser.add_argument("--json", type=Path, help="also write the figures printed to this JSON file")


def _commit():
    try:
        return subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=REPO, capture_output=True, text=True,
                              check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def write_json(path, figures):
    """Write the bench's figures (a JSON-able dict) to ``path`` with the command, commit and date
    that made them (``bench/summary.py`` reads them); nothing when path is None."""
    if path is None:
        return
    record = {"command": "python " + " ".join([Path(sys.argv[0]).as_posix().split(str(REPO) + "/")[-1], *sys.argv[1:]]),
              "commit": _commit(), "date": datetime.now(timezone.utc).strftime("%Y-%m-%d"), "figures": figures}
    Path(path).write_text(json.dumps(record, indent=1))
    print(f"figures written to {path}")
