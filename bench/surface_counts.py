"""How much surface the package has: what issue 50 counts before and after (flag declarations,
copies of the guidance default, the generation loop's lines, package lines).

  .venv/bin/python bench/surface_counts.py [--root CHECKOUT ...] [--out bench/results/surface.json]

Each ``--root`` is a checkout (a ``git worktree`` of an older commit, say; default this one),
so before and after come from one script; the JSON maps each checkout's commit to its counts.
"""

from __future__ import annotations

import argparse
import ast
import json
import re
import subprocess
from collections import Counter
from pathlib import Path

PACKAGES = ("zoo", "lit_models", "datamodules")
FLAG = re.compile(r"""add_argument\(\s*["'](--[a-z0-9][a-z0-9-]*)["']""")
GUIDANCE_DEFAULT = re.compile(r"""(cfg_scale\W[^\n]{0,40}|PAPER_CFG_SCALE\s*=\s*)\b1\.5\b""")


def sources(root: Path) -> dict[Path, str]:
    return {p: p.read_text() for top in PACKAGES for p in sorted((root / top).rglob("*.py"))}


def function_lines(path: Path, qualname: str) -> int:
    """Lines of ``Class.method`` (or a function) in ``path``; 0 if it is not there."""
    tree = ast.parse(path.read_text())
    owner, _, name = qualname.rpartition(".")
    for node in ast.walk(tree):
        if isinstance(node, ast.ClassDef) and node.name == owner:
            for item in node.body:
                if isinstance(item, ast.FunctionDef) and item.name == name:
                    return item.end_lineno - item.lineno + 1
    return 0


def count(root: Path) -> dict:
    files = sources(root)
    flags = Counter(m for text in files.values() for m in FLAG.findall(text))
    guidance = [f"{p.relative_to(root)}:{text[:m.start()].count(chr(10)) + 1}"
                for p, text in files.items() for m in GUIDANCE_DEFAULT.finditer(text)]
    commit = subprocess.run(["git", "-C", str(root), "rev-parse", "--short", "HEAD"],
                            capture_output=True, text=True).stdout.strip()
    return {
        "commit": commit,
        "flag_declarations": sum(flags.values()),
        "distinct_flags": len(flags),
        "most_declared": dict(flags.most_common(8)),
        "guidance_default_copies": guidance,
        "generation_loop_lines": function_lines(root / "zoo/data/shard_generator.py",
                                                "ShardGenerator.run"),
        "package_lines": sum(text.count("\n") for text in files.values()),
    }


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--root", type=Path, nargs="+",
                        default=[Path(__file__).resolve().parents[1]])
    parser.add_argument("--out", type=Path, help="also write the counts here (JSON)")
    args = parser.parse_args()
    counts = {c["commit"]: c for c in (count(root.resolve()) for root in args.root)}
    print(json.dumps(counts, indent=2))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.write_text(json.dumps(counts, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
