"""The same seeds give the same shards, reports and scores: one generation, one evaluation and
one instruction matrix, pinned to what the code gave before agents were described by
``AgentSpec`` (commit 7ff2eab), so a refactor of how agents are built cannot change them."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from zoo.cli import main
from zoo.files import sha256_file

SHARD_SHA256 = "fa89fa2e6eb96b31ee17f60168259cbe33c47dfc37838079f977047477351866"
CRAFTER_SCORE = 3.8492659586322953
MATRIX_ROWS = {
    "obtain_sapling": [
        {"seed": 3060664978, "unlock_step": {"collect_sapling": 19}},
        {"seed": 1175807978, "unlock_step": {"collect_sapling": 9}},
    ],
    "no_instruction": [
        {"seed": 3060664978, "unlock_step": {"collect_wood": 6, "place_table": 22,
                                             "make_wood_sword": 23, "defeat_zombie": 29,
                                             "defeat_skeleton": 40}},
        {"seed": 1175807978, "unlock_step": {"collect_wood": 7, "place_table": 30,
                                             "make_wood_sword": 40}},
    ],
}


def test_a_generation_writes_the_pinned_shard(tmp_path: Path) -> None:
    out = tmp_path / "gen"
    assert main(["data", "generate", "--expert", "scripted", "--env", "crafter", "--episodes",
                 "2", "--max-steps", "40", "--seed", "11", "--episodes-per-shard", "2",
                 "--out", str(out), "--workers", "1", "--no-progress"]) == 0
    assert sha256_file(out / "crafterplay-000000.tar") == SHARD_SHA256


def test_an_evaluation_reports_the_pinned_score(tmp_path: Path) -> None:
    out = tmp_path / "eval"
    assert main(["eval", "--agent", "scripted", "--env", "crafter", "--episodes", "2",
                 "--num-envs", "2", "--max-steps", "80", "--seed", "4", "--out", str(out),
                 "--no-gif"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["crafter_score"]["mean"] == pytest.approx(CRAFTER_SCORE, abs=1e-12)
    assert report["episode_length"]["mean"] == 80.0


def test_an_instruction_matrix_plays_the_pinned_rows(tmp_path: Path) -> None:
    out = tmp_path / "matrix"
    assert main(["tables", "instructions", "--agent", "scripted", "--env", "crafter", "--episodes",
                 "2", "--num-envs", "2", "--max-steps", "40", "--instructions", "obtain sapling",
                 "--seed", "6", "--out", str(out)]) == 0
    for row, episodes in MATRIX_ROWS.items():
        assert json.loads((out / "crafter" / f"{row}.json").read_text())["episodes"] == episodes
