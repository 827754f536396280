"""`zoo eval --task`: reports, instruction modes, and messages for bad combinations."""

from __future__ import annotations

import json

import pytest

from zoo.cli import main


def task_args(out, *extra, agent="scripted", task="T2"):
    return ["eval", "--task", task, "--agent", agent, "--env", "crafter", "--episodes", "2",
            "--num-envs", "2", "--no-gif", "--out", str(out), *extra]


def test_scripted_expert_follows_the_sub_tasks_by_default(tmp_path, capsys):
    assert main(task_args(tmp_path / "run")) == 0
    out = capsys.readouterr().out
    assert "| **task** | 100.0 |" in out and "| 1. place plant on grass |" in out
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    assert report["task"] == "T2" and report["instruction_mode"] == "sub-task instructions"
    assert report["max_steps"] == 1000 and len(report["episode_results"]) == 2
    assert (tmp_path / "run" / "report.md").is_file()


def test_chain_and_single_instruction(tmp_path, capsys):
    assert main(task_args(tmp_path / "chain", "--chain", task="T4")) == 0
    report = json.loads((tmp_path / "chain" / "report.json").read_text())
    assert report["instruction_mode"] == "chained instructions" and report["successes"] >= 1
    assert report["chain_config"]["coal_via_stone"] is True  # the report says which planner
    assert main(task_args(tmp_path / "direct", "--chain", "--chain-coal-direct", task="T4")) == 0
    report = json.loads((tmp_path / "direct" / "report.json").read_text())
    assert report["chain_config"]["coal_via_stone"] is False
    args = task_args(tmp_path / "one", "--instruction", "obtain sapling", task="collect_sapling")
    assert main(args) == 0
    report = json.loads((tmp_path / "one" / "report.json").read_text())
    assert report["instruction_mode"] == "instruction 'obtain sapling'"
    assert report["success_percent"] == 100.0


def test_random_agent_plays_a_task_without_instructions(tmp_path):
    args = task_args(tmp_path / "run", "--max-steps", "5", agent="random")
    assert main(args) == 0
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    assert report["instruction_mode"] == "no instruction" and report["max_steps"] == 5


@pytest.mark.parametrize(
    "args, message",
    [
        (
            ["--instruction", "fly to the moon"],
            "--instruction: the scripted expert cannot follow ['fly to the moon']; known",
        ),
        (["--instruction", "obtain wood", "--chain"], "give --instruction or --chain, not both"),
        (["--chain-coal-direct"], "--chain-coal-direct changes the --chain planner; give --chain"),
    ],
)
def test_bad_instruction_arguments(tmp_path, capsys, args, message):
    assert main(task_args(tmp_path / "run", *args)) == 2
    assert message in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_instructions_need_a_task_and_an_instructable_agent(tmp_path, capsys):
    plain = ["eval", "--agent", "scripted", "--env", "crafter", "--out", str(tmp_path / "a")]
    assert main([*plain, "--chain"]) == 2
    assert "--chain needs --task NAME (one of T1, T2" in capsys.readouterr().err
    assert main(task_args(tmp_path / "b", "--chain", agent="random")) == 2
    assert "agent random does not follow instructions" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(task_args(tmp_path / "c", task="T9"))
    assert "argument --task: invalid choice: 'T9'" in capsys.readouterr().err
