"""Every `zoo` command in a shell block of README.md or docs/ (all of it, docs/results/ too)
parses, so the docs cannot drift from the CLI (a review once found copy-paste commands that
failed as written); and every relative link in those files reaches a file, and a heading where
it names one, so moving a page cannot leave dead links behind.

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
from urllib.parse import unquote

import pytest

from zoo.cli import TRAIN_VERBS, build_parser

ROOT = Path(__file__).resolve().parents[1]
DOCS = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
FENCE = re.compile(r"^```(\S*)[^\n]*\n(.*?)^```[ \t]*$", re.DOTALL | re.MULTILINE)
SHELL_LANGUAGES = ("", "bash", "sh", "shell", "console")
# values for one-letter/upper-case placeholders that follow a flag in the docs
PLACEHOLDERS = {"E": "craftax", "G": "craftax", "GAME": "craftax", "S": "0", "N": "1"}
# argparse types that check a path exist; the docs' paths are made by earlier commands
MISSING_PATH = re.compile(
    r"error: argument \S+: .*(is not a folder|does not exist|no such)", re.IGNORECASE
)


SHELL_ARITHMETIC = re.compile(r"\$\(\(([0-9a-zA-Z_+*/ -]+)\)\)")


def _arithmetic(match: re.Match) -> str:
    """A shell ``$((10*k+10))`` as the value it takes with every variable at 1 (a SLURM
    array task), so the flag's own check sees a number."""
    return str(eval(re.sub(r"[A-Za-z_]\w*", "1", match.group(1))))  # digits and + - * / only


def doc_commands() -> list[tuple[str, list[str]]]:
    """(file:line, argv after `zoo`) for each `zoo` command in the docs' shell blocks."""
    found = []
    for path in DOCS:
        text = path.read_text()
        for block in FENCE.finditer(text):  # fences pair in order: a python block is skipped
            if block.group(1) not in SHELL_LANGUAGES:
                continue
            first_line = text.count("\n", 0, block.start(2)) + 1
            lines = block.group(2).split("\n")
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
                argv = shlex.split(SHELL_ARITHMETIC.sub(_arithmetic, match.group(1)), comments=True)
                argv = [PLACEHOLDERS.get(a, a) if j and argv[j - 1].startswith("--") else a
                        for j, a in enumerate(argv)]
                found.append((f"{path.relative_to(ROOT)}:{first_line + start}", argv))
    return found


COMMANDS = doc_commands()


def test_the_docs_have_commands() -> None:
    # README + docs held 67 when this test was written, 70 once docs/results.md became
    # docs/results/*.md (its three `zoo eval` table commands got a shell block)
    assert len(COMMANDS) >= 67
    assert any(where.startswith("docs/results/") for where, _ in COMMANDS)


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


# --- relative links -------------------------------------------------------------------------

INLINE_LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(\s*<?([^)\s>]+)>?(?:\s+\"[^\"]*\")?\s*\)")
REFERENCE_LINK = re.compile(r"^ {0,3}\[[^\]]+\]:\s*<?(\S+?)>?(?:\s|$)", re.MULTILINE)
FENCE = re.compile(r"^(```|~~~).*?^\1[^\n]*$", re.DOTALL | re.MULTILINE)
CODE_SPAN = re.compile(r"(`+)(?:(?!\1).)+?\1", re.DOTALL)
HEADING = re.compile(r"^ {0,3}#{1,6}[ \t]+(.*?)[ \t#]*$", re.MULTILINE)
EXTERNAL = re.compile(r"^(?:[a-z][a-z0-9+.-]*:|//)", re.IGNORECASE)


def _blank(match: re.Match) -> str:
    """The match with every character but newlines blanked, so line numbers stay right."""
    return re.sub(r"[^\n]", " ", match.group(0))


def _prose(text: str) -> str:
    """The Markdown without fenced code blocks and code spans, where links are not links."""
    return CODE_SPAN.sub(_blank, FENCE.sub(_blank, text))


def github_anchors(text: str) -> set[str]:
    """The anchors GitHub gives a Markdown file's headings (github-slugger): the heading's text
    without its Markdown, lower-cased, punctuation dropped, spaces to hyphens, repeats numbered."""
    anchors: set[str] = set()
    seen: dict[str, int] = {}
    for raw in HEADING.findall(FENCE.sub(_blank, text)):
        title = re.sub(r"!?\[([^\]]*)\]\([^)]*\)", r"\1", raw)  # a link counts by its text
        title = re.sub(r"<[^>]+>", "", title)
        slug = re.sub(r"[^\w\- ]", "", title.strip().lower()).replace(" ", "-")
        count = seen.get(slug, 0)
        seen[slug] = count + 1
        anchors.add(slug if count == 0 else f"{slug}-{count}")
    anchors.update(re.findall(r"<a\s+(?:name|id)=\"([^\"]+)\"", text))
    return anchors


def doc_links() -> list[tuple[str, Path, str]]:
    """(file:line, target file, anchor or "") for each relative link in the docs."""
    found = []
    for path in DOCS:
        text = path.read_text()
        prose = _prose(text)
        matches = [*INLINE_LINK.finditer(prose), *REFERENCE_LINK.finditer(prose)]
        for match in sorted(matches, key=lambda m: m.start()):
            target = match.group(1)
            if EXTERNAL.match(target):
                continue
            file_part, _, anchor = target.partition("#")
            resolved = (path.parent / unquote(file_part)).resolve() if file_part else path
            line = text.count("\n", 0, match.start()) + 1
            found.append((f"{path.relative_to(ROOT)}:{line}", resolved, unquote(anchor)))
    return found


LINKS = doc_links()


def test_the_docs_have_links() -> None:
    assert len(LINKS) >= 50
    assert any(where.startswith("docs/results/") for where, _, _ in LINKS)


def test_doc_links_reach_their_target() -> None:
    dead = [f"{where} -> {target.relative_to(ROOT) if target.is_relative_to(ROOT) else target}"
            for where, target, _ in LINKS if not target.exists()]
    assert not dead, "dead relative links:\n" + "\n".join(dead)


def test_doc_link_anchors_name_a_heading() -> None:
    anchors: dict[Path, set[str]] = {}
    dead = []
    for where, target, anchor in LINKS:
        if not anchor or target.suffix != ".md" or not target.is_file():
            continue
        if target not in anchors:
            anchors[target] = github_anchors(target.read_text())
        if anchor.lower() not in anchors[target]:
            dead.append(f"{where} -> {target.relative_to(ROOT)}#{anchor}")
    assert not dead, "links to headings that do not exist:\n" + "\n".join(dead)
