"""Mutation testing: does the suite fail when the code that decides results is broken?

Each mutation in ``bench/mutants/*.toml`` names a file, an exact text ``old`` in it (found
exactly once) and its replacement ``new``, and the tests that should fail on it. The runner
copies the tracked tree to a temp folder (the work tree is never touched), applies one mutation
at a time there, runs its tests with the copy first on ``PYTHONPATH`` and records the outcome:

- ``killed``: the tests failed (pytest exit 1); ``killed_by`` lists the failing tests;
- ``survived``: they passed, so the suite cannot see this bug;
- ``error``: pytest could not run them (exit 2-5: a bad node id, no tests, a crash);
- ``stale``: (only with ``--skip-stale``) the source no longer holds ``old``.

``--root DIR --whole-files`` replays the table on another checkout (e.g. a ``git worktree`` of
an older commit) with whole test files instead of node ids, to show what its suite caught.

Before the mutations it runs the same tests on the unmutated copy (``--no-baseline`` skips
this): a test that fails on main would "kill" every mutation and mean nothing.

    python bench/mutations.py                    # every mutation, table to bench/results/mutations.json
    python bench/mutations.py --fast             # those marked fast = true (the default suite runs these)
    python bench/mutations.py bench/mutants/gym.toml --only gym_next_step_keeps_final_reward

Exit status 0 when every mutation run was killed.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
import tomllib
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from queue import Queue

ROOT = Path(__file__).resolve().parents[1]
MUTANTS = ROOT / "bench" / "mutants"
RESULTS = ROOT / "bench" / "results" / "mutations.json"
_FAILED = re.compile(r"^(?:FAILED|ERROR) (\S+)", re.MULTILINE)


@dataclass(frozen=True)
class Mutation:
    """One source edit and the tests that must fail on it."""

    name: str
    file: str
    old: str
    new: str
    tests: tuple[str, ...]
    why: str
    fast: bool = False


@dataclass
class Outcome:
    name: str
    file: str
    why: str
    tests: list[str]
    status: str  # killed | survived | error
    killed_by: list[str] = field(default_factory=list)
    seconds: float = 0.0
    detail: str = ""


def load(paths: list[Path]) -> list[Mutation]:
    """The mutations of ``paths``; a missing key or a duplicate name names its file."""
    mutations: list[Mutation] = []
    for path in paths:
        for i, entry in enumerate(tomllib.loads(path.read_text())["mutation"]):
            missing = {"name", "file", "old", "new", "tests", "why"} - set(entry)
            if missing:
                raise ValueError(f"{path}: mutation {i} lacks {sorted(missing)}")
            mutations.append(Mutation(**{**entry, "tests": tuple(entry["tests"])}))
    names = [m.name for m in mutations]
    duplicated = sorted({n for n in names if names.count(n) > 1})
    if duplicated:
        raise ValueError(f"mutation names used twice: {duplicated}")
    return mutations


def apply(tree: Path, mutation: Mutation) -> str:
    """Write the mutated file into ``tree``; return the original text (to restore)."""
    path = tree / mutation.file
    text = path.read_text()
    found = text.count(mutation.old)
    if found != 1:
        raise ValueError(
            f"mutation {mutation.name}: {mutation.file} holds its `old` text {found} times,"
            " expected exactly once (the source changed: update bench/mutants)"
        )
    path.write_text(text.replace(mutation.old, mutation.new))
    return text


def copy_tree(dest: Path, root: Path = ROOT) -> Path:
    """The files git tracks or would track in ``root`` (no .venv, no data) under ``dest``."""
    listed = subprocess.run(
        ["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=root, check=True,
        capture_output=True,
    ).stdout.decode().split("\0")
    for rel in filter(None, listed):
        src = root / rel
        if src.is_file():
            (dest / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(src, dest / rel)
    return dest


def run_tests(tree: Path, tests: tuple[str, ...], timeout: float,
              marks: str = "") -> tuple[int, str]:
    """pytest on ``tests`` inside ``tree``, with the copy's packages imported first; ``marks``
    selects (default "": every named test, ``slow`` ones included)."""
    env = {**os.environ, "PYTHONPATH": str(tree), "PYTHONDONTWRITEBYTECODE": "1"}
    cmd = [sys.executable, "-m", "pytest", "-x", "-q", "-rfE", "-p", "no:cacheprovider",
           "-m", marks, *tests]
    try:
        done = subprocess.run(cmd, cwd=tree, env=env, capture_output=True, text=True,
                              timeout=timeout)
    except subprocess.TimeoutExpired:
        return -1, f"timed out after {timeout:.0f} s"
    return done.returncode, done.stdout + done.stderr


def mutate_one(tree: Path, mutation: Mutation, timeout: float, marks: str = "") -> Outcome:
    if not mutation.tests:  # an older checkout without the test files
        return Outcome(mutation.name, mutation.file, mutation.why, [], "survived",
                       detail="no test file of this checkout is named")
    start = time.perf_counter()
    original = apply(tree, mutation)
    try:
        rc, output = run_tests(tree, mutation.tests, timeout, marks)
    finally:
        (tree / mutation.file).write_text(original)
    status = {0: "survived", 1: "killed"}.get(rc, "error")
    return Outcome(
        mutation.name, mutation.file, mutation.why, list(mutation.tests), status,
        killed_by=_FAILED.findall(output) if status == "killed" else [],
        seconds=round(time.perf_counter() - start, 1),
        detail="" if status == "killed" else output[-1500:],
    )


def baseline(tree: Path, mutations: list[Mutation], timeout: float, marks: str = "") -> None:
    """Refuse to run when the tests fail on the unmutated tree."""
    tests = tuple(dict.fromkeys(t for m in mutations for t in m.tests))
    if not tests:
        return
    rc, output = run_tests(tree, tests, timeout * 4, marks)
    if rc != 0:
        raise RuntimeError(f"the mutations' tests fail on the unmutated tree (exit {rc}):\n"
                           f"{output[-3000:]}")


def _stale(tree: Path, mutations: list[Mutation], skip: bool) -> list[Mutation]:
    """Those whose ``old`` text ``tree`` lacks; raise on the first unless ``skip``."""
    stale = []
    for m in mutations:
        path = tree / m.file
        try:
            original = apply(tree, m)
        except (ValueError, FileNotFoundError):
            if not skip:
                raise
            stale.append(m)
            continue
        path.write_text(original)
    return stale


def run(mutations: list[Mutation], jobs: int = 2, timeout: float = 600.0,
        check_baseline: bool = True, root: Path = ROOT, skip_stale: bool = False,
        marks: str = "") -> list[Outcome]:
    """Each mutation in its own run, ``jobs`` at a time, each worker in its own copy of
    ``root``; ``marks`` as in ``run_tests``."""
    with tempfile.TemporaryDirectory(prefix="zoo-mutations-") as tmp:
        trees: Queue[Path] = Queue()
        first = copy_tree(Path(tmp) / "0", root)
        stale = _stale(first, mutations, skip_stale)  # before any test runs
        live = [m for m in mutations if m not in stale]
        for i in range(1, max(1, min(jobs, len(live)))):
            trees.put(Path(shutil.copytree(first, Path(tmp) / str(i))))
        trees.put(first)
        if check_baseline and live:
            baseline(first, live, timeout, marks)

        def work(mutation: Mutation) -> Outcome:
            tree = trees.get()
            try:
                return mutate_one(tree, mutation, timeout, marks)
            finally:
                trees.put(tree)

        with ThreadPoolExecutor(max_workers=trees.qsize()) as pool:
            done = dict(zip(live, pool.map(work, live)))
    return [done.get(m) or Outcome(m.name, m.file, m.why, list(m.tests), "stale",
                                   detail="the source lacks the mutation's `old` text")
            for m in mutations]


def report(outcomes: list[Outcome]) -> dict:
    counts = {s: sum(o.status == s for o in outcomes)
              for s in ("killed", "survived", "error", "stale")}
    return {**counts, "total": len(outcomes), "mutations": [asdict(o) for o in outcomes]}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("files", nargs="*", type=Path, help="mutant TOML files (default: all)")
    parser.add_argument("--only", nargs="+", help="run only these mutation names")
    parser.add_argument("--fast", action="store_true", help="only mutations marked fast")
    parser.add_argument("--jobs", type=int, default=2, help="mutations run at once (default 2)")
    parser.add_argument("--timeout", type=float, default=600.0, help="seconds per mutation")
    parser.add_argument("--no-baseline", action="store_true",
                        help="skip running the tests on the unmutated tree first")
    parser.add_argument("--out", type=Path, default=RESULTS, help="JSON table to write")
    parser.add_argument("--root", type=Path, default=ROOT,
                        help="checkout to mutate (default: this one)")
    parser.add_argument("--whole-files", action="store_true",
                        help="run the named tests' whole files, slow tests left out (for an older --root)")
    parser.add_argument("--skip-stale", action="store_true",
                        help="record mutations whose text the source lacks as stale")
    args = parser.parse_args(argv)
    mutations = load(args.files or sorted(MUTANTS.glob("*.toml")))
    if args.only:
        unknown = set(args.only) - {m.name for m in mutations}
        if unknown:
            raise SystemExit(f"unknown mutation names: {sorted(unknown)}")
        mutations = [m for m in mutations if m.name in args.only]
    if args.fast:
        mutations = [m for m in mutations if m.fast]
    if not mutations:
        raise SystemExit("no mutations selected")
    root = args.root.resolve()
    if args.whole_files:  # the files that exist there, as its default suite runs them
        mutations = [replace(m, tests=tuple(dict.fromkeys(
            f for f in (t.split("::")[0] for t in m.tests) if (root / f).exists())))
            for m in mutations]
    outcomes = run(mutations, args.jobs, args.timeout, not args.no_baseline, root,
                   args.skip_stale, "not slow" if args.whole_files else "")
    table = report(outcomes)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(table, indent=1) + "\n")
    for o in outcomes:
        print(f"{o.status:9s} {o.name:45s} {o.seconds:6.1f}s  {', '.join(o.killed_by)}")
        if o.status == "error":
            print(o.detail)
    print(f"{table['killed']} of {table['total']} killed -> {args.out}")
    return 0 if table["killed"] == table["total"] else 1


if __name__ == "__main__":
    sys.exit(main())
