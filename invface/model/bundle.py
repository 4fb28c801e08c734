"""FaceModel <-> .npz bundle: flat arrays plus a JSON header, validated on load.

The file is a plain ``np.savez_compressed`` archive read with ``allow_pickle=False``.
Variable-length lists (muscles, curves) are stored concatenated with offsets; names and
metadata live in the JSON header (key ``header``).
"""
from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np

from ..errors import BundleError, InvfaceError
from ..io.arrays import savez
from ..io.schema import Fields
from ..mesh.embedding import skin_embedding_method
from ..mesh.tets import signed_volumes
from .muscle import Muscle

FORMAT = "invface-facemodel"
VERSION = 1


def _concat(arrays, dtype, width=None):
    offsets = np.cumsum([0] + [len(a) for a in arrays]).astype(np.int64)
    shape = (0,) if width is None else (0, width)
    data = np.concatenate([np.asarray(a, dtype) for a in arrays]) if arrays else np.zeros(shape, dtype)
    return data, offsets


def _split(data, offsets):
    return [data[offsets[i]:offsets[i + 1]] for i in range(len(offsets) - 1)]


def write_bundle(model, path):
    """Write ``model`` to ``path`` atomically."""
    path = Path(path)
    m = model
    mt, mt_off = _concat([x.tets for x in m.muscles], np.int64)
    mf, _ = _concat([x.fibers for x in m.muscles], np.float64, 3)
    mc, mc_off = _concat([x.centerline for x in m.muscles], np.float64, 3)
    ma, ma_off = _concat([x.activation_curve for x in m.muscles], np.float64, 2)
    curve_names = list(m.curves)
    cv, cv_off = _concat([m.curves[k] for k in curve_names], np.int64)
    header = {
        "format": FORMAT, "version": VERSION, "units": "m",
        "frame": "+Y up, face along +Z, +X actor's left",
        "blendshape_names": list(m.blendshape_names),
        "landmark_names": list(m.landmarks), "curve_names": curve_names,
        "muscles": [{"name": x.name, "side": x.side} for x in m.muscles],
        "meta": m.meta,
    }
    if m.parts is not None:
        header["parts"] = list(m.parts.names)
    arrays = dict(
        header=np.array(json.dumps(header)),
        neutral=m.neutral, triangles=m.triangles,
        blendshapes=np.asarray(m.blendshapes, np.float64).reshape(len(m.blendshape_names), len(m.neutral), 3),
        jaw_pivot=m.jaw_pivot, jaw_frame=m.jaw_frame, jaw_weights=m.jaw_weights,
        rest_positions=m.rest_positions, tets=m.tets,
        fixed_cranium=m.fixed_cranium, fixed_jaw=m.fixed_jaw,
        embed_tets=m.embed_tets, embed_weights=m.embed_weights,
        volume_jaw_weights=m.volume_jaw_weights,
        muscle_tets=mt, muscle_tet_offsets=mt_off, muscle_fibers=mf,
        muscle_centerlines=mc, muscle_centerline_offsets=mc_off,
        muscle_activation_curves=ma, muscle_activation_curve_offsets=ma_off,
        landmark_ids=np.array([m.landmarks[k] for k in m.landmarks], np.int64),
        curve_ids=cv, curve_offsets=cv_off,
        cranium_vertices=m.cranium_mesh[0], cranium_triangles=m.cranium_mesh[1],
        jaw_vertices=m.jaw_mesh[0], jaw_triangles=m.jaw_mesh[1],
    )
    if m.blendshape_activations is not None:
        arrays["blendshape_activations"] = m.blendshape_activations
    if m.track_displacements is not None:
        arrays["track_displacements"] = m.track_displacements
    if m.scan_transform is not None:
        arrays["scan_transform"] = np.asarray(m.scan_transform, np.float64)
    if m.parts is not None:
        arrays.update(parts_vertices=m.parts.vertices, parts_triangles=m.parts.triangles,
                      parts_albedo=m.parts.albedo, parts_jaw_weights=m.parts.jaw_weights,
                      parts_offsets=m.parts.offsets)
    savez(path, arrays)


