"""The documents a user reads: the CLI reference is the parser's own, and every link and picture
in README.md, ARCHITECTURE.md and docs/ resolves inside the clone."""
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", ROOT / "ARCHITECTURE.md", *sorted((ROOT / "docs").glob("*.md"))]


def flag_is_help(action):
    import argparse
    return isinstance(action, argparse._HelpAction)


def test_the_cli_reference_is_current():
    """docs/cli.md is what scripts/cli_docs.py writes from the parser: every verb and option,
    with its help text and default, and no option the CLI does not have."""
    r = subprocess.run([sys.executable, str(ROOT / "scripts" / "cli_docs.py"), "--check"], capture_output=True,
                       text=True)
    assert r.returncode == 0, r.stderr
    text = (ROOT / "docs" / "cli.md").read_text()
    sys.path.insert(0, str(ROOT / "scripts"))
    from cli_docs import verbs
    from invface.cli import build_parser
    for words, sub, _ in verbs(build_parser()):
        section = text.split(f"## `invface {' '.join(words)}`")[1].split("\n## ")[0]
        for action in sub._actions:
            for flag in ([] if flag_is_help(action) else action.option_strings):
                assert f"`{flag}`" in section, (words, flag)
    documented = set(re.findall(r"`(--[a-z][a-z-]*)`", text))
    parsers = [build_parser()] + [sub for _, sub, _ in verbs(build_parser())]
    known = {f for sub in parsers for a in sub._actions for f in a.option_strings}
    assert documented <= known, documented - known


def test_links_and_pictures_stay_inside_the_clone():
    for doc in DOCS:
        text = doc.read_text()
        assert "../shared" not in text, doc.name
        for target in re.findall(r"\]\(([^)#\s]+)", text):
            if re.match(r"[a-z]+://", target):
                continue
            assert (doc.parent / target).exists(), (doc.name, target)


def test_every_verbs_example_parses():
    """The example under each verb's --help (and in docs/cli.md) is a command the parser takes;
    so are the README's recipes."""
    import shlex
    from invface.cli import EXAMPLES, build_parser
    readme = (ROOT / "README.md").read_text()
    recipes = [line for block in re.findall(r"```sh\n(.*?)```", readme, re.S) for line in block.splitlines()
               if line.startswith("invface ")]
    assert len(recipes) >= 5
    for line in [e for lines in EXAMPLES.values() for e in lines] + recipes:
        argv = shlex.split(line.split("#")[0])[1:]
        args = build_parser().parse_args(argv)
        assert callable(args.func), line


UNITS = ("rad", "m", "mm", "px", "px^2", "s", "fps", "frame", "frames", "iterations", "processes", "dimensionless",
         "index", "metres", "share")


def test_every_numeric_flag_states_its_default_and_unit():
    """Every numeric option's help (docs/cli.md's row) gives its default, argparse's "(default:
    ...)" or its own words, and a unit (or says it has none: "dimensionless", an index)."""
    import argparse
    import re

    from invface import cli
    numeric = {cli.COUNT, cli.POSITIVE, cli.NON_NEGATIVE, cli.FINITE, cli.NON_NEGATIVE_INT, float, int}
    missing = []

    def walk(parser, verb):
        for a in parser._actions:
            if isinstance(a, argparse._SubParsersAction):
                for name, sub in a.choices.items():
                    walk(sub, f"{verb} {name}".strip())
            elif a.type in numeric:
                text = a.help or ""
                words = set(re.findall(r"[a-z^0-9]+", text.replace("px^2", " px^2 ")))
                if not ("default" in text or a.default is not None) or not words & set(UNITS):
                    missing.append(f"{verb} {a.option_strings[-1]}: {text}")
    walk(cli.build_parser(), "")
    assert not missing, missing
