"""Write docs/cli.md, the per-verb reference of the ``invface`` command, from the CLI's own
parser: each verb's purpose, usage, and every option with its help text and default.

    python scripts/cli_docs.py [--check]

``--check`` exits 1 when docs/cli.md differs from what the parser gives (tests/test_docs.py
runs it), so the reference never drifts from the code.
"""
import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from invface.cli import build_parser  # noqa: E402

OUT = ROOT / "docs" / "cli.md"


def verbs(parser, prefix=()):
    """(verb words, its parser, its one-line help) for every verb, in the parser's order."""
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            helps = {a.dest: a.help for a in action._choices_actions}
            for name, sub in action.choices.items():
                if any(isinstance(a, argparse._SubParsersAction) for a in sub._actions):
                    yield from verbs(sub, prefix + (name,))
                else:
                    yield prefix + (name,), sub, helps.get(name, "")


def cell(text):
    return " ".join(str(text).split()).replace("|", "\\|")


def option_rows(sub):
    rows = []
    for a in sub._actions:
        if isinstance(a, (argparse._HelpAction, argparse._SubParsersAction)):
            continue
        name = ", ".join(f"`{s}`" for s in a.option_strings) if a.option_strings else f"`{a.dest}` (positional)"
        if a.option_strings and a.nargs != 0 and a.metavar is not None:
            name += f" {a.metavar}"
        default = "" if a.default in (None, argparse.SUPPRESS, False) or a.nargs == 0 else f"`{a.default}`"
        helptext = (a.help or "").replace("%(default)s", str(a.default))
        rows.append(f"| {name} | {cell(helptext)} | {default} |")
    return rows


def render():
    parser = build_parser()
    lines = ["# The `invface` command", "",
             "Every verb, its options, their meaning and their defaults, as `invface VERB --help` gives them",
             "(this page is written from the parser by `scripts/cli_docs.py`; `tests/test_docs.py` checks that",
             "it is current). Units are stated in each option's text. Exit codes: 0 done, 2 bad input or",
             "option (one line naming it and the fix), 1 an internal error (`--debug` shows the traceback).", ""]
    lines += ["## `invface` (before the verb)", "", "```", " ".join(parser.format_usage().split()).replace("usage: ", ""),
              "```", "", "| option | meaning | default |", "|---|---|---|",
              *[r for r in option_rows(parser) if "(positional)" not in r], ""]
    for words, sub, helptext in verbs(parser):
        verb = " ".join(words)
        usage = " ".join(sub.format_usage().split())
        lines += [f"## `invface {verb}`", "", cell(helptext) or cell(sub.description or ""), "",
                  "```", usage.replace("usage: ", ""), "```", "",
                  "| option | meaning | default |", "|---|---|---|", *option_rows(sub), ""]
        if sub.epilog:
            lines += ["```sh", *[line.strip() for line in sub.epilog.splitlines()[1:]], "```", ""]
    return "\n".join(lines)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--check", action="store_true", help="exit 1 when docs/cli.md is not current")
    args = ap.parse_args()
    text = render()
    if args.check:
        current = OUT.read_text() if OUT.is_file() else ""
        if current != text:
            print(f"{OUT} is not current: run python scripts/cli_docs.py", file=sys.stderr)
            return 1
        return 0
    OUT.parent.mkdir(exist_ok=True)
    OUT.write_text(text)
    print(f"wrote {OUT}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
