"""What a fit run folder holds and what its run was meant to hold (``run.json``, written
by ``pipeline.runs.start_run`` as a run starts): the reports name what a stopped run left
out, and a new run finds an earlier one's results."""
from __future__ import annotations

from pathlib import Path

from ..io.fitrecords import read_run_json

KINDS = ("blendshape", "simulation")


def earlier_fits(run):
    """The fit.json files of plate fits in a run folder: run/<kind>/fit.json (one plate) and
    run/<frame>/<kind>/fit.json (a sequence)."""
    run = Path(run)
    return sorted(f for pattern in ("*/fit.json", "*/*/fit.json") for f in run.glob(pattern)
                  if f.parent.name in KINDS)


def run_notes(run, frame=None):
    """Lines on what a fit run (its run.json, written as it starts) did first (the actor's
    identity, on the run's own page) and planned and is missing:
    the kinds of ``frame`` (a sequence frame's name; None for a single plate) or the frames
    of a sequence that have no fit, and whether the run was stopped before it finished."""
    run = Path(run)
    plan = read_run_json(run / "run.json")
    if not plan:
        return []
    stopped = "" if plan.get("finished") else " (the run stopped before it finished)"
    said = [plan["identity"] + "."] if frame is None and plan.get("identity") else []
    if frame is None and plan.get("calibration_frame") and plan.get("calibration_why"):
        said.append(f"Light and albedo were calibrated on {plan['calibration_frame']}: {plan['calibration_why']}.")
    if frame is None and plan.get("frames"):
        found = {f.parent.parent.name for f in earlier_fits(run) if f.parent.parent != run}
        missing = [f for f in plan["frames"] if f not in found]
        return said + ([f"{len(missing)} of {len(plan['frames'])} frames have no fit{stopped}: "
                        + ", ".join(missing[:10]) + (" ..." if len(missing) > 10 else "")] if missing else [])
    folder = run if frame is None else run / frame
    missing = [k for k in plan.get("kinds", []) if not (folder / k / "fit.json").is_file()]
    return said + ([f"No {k} model fit here{stopped}." for k in missing] if missing and stopped else [])
