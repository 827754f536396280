"""The PPO loop end to end on crafter (no JIT to wait for): logs, determinism, resume, plot."""

from __future__ import annotations

import csv

import pytest
import torch
import yaml

from zoo.cli import main
from zoo.rl.config import RLConfig
from zoo.rl.train import list_checkpoints, train_rl

TINY = RLConfig(
    agent="ppo_rnn", task="T2", env="crafter", num_envs=2, num_steps=4, total_env_steps=16,
    num_minibatches=1, update_epochs=2, hidden_size=16, input_downsample=4, anneal_lr=False,
    checkpoint_every=1, seed=3,
)


def _rows(run, name: str = "metrics.csv") -> list[dict]:
    with (run / name).open() as f:
        return list(csv.DictReader(f))


def _trainable(run) -> dict[str, torch.Tensor]:
    return torch.load(list_checkpoints(run)[-1], weights_only=True)["trainable"]


def test_a_run_logs_every_update_and_repeats_from_its_seed(tmp_path):
    last = train_rl(TINY, tmp_path / "a", progress=False)
    train_rl(TINY, tmp_path / "b", progress=False)
    assert last["env_steps"] == 16
    assert last["trainable_parameters"] == last["total_parameters"] > 0  # PPO-RNN trains all
    assert last["reference_parameters"] == 0
    rows = _rows(tmp_path / "a")
    assert [int(r["env_steps"]) for r in rows] == [8, 16]
    assert all(0 <= float(r["env_share"]) <= 1 for r in rows)
    assert yaml.safe_load((tmp_path / "a" / "config.yaml").read_text()) == TINY.to_dict()
    a, b = _trainable(tmp_path / "a"), _trainable(tmp_path / "b")
    assert a.keys() == b.keys()
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert [r["policy_loss"] for r in rows] == [r["policy_loss"] for r in _rows(tmp_path / "b")]


def test_episodes_csv_has_one_row_per_ended_episode(tmp_path, monkeypatch):
    import zoo.rl.envs as rl_envs

    make = rl_envs.make_task_env
    monkeypatch.setattr(  # 5-step episodes, so the 8 steps of each env end at least one
        rl_envs, "make_task_env", lambda *a, **k: make(*a, **{**k, "max_steps": 5})
    )
    train_rl(TINY, tmp_path, progress=False)
    rows, episodes = _rows(tmp_path), _rows(tmp_path, "episodes.csv")
    assert len(episodes) == int(rows[-1]["episodes"]) >= TINY.num_envs
    assert all(1 <= int(e["length"]) <= 5 for e in episodes)
    assert len({e["episode"] for e in episodes}) == len(episodes)  # each seed index once
    assert {int(e["update"]) for e in episodes} <= {1, 2}


def test_resume_continues_the_step_count_and_the_optimizer_state(tmp_path):
    run = tmp_path / "run"
    train_rl(TINY.replace(total_env_steps=8), run, progress=False)
    first = torch.load(list_checkpoints(run)[-1], weights_only=True)
    assert (first["update"], first["env_steps"]) == (1, 8)
    with pytest.raises(FileExistsError, match="--resume"):
        train_rl(TINY, run, progress=False)
    with pytest.raises(ValueError, match=r"\['lr'\] differ"):
        train_rl(TINY.replace(lr=1.0), run, resume=True, progress=False)
    with (run / "metrics.csv").open("a") as f:  # a row logged after the checkpoint, then killed
        f.write("2" + ",16" + "," * (len(_rows(run)[0]) - 2) + "\n")
    with (run / "episodes.csv").open("a") as f:
        f.write("2,999,1,2,7\n")
    train_rl(TINY, run, resume=True, progress=False)
    rows = _rows(run)
    assert [(int(r["update"]), int(r["env_steps"])) for r in rows] == [(1, 8), (2, 16)]
    assert "999" not in [r["episode"] for r in _rows(run, "episodes.csv")]
    last = torch.load(list_checkpoints(run)[-1], weights_only=True)
    assert (last["update"], last["env_steps"]) == (2, 16)
    steps_before = [s["step"] for s in first["optimizer"]["state"].values()]
    steps_after = [s["step"] for s in last["optimizer"]["state"].values()]
    assert all(int(b) == 2 and int(a) == 4 for b, a in zip(steps_before, steps_after))
    assert last["next_episode"] >= first["next_episode"] + TINY.num_envs  # fresh seeds


def test_zoo_rl_cli_errors_are_one_line_and_plot_draws_the_runs(tmp_path, capsys):
    config = tmp_path / "bad.yaml"
    values = TINY.to_dict()
    del values["gamma"]
    config.write_text(yaml.safe_dump(values))
    assert main(["rl", "train", "--config", str(config), "--out", str(tmp_path / "x")]) == 2
    assert "missing key(s) ['gamma']" in capsys.readouterr().err
    good = tmp_path / "good.yaml"
    good.write_text(yaml.safe_dump(TINY.to_dict()))
    for seed in (0, 1):
        out = tmp_path / f"seed{seed}"
        assert main(["rl", "train", "--config", str(good), "--out", str(out), "--seed",
                     str(seed), "--no-progress", "--total-env-steps", "16"]) == 0
    assert main(["rl", "train", "--config", str(good), "--out", str(tmp_path / "seed0")]) == 2
    assert "--resume" in capsys.readouterr().err
    assert len(_rows(tmp_path / "seed1")) == 2


def _fake_run(folder, agent: str, task: str, success: list[float]) -> None:
    """A run folder as the trainer writes it (config.yaml, metrics.csv), with set values."""
    from zoo.rl.train import COLUMNS

    folder.mkdir(parents=True)
    (folder / "config.yaml").write_text(yaml.safe_dump({"agent": agent, "task": task}))
    with (folder / "metrics.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, COLUMNS)
        writer.writeheader()
        for k, rate in enumerate(success):
            writer.writerow({"update": k + 1, "env_steps": 100 * (k + 1),
                             "success_rate_100": "" if rate is None else rate})


def test_plot_averages_seeds_per_task_and_agent_and_draws_baselines(tmp_path):
    _fake_run(tmp_path / "a0", "ppo_rnn", "T2", [None, 0.0, 0.2])
    _fake_run(tmp_path / "a1", "ppo_rnn", "T2", [0.0, 0.2, 0.6])
    _fake_run(tmp_path / "b0", "ppo_steve", "T4", [0.1, 0.3])
    report = tmp_path / "steve_t2.json"
    report.write_text('{"task": "T2", "success_percent": 25.0}')
    report4 = tmp_path / "steve_t4.json"
    report4.write_text('{"task": "T4", "success_percent": 5.0}')
    runs = [str(tmp_path / n) for n in ("a0", "a1", "b0")]
    out = tmp_path / "fig.png"
    assert main(["rl", "plot", *runs, "--out", str(out), "--baseline",
                 f"C-Steve-1={report}", "--baseline", f"C-Steve-1={report4}"]) == 0
    assert out.stat().st_size > 0
    table = yaml.safe_load(out.with_suffix(".json").read_text())
    assert table["T2"]["ppo_rnn"] == pytest.approx(
        {"success_rate": 0.4, "std": 0.2, "seeds": 2, "env_steps": 300})
    assert table["T2"]["C-Steve-1"]["success_rate"] == 0.25
    assert table["T4"]["ppo_steve"]["success_rate"] == pytest.approx(0.3)
    assert table["T4"]["C-Steve-1"]["success_rate"] == 0.05  # a label per task, not per run
    with pytest.raises(SystemExit, match="LABEL=report.json"):
        main(["rl", "plot", runs[0], "--out", str(out), "--baseline", "nolabel"])
