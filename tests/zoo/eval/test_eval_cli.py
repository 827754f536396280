"""`zoo eval` end to end, in-process, and its messages for bad arguments."""

from __future__ import annotations

import json

import pytest

from zoo.cli import main
from zoo.eval.stats import load_stats


def eval_args(out, *extra):
    return ["eval", "--agent", "random", "--env", "crafter", "--episodes", "3",
            "--max-steps", "20", "--num-envs", "2", "--out", str(out), *extra]


def test_eval_writes_a_report(tmp_path, capsys):
    assert main(eval_args(tmp_path / "run", "--seed", "7")) == 0
    out = capsys.readouterr().out
    assert "Crafter Score" in out and "collect_wood" in out
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    assert report["env"] == "crafter" and report["agent"] == "random" and report["seed"] == 7
    assert report["episodes"] == 3 and report["episode_length"]["max"] <= 20
    _, _, lengths = load_stats(tmp_path / "run" / "stats.jsonl")
    assert len(lengths) == 3
    assert (tmp_path / "run" / "episode.gif").is_file()


def test_rerun_needs_overwrite_and_no_gif_skips_the_gif(tmp_path, capsys):
    out = tmp_path / "run"
    assert main(eval_args(out, "--no-gif")) == 0
    assert not (out / "episode.gif").exists()
    assert main(eval_args(out)) == 2
    assert "already holds report.json; pass --overwrite" in capsys.readouterr().err
    assert main(eval_args(out, "--overwrite", "--no-gif")) == 0


@pytest.mark.parametrize(
    "change, message",
    [
        (["--episodes", "0"], "argument --episodes: expected a positive integer, got 0"),
        (["--env", "minecraft"], "argument --env: invalid choice: 'minecraft'"),
        (["--agent", "alphago"], "argument --agent: invalid choice: 'alphago'"),
        (["--seed", "-1"], "argument --seed: expected an integer >= 0, got -1"),
    ],
)
def test_bad_arguments_are_rejected_by_the_parser(tmp_path, capsys, change, message):
    with pytest.raises(SystemExit) as exit_info:
        main(eval_args(tmp_path / "run", *change))
    assert exit_info.value.code == 2
    assert message in capsys.readouterr().err


def test_out_may_not_be_a_file(tmp_path, capsys):
    (tmp_path / "file").write_text("x")
    with pytest.raises(SystemExit) as stop:
        main(eval_args(tmp_path / "file"))
    assert stop.value.code == 2
    assert "argument --out: " in (err := capsys.readouterr().err)
    assert "file exists and is not a folder" in err


def test_ppo_needs_a_checkpoint(tmp_path, capsys):
    args = eval_args(tmp_path / "run")
    args[args.index("random")] = "ppo"
    assert main(args) == 2
    assert "needs --checkpoint" in capsys.readouterr().err


def test_missing_checkpoint_file(tmp_path, capsys):
    assert main(eval_args(tmp_path / "run", "--checkpoint", str(tmp_path / "nope.ckpt"))) == 2
    assert "nope.ckpt does not exist" in capsys.readouterr().err


def test_agent_is_required_without_a_checkpoint(tmp_path, capsys):
    args = eval_args(tmp_path / "run")
    del args[1:3]
    assert main(args) == 2
    assert "give --agent NAME (one of random" in capsys.readouterr().err


@pytest.mark.slow
def test_eval_in_craftax(tmp_path):
    assert main(["eval", "--agent", "random", "--env", "craftax", "--episodes", "4",
                 "--num-envs", "2", "--out", str(tmp_path)]) == 0
    report = json.loads((tmp_path / "report.json").read_text())
    assert report["env"] == "craftax" and report["episodes"] == 4


def test_temperature_is_only_for_sampling_policies(tmp_path, capsys):
    assert main(eval_args(tmp_path / "run", "--temperature", "0.5")) == 2
    assert "temperature applies to the cvpt, csteve1 and rl agents only, not 'random'" in capsys.readouterr().err
    assert main(eval_args(tmp_path / "run", "--temperature", "-1")) == 2
    assert "temperature must be >= 0" in capsys.readouterr().err


def test_wandb_logs_the_report_as_an_offline_run(tmp_path, capsys, monkeypatch):
    monkeypatch.setenv("WANDB_MODE", "offline")
    monkeypatch.setenv("WANDB_SILENT", "true")
    assert main(eval_args(tmp_path / "run", "--wandb")) == 0
    assert "W&B run in" in capsys.readouterr().out
    (run,) = (tmp_path / "run" / "wandb").glob("offline-run-*")
    assert list(run.glob("*.wandb"))  # the run's log, for `wandb sync`
    report = json.loads((tmp_path / "run" / "report.json").read_text())
    from zoo.eval.wandb_log import report_scalars

    scalars = report_scalars(report)
    assert scalars["eval/crafter_score"] == report["crafter_score"]["mean"]
    assert scalars["eval/success/collect_wood"] == report["success_rates"]["collect_wood"]


def test_task_reports_give_their_success_and_sub_tasks_to_wandb():
    from zoo.eval.wandb_log import report_scalars

    report = {"success_percent": 25.0, "subtasks": [
        {"instruction": "obtain coal", "completed_percent": 50.0}]}
    assert report_scalars(report) == {"eval/task_success": 25.0,
                                      "eval/subtask/1_obtain coal": 50.0}
