"""A fit run's bookkeeping: the hash of its inputs, its run.json, resume and each frame's record.

Every kind of every frame is written atomically as it finishes, its ``fit.json`` carrying
``input_hash``: the SHA-1 of the frame's pixels and camera, the model, the calibration and
the fit options. A rerun of the same command into the same folder skips the frames whose hash
matches (``start_run(force=True)`` starts over); a run with other inputs is refused.
"""
from __future__ import annotations

import hashlib
import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from ..errors import InvfaceError
from ..io.fitrecords import read_fit_json, read_run_json
from ..io.jsonfile import write_object

RUN_FILE = "run.json"


def _sha(*parts):
    h = hashlib.sha1()
    for p in parts:
        h.update(np.ascontiguousarray(p).tobytes() if isinstance(p, np.ndarray) else str(p).encode())
    return h.hexdigest()[:16]


def run_hash(model, calibration, options):
    """The SHA-1 (16 hex) of what a frame's fit depends on besides its pixels: the model
    (neutral, blendshapes, tets), the calibration (light, albedo) and the fit options (dict)."""
    cal = getattr(calibration, "calibration", calibration)
    return _sha(np.asarray(model.neutral, float), np.asarray(model.blendshapes, float), np.asarray(model.tets),
                np.asarray(cal.gamma, float), np.asarray(cal.albedo, float),
                json.dumps(options, sort_keys=True, default=str))


def read_run(out):
    """out/run.json as a dict ({} when absent; ``io.fitrecords.read_run_json``: a file that is
    not a run record is an InvfaceError naming it and the field)."""
    return read_run_json(Path(out) / RUN_FILE)


def start_run(out, frames, kinds, force=False, inputs=None, extra=None):
    """Claim the output folder for a fit run. One with an earlier run's fits is resumed when
    its run.json records the same ``inputs`` hash (``run_hash``): the finished frames stay and
    True is returned; otherwise it is refused (InvfaceError) unless ``force``, which removes
    the fits (the kind folders with a fit.json) and the report pages, nothing else. Then
    out/run.json {frames, kinds, inputs, finished: false, **extra} is written; the reports read
    it to name what a stopped run left out."""
    import shutil
    from ..report.runs import earlier_fits
    out = Path(out)
    old = earlier_fits(out)
    resume = bool(old) and not force and inputs is not None and read_run(out).get("inputs") == inputs
    if old and not force and not resume:
        raise InvfaceError(f"{out}: holds an earlier run's fits ({len(old)} fit.json, e.g. {old[0]}) made from "
                           "other inputs; pass --restart to replace them, or choose another output folder")
    if not resume:
        for f in old:
            shutil.rmtree(f.parent)
        for page in [*out.glob("index.html"), *out.glob("*/index.html"), *out.glob("weights_*.png"),
                     *out.glob("activations_*.png")]:
            page.unlink()
    out.mkdir(parents=True, exist_ok=True)
    write_object(out / RUN_FILE, {"frames": list(frames), "kinds": list(kinds), "inputs": inputs,
                                  "finished": False, **(extra or {})})
    return resume


def finish_run(out):
    """Mark out/run.json finished."""
    write_object(Path(out) / RUN_FILE, dict(read_run(out), finished=True))


def frame_hash(digest, inputs):
    """A frame's input hash: its pixel digest and the run's ``run_hash``."""
    return _sha(digest, inputs)


def fit_record(folder, kind):
    """The kind's fit.json in a frame folder as a dict (``io.fitrecords.read_fit_json``); None
    when absent or not a fit record, so that the frame is fitted again."""
    try:
        return read_fit_json(Path(folder) / kind / "fit.json")
    except InvfaceError:
        return None


def finished_record(folder, kind, input_hash):
    """The kind's fit.json in a frame folder (a dict) when it was made from the same inputs,
    else None."""
    rec = fit_record(folder, kind)
    return rec if rec is not None and rec.get("input_hash") == input_hash else None


def start_from(model, record):
    """A warm start (p, rotation, translation) from a fit.json record."""
    from ..model.controls import FitVector
    vec = FitVector.of(model)
    p, rot, tr = vec.unpack(vec.from_dict(record, what="fit.json"))
    return SimpleNamespace(p=p, rotation=rot, translation=tr)
