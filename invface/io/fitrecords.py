"""A fit run's records as the reports, the resume and the exporters read them: each fit's
``fit.json`` (``fit.results.write_fit_files``) and the run's ``run.json``
(``pipeline.runs.start_run``). Their fields go through ``schema.Fields``, so a record edited
by hand or by another tool is one line naming the file and the field, not a TypeError in a
report or an export.
"""
from __future__ import annotations

from pathlib import Path

from ..errors import InvfaceError
from .jsonfile import read_object
from .schema import Fields

_REFIT = "fit the plate again, or restore the file"


def read_fit_json(path, error=InvfaceError, required=()):
    """The fit.json at ``path`` as a dict, with the fields the reports, the resume and the
    exports read checked where present: kind, flagged and status (str); weights, activations
    and arkit ({name: number}); jaw (n,), rotation (3,) rad, translation (3,) m; eyes ({side:
    {yaw, pitch}} rad); frame (int >= 0), time (s), curve_rms_px, image_rms and
    lip_volume_change (numbers; null where the fit's value was not finite). ``required``: the
    names the caller cannot do without. Fields it does not check pass as written. ``error``:
    the InvfaceError class raised, naming the file and the field."""
    path = Path(path)
    data = read_object(path, error, what=f"fit result ({_REFIT})")
    f = Fields(data, path, error, listing=f"a fit.json from fit-plate or fit-scan holds them; {_REFIT}")
    f.require(*required)
    vector = {"jaw": (None,), "rotation": (3,), "translation": (3,)}
    readers = {"kind": f.text, "flagged": f.text, "status": f.text, "weights": f.numbers, "activations": f.numbers,
               "arkit": f.numbers, "eyes": lambda n, default: _eyes(f, default), "time": f.number,
               "curve_rms_px": f.number, "image_rms": f.number, "lip_volume_change": f.number,
               "frame": lambda n, default: f.number(n, default, low=0, integer=True)}
    readers.update({n: lambda n, default: _listed(f.array(n, vector[n], default)) for n in vector})
    return _checked(dict(data), data, readers)


def _listed(a):
    """An array as a list (None stays None)."""
    return None if a is None else a.tolist()


def _eyes(f, default):
    """fit.json's "eyes": {side: {yaw, pitch}} with numbers, or ``default``."""
    eyes = f.mapping("eyes", default)
    return default if eyes is default else {side: eyes.numbers(side) for side in eyes.data}


def _checked(rec, data, readers):
    """``rec`` with each field of ``data`` that ``readers`` ({name: reader(name, default)}) names
    replaced by what its reader returns; a field that is null stays null."""
    for name, read in readers.items():
        if name in data:
            rec[name] = read(name, None)
    return rec


def read_run_json(path, error=InvfaceError):
    """The run.json at ``path`` as a dict ({} when there is none), with its fields checked where
    present: frames, kinds and identity_frames (lists of str), inputs, identity, identity_from, calibrated_on,
    calibration_frame, calibration_why (str), finished and identity_space (true / false), fps
    (> 0)."""
    path = Path(path)
    if not path.is_file():
        return {}
    data = read_object(path, error, what="run record (run.json; rerun the fit with --restart to rewrite it)")
    f = Fields(data, path, error)
    readers = {"frames": f.strings, "kinds": f.strings, "identity_frames": f.strings, "finished": f.boolean,
               "identity_space": f.boolean,
               "fps": lambda n, default: f.number(n, default, low=1e-6)}
    readers.update(dict.fromkeys(("inputs", "identity", "identity_from", "calibrated_on", "calibration_frame",
                                  "calibration_why"), f.text))
    return _checked(dict(data), data, readers)
