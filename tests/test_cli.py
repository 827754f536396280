"""The `zoo` entry point: help that explains itself, clear errors, and the README's demo."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from zoo.cli import main


def test_help_lists_every_command():
    out = subprocess.run(
        [sys.executable, "-m", "zoo.cli", "--help"], capture_output=True, text=True, check=True
    ).stdout
    for command in ("data", "eval", "captions", "expert", "export", "demo", "pipeline", "fit",
                    "test"):
        assert f"    {command} " in out or f"    {command}\n" in out, command


def test_help_does_not_load_torch():
    code = "import sys, zoo.cli; zoo.cli.build_parser(); print('torch' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_bad_arguments_name_the_option(capsys):
    with pytest.raises(SystemExit) as err:
        main(["eval", "--agent", "scripted", "--env", "minecraft"])
    assert err.value.code == 2
    assert "--env: invalid choice: 'minecraft'" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["demo", "--episodes", "0"])
    assert "--episodes: expected a positive integer, got 0" in capsys.readouterr().err
    assert main([]) == 0  # a bare `zoo` prints the help


def test_demo_generates_data_and_a_report(tmp_path, capsys):
    out = tmp_path / "demo"
    argv = ["demo", "--env", "crafter", "--episodes", "2", "--max-steps", "40", "--out", str(out)]
    assert main(argv) == 0
    printed = capsys.readouterr().out
    assert "$ zoo data generate" in printed and "$ zoo eval" in printed
    manifest = json.loads((out / "crafterplay" / "manifest.json").read_text())
    assert sum(shard["episodes"] for shard in manifest["shards"]) == 2
    report = json.loads((out / "eval" / "report.json").read_text())
    assert report["episodes"] == 2 and len(report["success_rates"]) == 22
    assert (out / "eval" / "episode.gif").stat().st_size > 0
    (out / "file").write_text("")
    assert main(["demo", "--out", str(out / "file")]) == 2


def test_zoo_package_never_imports_lightning():
    code = (
        "import pkgutil, importlib, sys, zoo\n"
        "for m in pkgutil.walk_packages(zoo.__path__, 'zoo.'):\n"
        "    importlib.import_module(m.name)\n"
        "print(sorted(k for k in sys.modules if k.split('.')[0] in ('lightning', 'pytorch_lightning')))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