class _Reader:
    """Typed, shape-checked access to the arrays of one bundle; errors name the field."""

    def __init__(self, path, data):
        self.path = path
        self.data = data

    def fail(self, field, problem):
        raise BundleError(f"{self.path}: field '{field}' {problem}")

    def get(self, field, kind, shape=None, optional=False):
        if field not in self.data:
            if optional:
                return None
            self.fail(field, "is missing (not an invface FaceModel bundle, or written by an incompatible version)")
        try:
            a = self.data[field]
        except Exception as e:  # zip member truncated or corrupted
            self.fail(field, f"cannot be read ({type(e).__name__}: {e}); the file is truncated or corrupted")
        if kind == "f":
            if a.dtype.kind not in "fiu":
                self.fail(field, f"must be numeric, got dtype {a.dtype}")
            a = a.astype(np.float64)
            if not np.all(np.isfinite(a)):
                self.fail(field, f"has {int((~np.isfinite(a)).sum())} non-finite values")
        elif kind == "i":
            if a.dtype.kind not in "iu":
                self.fail(field, f"must be integer, got dtype {a.dtype}")
            a = a.astype(np.int64)
        if shape is not None:
            if a.ndim != len(shape) or any(s is not None and s != d for s, d in zip(shape, a.shape)):
                want = "(" + ", ".join("*" if s is None else str(s) for s in shape) + ")"
                self.fail(field, f"has shape {a.shape}, expected {want}")
        return a

    def ids(self, field, upper, shape=None):
        a = self.get(field, "i", shape)
        if a.size and (a.min() < 0 or a.max() >= upper):
            self.fail(field, f"has indices outside [0, {upper}) (min {a.min()}, max {a.max()})")
        return a


def _read_header(path, raw):
    """The bundle's JSON header (a dict), checked: the format, a version this invface reads,
    the name lists, and a name for every muscle."""
    h = Fields({"header": raw}, path, BundleError).json("header")
    fmt = h.data.get("format")
    if fmt != FORMAT:
        h.fail("format", f"is {fmt!r}, expected {FORMAT!r}")
    version = h.number("version", default=-1, integer=True)
    if version > VERSION:
        h.fail("version", f"is {version}, newer than this invface ({VERSION}); upgrade invface")
    for key in ("blendshape_names", "landmark_names", "curve_names", "muscles"):
        h.listing_of(key)
    for i, muscle in enumerate(h.data["muscles"]):
        Fields(muscle, f"{path}: header muscle {i}", BundleError).text("name")
    return h.data


def read_bundle(path):
    """Read and validate a bundle: the FaceModel's fields as a dict (``FaceModel(**fields)``);
    every problem raises BundleError naming path and field."""

    path = Path(path)
    if not path.exists():
        raise BundleError(f"{path}: no such file")
    try:
        data = np.load(path, allow_pickle=False)
    except (zipfile.BadZipFile, ValueError, OSError, EOFError) as e:
        raise BundleError(f"{path}: not a readable .npz bundle ({type(e).__name__}: {e}); "
                          "the file is truncated or corrupted, rebuild it") from e
    with data:
        r = _Reader(path, data)
        header = _read_header(path, r.get("header", None, ()))

        neutral = r.get("neutral", "f", (None, 3))
        V = len(neutral)
        triangles = r.ids("triangles", V, (None, 3))
        K = len(header["blendshape_names"])
        blendshapes = r.get("blendshapes", "f", (K, V, 3))
        X = r.get("rest_positions", "f", (None, 3))
        N = len(X)
        tets = r.ids("tets", N, (None, 4))
        T = len(tets)
        _check_elements(r, X, tets, triangles)
        jaw_weights = r.get("jaw_weights", "f", (V,))
        vjw = r.get("volume_jaw_weights", "f", (N,))
        for name, w in (("jaw_weights", jaw_weights), ("volume_jaw_weights", vjw)):
            if w.min() < -1e-9 or w.max() > 1 + 1e-9:
                r.fail(name, f"must lie in [0, 1] (range {w.min():.3g}..{w.max():.3g})")
        embed_tets = r.ids("embed_tets", T, (V,))
        embed_weights = r.get("embed_weights", "f", (V, 4))
        if np.abs(embed_weights.sum(1) - 1).max() > 1e-6:
            r.fail("embed_weights", "rows must sum to 1 (barycentric weights)")
        M = len(header["muscles"])
        muscles = _read_muscles(r, header, T)
        lm_ids = r.ids("landmark_ids", V, (len(header["landmark_names"]),))
        cv_off = r.get("curve_offsets", "i", (len(header["curve_names"]) + 1,))
        cv = r.ids("curve_ids", V, (int(cv_off[-1]),))
        cverts = r.get("cranium_vertices", "f", (None, 3))
        jverts = r.get("jaw_vertices", "f", (None, 3))
        acts = r.get("blendshape_activations", "f", (K, M), optional=True)
        track = r.get("track_displacements", "f", (K, N, 3), optional=True)
        scan_tf = r.get("scan_transform", "f", (4, 4), optional=True)
        parts = _read_parts(r, header)
        meta = dict(header.get("meta", {}))
        try:
            skin_embedding_method(meta)
        except InvfaceError as e:
            r.fail("header", str(e))
        return dict(
            neutral=neutral, triangles=triangles, blendshape_names=[str(s) for s in header["blendshape_names"]],
            blendshapes=blendshapes, jaw_pivot=r.get("jaw_pivot", "f", (3,)), jaw_frame=r.get("jaw_frame", "f", (3, 3)),
            jaw_weights=jaw_weights, rest_positions=X, tets=tets,
            fixed_cranium=r.ids("fixed_cranium", N, (None,)), fixed_jaw=r.ids("fixed_jaw", N, (None,)),
            embed_tets=embed_tets, embed_weights=embed_weights, volume_jaw_weights=vjw, muscles=muscles,
            landmarks={str(k): int(v) for k, v in zip(header["landmark_names"], lm_ids)},
            curves={str(k): v for k, v in zip(header["curve_names"], _split(cv, cv_off))},
            cranium_mesh=(cverts, r.ids("cranium_triangles", len(cverts), (None, 3))),
            jaw_mesh=(jverts, r.ids("jaw_triangles", len(jverts), (None, 3))),
            blendshape_activations=acts, track_displacements=track, scan_transform=scan_tf,
            parts=parts, meta=meta,
        )


