"""The README's recipes run verbatim (issue 64): every `invface` line of the README's first
shell block, in order, in a fresh folder, with the small options each verb's line gets here
(SMALL: a small head, few iterations, a short clip). A line whose input no earlier line makes
(the VFX plate sequence) is skipped. Each must exit 0 and leave what the README says it does."""
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import SMALL_RESOLUTION

README = Path(__file__).resolve().parents[1] / "README.md"
SMALL = {"samples": ["--resolution", str(SMALL_RESOLUTION), "--frames", "4"],
         "fit-plate": ["--resolution", str(SMALL_RESOLUTION), "--iterations", "2"],
         "build-model": ["--resolution", str(SMALL_RESOLUTION)]}
# what each recipe's line leaves, as the README's comments say
LEAVES = {"fit": ["index.html", "arkit_blendshape.csv", "face_simulation.usd", "rig_blendshape.glb",
                  "rig_simulation.usd"],
          "take": ["index.html", "curves.csv", "overlay_blendshape.mp4"],
          "actor": ["contact_sheet.png"], "fit-actor": ["index.html"]}


def recipe_lines():
    block = re.search(r"```sh\n(.*?)```", README.read_text(), re.S).group(1)
    return [shlex.split(line.split("  #")[0]) for line in block.splitlines() if line.startswith("invface ")]


def test_the_recipes_parse_and_name_what_they_make():
    lines = recipe_lines()
    verbs = [w[1] for w in lines]
    assert verbs[:3] == ["samples", "fit-plate", "fit-plate"] and "build-model" in verbs and "export" in verbs


@pytest.mark.skipif(not __import__("importlib").util.find_spec("skimage"), reason="scikit-image is not installed")
def test_the_readme_recipes_run_verbatim(tmp_path):
    ran = []
    repo = str(README.parent)          # this checkout's invface, from another working folder
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([repo, *filter(None, [os.environ.get("PYTHONPATH")])]))
    for words in recipe_lines():
        verb, rest = words[1], words[2:]
        if verb == "fit-plate" and not any((tmp_path / a).exists() for a in rest if "/" in a or "." in a):
            continue                                   # its plates are the user's own (shot.%04d.dpx)
        r = subprocess.run([sys.executable, "-m", "invface.cli", verb, *rest, *SMALL.get(verb, [])], cwd=tmp_path,
                           capture_output=True, text=True, env=env)
        assert r.returncode == 0, (words, r.stderr[-3000:])
        assert "Traceback" not in r.stderr
        ran.append(verb)
    assert ran == ["samples", "fit-plate", "fit-plate", "build-model", "fit-plate", "export"]
    for folder, names in LEAVES.items():
        for name in names:
            assert (tmp_path / folder / name).is_file(), (folder, name)
    assert (tmp_path / "actor.npz").is_file()
