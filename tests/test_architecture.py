"""The house rules, checked statically (AST) over invface's source:

- every file is written through ``invface.io`` (its one atomic writer);
- no import cycles between modules or between subpackages, counting imports made inside
  functions and the simulation model's registration string;
- the import directions of ARCHITECTURE.md;
- functions a reader can hold in their head: none over ``LONGEST`` lines but the one Mitsuba
  integrator registration, whose class exists only once a variant is set;

and the atomic writer's promise: a failed rename leaves no temporary file and no target.
"""
from __future__ import annotations

import ast
import re
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[1] / "invface"

# calls that write or rename a file: allowed only inside invface/io/
WRITE_METHODS = {"savez", "savez_compressed", "savefig", "imsave", "imwrite", "VideoWriter", "write_text",
                 "write_bytes", "mkstemp", "NamedTemporaryFile", "export", "tofile", "rename"}
WRITE_FUNCTIONS = {"os.replace", "os.rename", "np.save", "numpy.save", "shutil.move", "shutil.copy",
                   "shutil.copyfile", "shutil.copy2", "shutil.copytree"}


def modules():
    """{dotted module name: path} of every module in invface."""
    out = {}
    for p in sorted(ROOT.rglob("*.py")):
        parts = list(p.relative_to(ROOT.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


MODULES = modules()


def _dotted(node):
    """'a.b.c' of an attribute chain, or None."""
    names = []
    while isinstance(node, ast.Attribute):
        names.append(node.attr)
        node = node.value
    if isinstance(node, ast.Name):
        names.append(node.id)
        return ".".join(reversed(names))
    return None


def _mode(call):
    """The mode string of an open() / Path.open() call, or None."""
    args = call.args[1:] if isinstance(call.func, ast.Name) else call.args
    mode = args[0] if args else None
    for k in call.keywords:
        if k.arg == "mode":
            mode = k.value
    return mode.value if isinstance(mode, ast.Constant) and isinstance(mode.value, str) else None


def file_writes(tree):
    """(line, call) of every call in ``tree`` that writes or renames a file by itself."""
    # bare names are writes only when imported from outside invface (``from numpy import savez``);
    # invface.io's own writers (savez, write_text, VideoWriter) are what every module should call
    foreign = {a.asname or a.name for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)
               and not n.level and not (n.module or "").startswith("invface") for a in n.names}
    found = []
    for n in ast.walk(tree):
        if not isinstance(n, ast.Call):
            continue
        f, name = n.func, _dotted(n.func) or ""
        if (isinstance(f, ast.Name) and f.id == "open") or (isinstance(f, ast.Attribute) and f.attr == "open"):
            if set(_mode(n) or "") & set("wax+"):
                found.append((n.lineno, f"open(..., {_mode(n)!r})"))
        elif name in WRITE_FUNCTIONS or (isinstance(f, ast.Attribute) and f.attr in WRITE_METHODS) \
                or (isinstance(f, ast.Name) and f.id in WRITE_METHODS and f.id in foreign):
            found.append((n.lineno, name or getattr(f, "attr", "?")))
    return found


def test_every_file_write_goes_through_io():
    bad = []
    for mod, path in MODULES.items():
        if mod == "invface.io" or mod.startswith("invface.io."):
            continue
        for line, call in file_writes(ast.parse(path.read_text())):
            bad.append(f"{path.relative_to(ROOT.parent)}:{line}: {call}")
    assert not bad, "file writes outside invface/io (use invface.io's writers):\n" + "\n".join(bad)


LONGEST = 80           # lines of a function, docstring included
LONG_ALLOWED = {"invface.render.integrator.register"}


def long_functions(tree, mod):
    """[(dotted name, lines)] of the functions (methods and nested ones included) longer than
    LONGEST in a module's AST."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            lines = node.end_lineno - node.lineno + 1
            if lines > LONGEST:
                out.append((f"{mod}.{node.name}", lines))
    return out


def test_no_function_over_80_lines():
    found = [f for mod, path in MODULES.items() for f in long_functions(ast.parse(path.read_text()), mod)]
    bad = [f"{name}: {n} lines" for name, n in found if name not in LONG_ALLOWED]
    assert not bad, f"functions over {LONGEST} lines (split them along their stages):\n" + "\n".join(bad)
    assert len(found) <= 2


def test_the_length_lint_counts_nested_functions():
    src = "def outer():\n    def inner():\n" + "        x = 1\n" * 85 + "    return inner\n"
    names = [n for n, _ in long_functions(ast.parse(src), "m")]
    assert names == ["m.outer", "m.inner"]


def test_the_write_lint_finds_writes():
    """The lint itself: each kind of write it must catch, caught."""
    src = "\n".join(["import os, numpy as np, cv2", "from numpy import savez", "from invface.io import write_text",
                     "savez(p, x=1)", "write_text(p, 'x')", "os.replace(a, b)", "np.savez_compressed(p, x=1)",
                     "fig.savefig(p)", "cv2.imwrite(p, img)", "Path(p).write_text('x')", "open(p, 'w')",
                     "open(p, mode='ab')", "mesh.export(p)", "cv2.VideoWriter(p, 0, 1, (2, 2))",
                     "open(p)", "model.save(p)", "s.replace('a', 'b')", "Path(p).open('wb')"])
    calls = [c for _, c in file_writes(ast.parse(src))]
    assert len(calls) == 11, calls


def imports(mod, path):
    """The invface modules that ``mod`` imports anywhere in its file (functions included), and
    those named by registration strings "invface.x.y:Name"."""
    tree = ast.parse(path.read_text())
    pkg = mod if path.name == "__init__.py" else mod.rsplit(".", 1)[0]
    found = set()
    for n in ast.walk(tree):
        targets = []
        if isinstance(n, ast.Import):
            targets = [a.name for a in n.names]
        elif isinstance(n, ast.ImportFrom):
            base = n.module or ""
            if n.level:
                up = pkg
                for _ in range(n.level - 1):
                    up = up.rsplit(".", 1)[0]
                base = up + ("." + n.module if n.module else "")
            targets = [f"{base}.{a.name}" if f"{base}.{a.name}" in MODULES else base for a in n.names]
        elif isinstance(n, ast.Constant) and isinstance(n.value, str):
            m = re.fullmatch(r"(invface(?:\.\w+)+):\w+", n.value)
            targets = [m.group(1)] if m else []
        for t in targets:
            while t not in MODULES and "." in t:
                t = t.rsplit(".", 1)[0]
            if t in MODULES and t != mod:
                found.add(t)
    return found


GRAPH = {m: imports(m, p) for m, p in MODULES.items()}


def package(mod):
    """The subpackage (or top-level module) a module belongs to: invface.fit.plate -> invface.fit."""
    return ".".join(mod.split(".")[:2])


def cycles(graph):
    """The strongly connected components of more than one node (Tarjan, iterative)."""
    index, low, stack, on, out = {}, {}, [], set(), []
    for root in graph:
        if root in index:
            continue
        work = [(root, iter(graph.get(root, ())))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            w = next(it, None)
            if w is not None:
                if w not in index:
                    index[w] = low[w] = len(index)
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(graph.get(w, ()))))
                elif w in on:
                    low[v] = min(low[v], index[w])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[v])
            if low[v] == index[v]:
                comp = []
                while True:
                    w = stack.pop()
                    on.discard(w)
                    comp.append(w)
                    if w == v:
                        break
                if len(comp) > 1:
                    out.append(sorted(comp))
    return out


def test_cycle_finder_finds_cycles():
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_no_module_import_cycles():
    assert cycles(GRAPH) == []


def test_no_package_import_cycles():
    # the root package is the facade that re-exports the others; it is no layer of its own
    pg = {}
    for a, bs in GRAPH.items():
        if a == "invface":
            continue
        for b in bs:
            if b != "invface" and package(a) != package(b):
                pg.setdefault(package(a), set()).add(package(b))
    assert cycles(pg) == []


# ARCHITECTURE.md's table: the packages each package may import (errors and _env are open to all)
MAY_IMPORT = {
    "invface.io": set(),
    "invface.mesh": {"io"},
    "invface.model": {"mesh", "io"},
    "invface.sim": {"model", "mesh"},
    "invface.template": {"model", "sim", "mesh", "io"},
    "invface.morph": {"template", "model", "sim", "mesh", "io"},
    "invface.measure": {"model", "sim"},
    "invface.render": {"mesh", "io"},
    "invface.bridge": {"model"},
    "invface.fit": {"bridge", "render", "sim", "model", "morph", "measure", "mesh", "io"},
    "invface.report": {"render", "mesh", "io"},
    "invface.pipeline": {"fit", "report", "render", "sim", "model", "morph", "template", "measure", "mesh",
                         "io", "bridge"},
    "invface.cli": {"pipeline", "fit", "report", "render", "sim", "model", "morph", "template", "measure",
                    "mesh", "io", "bridge"},
}
OPEN = {"invface.errors", "invface._env", "invface._lazy"}


def test_import_directions():
    bad = []
    for a, bs in GRAPH.items():
        pa = package(a)
        if pa in ("invface", "invface.errors", "invface._env", "invface._lazy"):
            continue
        assert pa in MAY_IMPORT, f"{pa} is missing from ARCHITECTURE.md's table (and MAY_IMPORT)"
        for b in bs:
            pb = package(b)
            if pb == "invface":                       # the root package (its __version__): the CLI only
                if pa != "invface.cli":
                    bad.append(f"{a} imports the root package invface")
                continue
            if pb != pa and pb not in OPEN and pb.split(".", 1)[1] not in MAY_IMPORT[pa]:
                bad.append(f"{a} imports {b}: {pa} may import only {sorted(MAY_IMPORT[pa])}")
    assert not bad, "\n".join(bad)


def test_the_table_is_architecture_md():
    """MAY_IMPORT is the table in ARCHITECTURE.md, row by row."""
    text = (ROOT.parent / "ARCHITECTURE.md").read_text()
    for pkg, allowed in MAY_IMPORT.items():
        name = pkg.split(".", 1)[1]
        row = next((line for line in text.splitlines() if line.startswith(f"| `{name}")), None)
        assert row is not None, name
        cell = row.split("|")[3].split("never")[0]
        if name in ("pipeline", "cli"):          # "everything above but cli", "everything"
            assert "everything" in cell, name
            continue
        listed = set(re.findall(r"`(\w+)`", cell)) - {"errors"}
        assert listed == allowed or (not allowed and "nothing" in cell), (name, listed, allowed)


def test_simulation_and_model_never_touch_dr_jit():
    """The Dr.Jit bridge is the one place where the simulation's adjoint meets Dr.Jit arrays:
    the simulation, the model, meshes, morph, template and io never import Dr.Jit or Mitsuba."""
    below = ("invface.sim", "invface.model", "invface.mesh", "invface.morph", "invface.template", "invface.io")
    bad = [m for m, p in MODULES.items() if m.startswith(below)
           and re.search(r"^\s*(import|from) (drjit|mitsuba)", p.read_text(), re.M)]
    assert not bad, bad


# -- the atomic writer ------------------------------------------------------------------------
def _writers(tmp_path):
    from invface.io.arrays import savez
    from invface.io.atomic import write_text
    from invface.io.images import write_display_image, write_image
    from invface.io.jsonfile import write_object
    from invface.io.meshes import write_mesh
    from invface.io.tables import write_csv
    img = np.full((8, 8, 3), 0.5, np.float32)
    tri = (np.eye(3), np.array([[0, 1, 2]]))
    return {"json": lambda p: write_object(p.with_suffix(".json"), {"a": 1}),
            "npz": lambda p: savez(p.with_suffix(".npz"), {"a": np.zeros(3)}),
            "png": lambda p: write_image(p.with_suffix(".png"), img),
            "exr": lambda p: write_image(p.with_suffix(".exr"), img),
            "display": lambda p: write_display_image(p.with_suffix(".png"), img),
            "csv": lambda p: write_csv(p.with_suffix(".csv"), ["a"], [[1]]),
            "html": lambda p: write_text(p.with_suffix(".html"), "<p>"),
            "obj": lambda p: write_mesh(p.with_suffix(".obj"), *tri)}


@pytest.mark.parametrize("kind", ["json", "npz", "png", "exr", "display", "csv", "html", "obj"])
def test_failed_rename_leaves_nothing(tmp_path, monkeypatch, kind):
    import invface.io.atomic as atomic
    write = _writers(tmp_path)[kind]
    write(tmp_path / "before")                       # the writer works...
    assert len(list(tmp_path.iterdir())) == 1

    def refuse(src, dst):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(atomic.os, "replace", refuse)
    with pytest.raises(OSError):
        write(tmp_path / "after")                    # ...and a failed rename leaves no trace
    assert sorted(p.name for p in tmp_path.iterdir()) == [f"before.{'png' if kind == 'display' else kind}"]


def test_failed_write_keeps_the_old_file(tmp_path):
    from invface.io.atomic import atomic_open
    target = tmp_path / "fit.json"
    target.write_text("old")
    with pytest.raises(RuntimeError), atomic_open(target) as fh:
        fh.write("half")
        raise RuntimeError("killed mid-write")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["fit.json"]


def test_video_writer_is_atomic(tmp_path):
    from invface.errors import InvfaceError
    from invface.io.video import VideoWriter
    frame = np.zeros((16, 16, 3), np.uint8)
    with VideoWriter(tmp_path / "a.mp4", fps=24) as v:
        for _ in range(3):
            v.write(frame)
    assert (tmp_path / "a.mp4").stat().st_size > 0
    with pytest.raises(InvfaceError, match="b.mp4: frame 1 is 8x8"), VideoWriter(tmp_path / "b.mp4") as v:
        v.write(frame)
        v.write(frame[:8, :8])
    with pytest.raises(InvfaceError, match="no video was written"), VideoWriter(tmp_path / "c.mp4"):
        pass
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.mp4"]


def test_videos_are_h264_that_browsers_play(tmp_path):
    """With imageio-ffmpeg (a dependency) the writer encodes H.264 (read back by OpenCV as
    such), an odd-sized frame padded to even sides, its pixels kept."""
    import cv2
    pytest.importorskip("imageio_ffmpeg")
    from invface.io.video import VideoWriter
    frame = np.zeros((61, 81, 3), np.uint8)
    frame[20:40, 30:50] = (250, 120, 30)
    with VideoWriter(tmp_path / "v.mp4", fps=24) as v:
        for _ in range(5):
            v.write(frame)
    assert v.codec == "h264"
    cap = cv2.VideoCapture(str(tmp_path / "v.mp4"))
    fourcc = int(cap.get(cv2.CAP_PROP_FOURCC)).to_bytes(4, "little").decode().lower()
    ok, got = cap.read()
    cap.release()
    assert fourcc in ("h264", "avc1") and ok and got.shape == (62, 82, 3)
    assert np.abs(got[30, 40, ::-1].astype(int) - (250, 120, 30)).max() < 12


def test_exporter_table(tmp_path):
    from invface.errors import ConfigError
    from invface.io import export, exporter
    from invface.io.exporters import suffixes
    export(tmp_path / "m.obj", (np.eye(3), np.array([[0, 1, 2]])))
    export(tmp_path / "t.csv", (["a", "b"], [[1, 2]]))
    export(tmp_path / "d.json", {"x": [1, 2]})
    assert (tmp_path / "t.csv").read_text().splitlines() == ["a,b", "1,2"]
    assert {".obj", ".ply", ".png", ".exr", ".json", ".npz", ".csv", ".html"} <= set(suffixes())
    with pytest.raises(ConfigError, match=r"result: cannot write '\(no suffix\)' files; use one of"):
        exporter(tmp_path / "result")


def test_written_files_get_the_usual_mode(tmp_path):
    """The temporary file's private mode (0600) is not what the user gets: a written file has the
    mode a plain open() gives a new file under the process's umask."""
    import os
    import stat

    from invface.io.atomic import write_text
    mask = os.umask(0)
    os.umask(mask)
    write_text(tmp_path / "page.html", "<p>")
    (tmp_path / "plain.html").write_text("<p>")
    mode = lambda p: stat.S_IMODE(p.stat().st_mode)
    assert mode(tmp_path / "page.html") == mode(tmp_path / "plain.html") == 0o666 & ~mask
