"""bench/mutations.py: the fast mutations are all killed by the tests they name, the work tree
is never touched, and a mutant file that no longer matches the source is refused by name."""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
_SPEC = importlib.util.spec_from_file_location("mutations", ROOT / "bench" / "mutations.py")
mutations = importlib.util.module_from_spec(_SPEC)
sys.modules["mutations"] = mutations  # dataclasses look their module up by name
_SPEC.loader.exec_module(mutations)


def test_the_fast_mutations_are_killed_by_their_tests() -> None:
    """The default suite's share of the mutation table (bench/results/mutations.json has all):
    each fast mutation fails one of the tests it names, and the sources are unchanged after.
    No baseline run: this suite runs those tests unmutated itself."""
    chosen = [m for m in mutations.load(sorted(mutations.MUTANTS.glob("*.toml"))) if m.fast]
    assert len(chosen) >= 8
    before = {m.file: (ROOT / m.file).read_text() for m in chosen}
    outcomes = mutations.run(chosen, jobs=2, timeout=120, check_baseline=False)
    table = {o.name: (o.status, o.detail) for o in outcomes}
    assert all(status == "killed" for status, _ in table.values()), table
    for o, m in zip(outcomes, chosen):  # a named test (or a case of it) failed, not another
        assert o.killed_by and all(k.startswith(m.tests) for k in o.killed_by), o
    assert {f: (ROOT / f).read_text() for f in before} == before


def _mutant_file(tmp_path: Path, old: str) -> Path:
    path = tmp_path / "m.toml"
    path.write_text(
        '[[mutation]]\nname = "n"\nfile = "zoo/eval/stats.py"\n'
        f'old = "{old}"\nnew = "x"\ntests = ["tests/zoo/eval"]\nwhy = "w"\n'
    )
    return path


def test_a_mutation_whose_text_is_gone_is_refused(tmp_path: Path) -> None:
    (mutation,) = mutations.load([_mutant_file(tmp_path, "text no source holds")])
    tree = tmp_path / "tree"
    (tree / "zoo" / "eval").mkdir(parents=True)
    (tree / "zoo" / "eval" / "stats.py").write_text("a = 1\n")
    with pytest.raises(ValueError, match=r"mutation n: zoo/eval/stats.py holds its `old` text 0"):
        mutations.apply(tree, mutation)


def test_a_mutant_without_its_tests_names_the_file(tmp_path: Path) -> None:
    path = tmp_path / "bad.toml"
    path.write_text('[[mutation]]\nname = "n"\nfile = "f"\nold = "a"\nnew = "b"\nwhy = "w"\n')
    with pytest.raises(ValueError, match=r"bad.toml: mutation 0 lacks \['tests'\]"):
        mutations.load([path])


def test_every_mutant_still_matches_the_source() -> None:
    """Each mutant's ``old`` text is in its file exactly once, so a refactor that moves the code
    shows up here, not as a stale row the next time someone runs the whole table."""
    gone = {}
    for m in mutations.load(sorted(mutations.MUTANTS.glob("*.toml"))):
        path = ROOT / m.file
        found = path.read_text().count(m.old) if path.exists() else 0
        if found != 1:
            gone[m.name] = (m.file, found)
    assert not gone, f"mutants whose source changed (update bench/mutants): {gone}"
