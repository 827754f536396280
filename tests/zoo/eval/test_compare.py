"""`zoo compare`: reports side by side; bad folders are named."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from zoo.cli import main
from zoo.envs.constants import ACHIEVEMENT_NAMES


def _report(folder: Path, agent: str, score: float, wood: float) -> Path:
    folder.mkdir()
    rates = {name: 0.0 for name in ACHIEVEMENT_NAMES} | {"collect_wood": wood}
    report = {
        "episodes": 20, "chunks": 5, "agent": agent, "env": "craftax",
        "crafter_score": {"mean": score, "std": 1.25}, "normalized_return": {"mean": 10.0, "std": 0.5},
        "success_rates": rates,
    }
    (folder / "report.json").write_text(json.dumps(report))
    return folder


def test_table_has_a_column_per_report_and_a_row_per_achievement(tmp_path, capsys):
    a = _report(tmp_path / "a", "scripted", 94.04, 100.0)
    b = _report(tmp_path / "b", "cvpt", 12.5, 62.5)
    plot = tmp_path / "cmp.png"
    assert main(["compare", str(a), str(b), "--plot", str(plot)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "|  | scripted (craftax) | cvpt (craftax) |"
    assert "| Crafter Score (%) | 94.0 ± 1.2 | 12.5 ± 1.2 |" in lines
    assert "| collect wood | 100.0 | 62.5 |" in lines
    assert len([line for line in lines if line.startswith("|")]) == 2 + 3 + len(ACHIEVEMENT_NAMES)
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_labels_replace_the_default_names(tmp_path, capsys):
    a = _report(tmp_path / "a", "scripted", 50.0, 1.0)
    assert main(["compare", str(a), "--labels", "expert"]) == 0
    assert capsys.readouterr().out.startswith("|  | expert |")


@pytest.mark.parametrize(
    "content, message",
    [(None, "no report.json"), ("{", "not valid JSON"), ("{}", "missing ['crafter_score'")],
)
def test_bad_report_folder_is_named(tmp_path, capsys, content, message):
    folder = tmp_path / "run"
    folder.mkdir()
    if content is not None:
        (folder / "report.json").write_text(content)
    assert main(["compare", str(folder)]) == 2
    err = capsys.readouterr().err
    assert "zoo compare: error:" in err and str(folder) in err and message in err


def test_label_count_must_match(tmp_path, capsys):
    a = _report(tmp_path / "a", "scripted", 50.0, 1.0)
    assert main(["compare", str(a), "--labels", "x", "y"]) == 2
    assert "2 --labels for 1 reports" in capsys.readouterr().err
