"""Every `zoo` command in a shell block of README.md or docs/ parses, so the docs cannot drift
from the CLI (a review once found copy-paste commands that failed as written).

argparse commands are parsed, not run; training verbs print their config, which makes
LightningCLI check every key, type and class path of the YAML plus the flags. Placeholders that
stand for a choice (`--env E`, `--seed_everything S`) get a valid value; paths stay as written,
since parsing never opens them.
"""

from __future__ import annotations

import contextlib
import io
import re
import shlex
from pathlib import Path

import pytest

from zoo.cli import TRAIN_VERBS, build_parser

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]
SHELL_BLOCK = re.compile(r"^```(?:bash|sh|console)?\n(.*?)^```", re.S | re.M)
# values for one-letter/upper-case placeholders that follow a flag in the docs
PLACEHOLDERS = {"E": "craftax", "G": "craftax", "GAME": "craftax", "S": "0", "N": "1"}
# argparse types that check a path exist; the docs' paths are made by earlier commands
MISSING_PATH = re.compile(r"error: argument \S+: .*(is not a folder|does not exist|no such)", re.I)


def doc_commands() -> list[tuple[str, list[str]]]:
    """(file:line, argv after `zoo`) for each `zoo` command in the docs' shell blocks."""
    found = []
    for path in DOCS:
        text = path.read_text()
        for block in SHELL_BLOCK.finditer(text):
            first_line = text.count("\n", 0, block.start(1)) + 1
            lines = block.group(1).split("\n")
            i = 0
            while i < len(lines):
                start, command = i, lines[i]
                while command.rstrip().endswith("\\") and i + 1 < len(lines):
                    i += 1
                    command = command.rstrip()[:-1] + " " + lines[i]
                i += 1
                match = re.match(r"\s*(?:\$ )?(?:\w+=\S+ )*(?:\.venv/bin/)?zoo (.*)", command)
                if not match:
                    continue
                argv = shlex.split(match.group(1), comments=True)
                argv = [PLACEHOLDERS.get(a, a) if j and argv[j - 1].startswith("--") else a
                        for j, a in enumerate(argv)]
                found.append((f"{path.relative_to(ROOT)}:{first_line + start}", argv))
    return found


COMMANDS = doc_commands()


def test_the_docs_have_commands() -> None:
    assert len(COMMANDS) >= 60  # README + docs held 67 when this test was written


@pytest.mark.parametrize("argv", [c[1] for c in COMMANDS], ids=[c[0] for c in COMMANDS])
def test_doc_command_parses(argv: list[str], capsys: pytest.CaptureFixture) -> None:
    command = "zoo " + shlex.join(argv)
    if argv[0] in TRAIN_VERBS:
        from lit_models.cli import run_lightning_cli

        with pytest.raises(SystemExit) as exit_info, contextlib.redirect_stdout(io.StringIO()):
            run_lightning_cli([*argv, "--print_config"])
        assert exit_info.value.code in (0, None), f"{command}: {capsys.readouterr().err}"
        return
    try:
        args = build_parser().parse_args(argv)
    except SystemExit:
        err = capsys.readouterr().err
        if MISSING_PATH.search(err):
            return  # flags and choices parsed; the folder is one an earlier command makes
        pytest.fail(f"{command} does not parse: {err}")
    assert callable(getattr(args, "handler", None)), f"{command} names no command"