def _check_elements(r, X, tets, triangles):
    """Refuse an empty tet mesh, inverted or degenerate tets (rest positions ``X``) and skin
    triangles with a repeated vertex."""
    if len(tets) == 0:
        r.fail("tets", "is empty")
    vol = signed_volumes(X, tets)
    if np.any(vol <= 0):
        r.fail("tets", f"has {int((vol <= 0).sum())} inverted or degenerate tets (first: {int(np.argmax(vol <= 0))})")
    deg = (triangles[:, 0] == triangles[:, 1]) | (triangles[:, 1] == triangles[:, 2]) | (triangles[:, 0] == triangles[:, 2])
    if deg.any():
        r.fail("triangles", f"has {int(deg.sum())} triangles with a repeated vertex")


def _read_muscles(r, header, T):
    """The header's muscles with their tets (of ``T``), unit fibre directions, centre-lines and
    activation curves, each stored flat with an offsets array: a list of Muscle."""
    M = len(header["muscles"])
    mt_off = r.get("muscle_tet_offsets", "i", (M + 1,))
    mt = r.ids("muscle_tets", T, (int(mt_off[-1]),))
    mf = r.get("muscle_fibers", "f", (int(mt_off[-1]), 3))
    if len(mf) and np.abs(np.linalg.norm(mf, axis=1) - 1).max() > 1e-6:
        r.fail("muscle_fibers", "must be unit vectors")
    mc_off = r.get("muscle_centerline_offsets", "i", (M + 1,))
    mc = r.get("muscle_centerlines", "f", (int(mc_off[-1]), 3))
    ma_off = r.get("muscle_activation_curve_offsets", "i", (M + 1,))
    ma = r.get("muscle_activation_curves", "f", (int(ma_off[-1]), 2))
    for off, fld in ((mt_off, "muscle_tet_offsets"), (mc_off, "muscle_centerline_offsets"),
                     (ma_off, "muscle_activation_curve_offsets")):
        if off[0] != 0 or np.any(np.diff(off) < 0):
            r.fail(fld, "must start at 0 and be non-decreasing")
    muscles = []
    for i, (mh, t, f, c, a) in enumerate(zip(header["muscles"], _split(mt, mt_off), _split(mf, mt_off),
                                             _split(mc, mc_off), _split(ma, ma_off))):
        if len(t) == 0 or len(c) < 2:
            r.fail("muscle_tets", f"muscle '{mh.get('name', i)}' is empty or has no centre-line")
        muscles.append(Muscle(str(mh["name"]), t, f, c, a, str(mh.get("side", "M"))))
    return muscles


def _read_parts(r, header):
    """The optional inner parts (eyes, teeth, mouth), or None for a bundle without them."""
    from .parts import InnerParts
    if "parts_vertices" not in r.data:
        return None
    names = header.get("parts")
    if not isinstance(names, list):
        r.fail("header", "lacks the list 'parts' that names the parts' meshes")
    pv = r.get("parts_vertices", "f", (None, 3))
    P = len(pv)
    parts = InnerParts(pv, r.ids("parts_triangles", P, (None, 3)), r.get("parts_albedo", "f", (P, 3)),
                       r.get("parts_jaw_weights", "f", (P,)), [str(n) for n in names],
                       r.get("parts_offsets", "i", (len(names) + 1,)))
    try:
        parts.validate()
    except ValueError as e:
        r.fail("parts_vertices", str(e))
    return parts
