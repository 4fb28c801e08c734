"""PLY files whose faces are stored as triangle strips (``element tristrips`` with a
``vertex_indices`` list, strips separated by -1): the layout of the Stanford and Cyberware scan
archives, which trimesh reads as vertices alone. ASCII and binary (either byte order)."""
from __future__ import annotations

import numpy as np

from ..errors import MeshError

SCALARS = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
           "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
           "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def header(data, path):
    """(format, [(element name, count, [(property name, type, list count type or None)])],
    offset of the body) of a PLY file's bytes."""
    end = data.find(b"end_header")
    if not data.startswith(b"ply") or end < 0:
        raise MeshError(f"{path}: not a PLY file (no 'ply' ... 'end_header')")
    body = data.index(b"\n", end) + 1
    fmt, elements = None, []
    for line in data[:end].decode("ascii", "replace").splitlines():
        w = line.split()
        if not w:
            continue
        if w[0] == "format":
            fmt = w[1]
        elif w[0] == "element":
            elements.append((w[1], int(w[2]), []))
        elif w[0] == "property" and elements:
            if w[1] == "list":
                elements[-1][2].append((w[4], w[3], w[2]))
            else:
                elements[-1][2].append((w[2], w[1], None))
    return fmt, elements, body


def vertex_count(path):
    """The number of vertices a PLY file's header declares (0 without a vertex element)."""
    from pathlib import Path
    with open(Path(path), "rb") as fh:
        head = fh.read(65536)
    try:
        _, elements, _ = header(head, path)
    except (MeshError, ValueError):
        return 0
    return next((count for name, count, _ in elements if name == "vertex"), 0)


def strips_to_triangles(indices):
    """(f, 3) triangles of strips given as one index list with -1 between strips; each strip's
    odd triangles are flipped so that all keep the first one's winding; degenerate ones dropped."""
    idx = np.asarray(indices, np.int64)
    tris = []
    for strip in np.split(idx, np.flatnonzero(idx < 0)):
        s = strip[strip >= 0]
        if len(s) < 3:
            continue
        t = np.stack([s[:-2], s[1:-1], s[2:]], 1)
        t[1::2] = t[1::2][:, [1, 0, 2]]
        tris.append(t)
    T = np.concatenate(tris) if tris else np.zeros((0, 3), np.int64)
    keep = (T[:, 0] != T[:, 1]) & (T[:, 1] != T[:, 2]) & (T[:, 0] != T[:, 2])
    return T[keep]


def read_tristrips(path):
    """(vertices (n, 3), faces (f, 3)) of a PLY file with a tristrips element, or None when it
    has none. Raises MeshError naming the file when it cannot be read."""
    from pathlib import Path
    data = Path(path).read_bytes()
    fmt, elements, pos = header(data, path)
    if not any(name == "tristrips" for name, _, _ in elements):
        return None
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise MeshError(f"{path}: unknown PLY format '{fmt}'")
    read = _ascii_elements if fmt == "ascii" else _binary_elements
    found = read(data, pos, elements, "<" if fmt == "binary_little_endian" else ">", path)
    vertex = found.get("vertex")
    strips = found.get("tristrips")
    if vertex is None or not {"x", "y", "z"} <= set(vertex) or strips is None or "vertex_indices" not in strips:
        raise MeshError(f"{path}: a PLY with tristrips needs a vertex element with x, y, z and a "
                        "tristrips element with vertex_indices")
    V = np.stack([np.asarray(vertex[c], float) for c in "xyz"], 1)
    F = strips_to_triangles(np.concatenate([np.asarray(s) for s in strips["vertex_indices"]]))
    if len(F) and (F.max() >= len(V)):
        raise MeshError(f"{path}: its strips index vertex {int(F.max())}, the file has {len(V)}")
    return V, F


def _binary_elements(data, pos, elements, order, path):
    out = {}
    for name, count, props in elements:
        if all(p[2] is None for p in props):                     # scalar records: one numpy read
            dt = np.dtype([(p[0], order + SCALARS[p[1]]) for p in props])
            rec = np.frombuffer(data, dt, count, pos)
            pos += dt.itemsize * count
            out[name] = {p[0]: rec[p[0]] for p in props}
            continue
        cols = {p[0]: [] for p in props}
        for _ in range(count):
            for pname, ptype, ctype in props:
                if ctype is None:
                    v = np.frombuffer(data, order + SCALARS[ptype], 1, pos)[0]
                    pos += np.dtype(SCALARS[ptype]).itemsize
                else:
                    n = int(np.frombuffer(data, order + SCALARS[ctype], 1, pos)[0])
                    pos += np.dtype(SCALARS[ctype]).itemsize
                    v = np.frombuffer(data, order + SCALARS[ptype], n, pos)
                    pos += np.dtype(SCALARS[ptype]).itemsize * n
                cols[pname].append(v)
        out[name] = cols
        if pos > len(data):
            raise MeshError(f"{path}: the file ends inside its '{name}' element")
    return out


def _ascii_elements(data, pos, elements, _order, path):
    words = data[pos:].split()
    i, out = 0, {}
    for name, count, props in elements:
        cols = {p[0]: [] for p in props}
        for _ in range(count):
            for pname, ptype, ctype in props:
                if ctype is None:
                    cols[pname].append(float(words[i]))
                    i += 1
                else:
                    n = int(words[i])
                    cols[pname].append(np.array(words[i + 1:i + 1 + n], float).astype(np.int64))
                    i += 1 + n
        out[name] = cols
    if i > len(words):
        raise MeshError(f"{path}: the file ends inside its data")
    return out
