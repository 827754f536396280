"""The shipped C-Steve-1 names its goal models, so each command that tells it an instruction
works with ``--checkpoint`` alone (issue 50 §2): eval on a task, play, the instruction matrix."""

from __future__ import annotations

import json
from pathlib import Path

from zoo.cli import main

STEVE = str(Path(__file__).resolve().parents[1] / "weights" / "csteve1_cpu")


def test_eval_on_a_task_with_an_instruction(tmp_path: Path) -> None:
    out = tmp_path / "eval"
    assert main(["eval", "--checkpoint", STEVE, "--task", "make_wood_pickaxe", "--instruction",
                 "craft wood pickaxe", "--env", "crafter", "--episodes", "2", "--num-envs", "2",
                 "--max-steps", "20", "--out", str(out), "--no-gif"]) == 0
    report = json.loads((out / "report.json").read_text())
    assert report["episodes"] == 2
    assert report["instruction_mode"] == "instruction 'craft wood pickaxe'"
    assert report["agent_spec"]["kind"] == "csteve1"


def test_play(tmp_path: Path) -> None:
    out = tmp_path / "play"
    assert main(["play", "--checkpoint", STEVE, "--instruction", "obtain drink", "--env",
                 "crafter", "--max-steps", "10", "--out", str(out)]) == 0
    assert (out / "play.gif").is_file() and (out / "play.json").is_file()


def test_the_instruction_matrix(tmp_path: Path) -> None:
    out = tmp_path / "matrix"
    assert main(["tables", "instructions", "--checkpoint", STEVE, "--env", "crafter",
                 "--episodes", "2", "--num-envs", "2", "--max-steps", "10", "--instructions",
                 "obtain drink", "--out", str(out)]) == 0
    agent = json.loads((out / "report.json").read_text())["setting"]["agent"]
    assert agent["kind"] == "csteve1" and agent["cfg_scale"] == 1.0
