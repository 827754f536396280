"""`zoo tables task-table|cfg-sweep|goal-check`: C-Steve-1's results protocol as commands, beside
the plain `zoo eval` that still needs --env."""

from __future__ import annotations

import io
import json
import tarfile
from pathlib import Path

import numpy as np
import pytest
import torch

from zoo.cli import build_parser, main
from zoo.eval import csteve1_tables
from zoo.eval.task_eval import wilson_interval

# the commands of docs/results/csteve1.md, both games
GOAL_CHECK = ["tables", "goal-check", "--cclip", "weights/cclip_cpu", "--prior", "weights/prior_cpu",
              "--embeddings", ".", "--out", "runs/steve_goals"]
CFG_SWEEP = ["tables", "cfg-sweep", "--csteve1", "weights/csteve1_cpu", "--cclip",
             "weights/cclip_cpu", "--prior", "weights/prior_cpu", "--env", "craftax", "crafter",
             "--episodes", "20", "--num-envs", "10", "--out", "runs/steve_sweep",
             "--cfg-scales", "0", "0.5", "1"]
TASK_TABLE = ["tables", "task-table", "--cvpt", "weights/cvpt_tiny_cpu", "--csteve1",
              "weights/csteve1_cpu", "--cclip", "weights/cclip_cpu", "--prior",
              "weights/prior_cpu", "--env", "craftax", "crafter", "--episodes", "100",
              "--num-envs", "20", "--seed", "1", "--cfg-scale", "0.5", "--rows", "cvpt",
              "csteve1", "csteve1_other", "--out", "runs/steve_table"]


def test_the_protocols_parse_with_the_docs_flags() -> None:
    parser = build_parser()
    table = parser.parse_args(TASK_TABLE)
    assert table.protocol == "task-table" and table.env == ["craftax", "crafter"]
    assert (table.episodes, table.num_envs, table.seed, table.cfg_scale) == (100, 20, 1, 0.5)
    assert table.rows == ["cvpt", "csteve1", "csteve1_other"]
    assert table.tasks == list(csteve1_tables.OTHER_INSTRUCTION)
    assert table.cvpt == Path("weights/cvpt_tiny_cpu") and table.out == Path("runs/steve_table")
    sweep = parser.parse_args(CFG_SWEEP)
    assert sweep.protocol == "cfg-sweep" and sweep.cfg_scales == [0, 0.5, 1]
    assert sweep.num_envs == 10 and sweep.csteve1 == Path("weights/csteve1_cpu")
    goals = parser.parse_args(GOAL_CHECK)
    assert goals.protocol == "goal-check" and goals.embeddings == Path(".")
    assert (goals.max_shards, goals.min_count, goals.samples) == (12, 50, 20)
    assert table.handler is sweep.handler is goals.handler
    plain = parser.parse_args(["eval", "--env", "crafter", "--checkpoint", "x.ckpt"])
    assert "protocol" not in vars(plain) and plain.env == "crafter"
    assert plain.handler is not table.handler
    defaults = parser.parse_args(["tables", "task-table", "--out", "o"])
    assert (defaults.env, defaults.episodes, defaults.num_envs) == (["craftax", "crafter"], 100, 20)
    # None: what the C-Steve-1 export records (else 1.5 and 1)
    assert (defaults.seed, defaults.cfg_scale, defaults.temperature) == (0, None, None)
    assert defaults.rows == list(csteve1_tables.TABLE_ROWS)


def test_versus_cvpt_states_disjoint_intervals_and_the_p_value() -> None:
    """50 episodes a cell. Sapling 38 vs 27: ahead, Wilson intervals 62.6-85.7% and 40.4-67.0%
    overlap, two-proportion p = 0.021 (pooled 0.65, z = 2.306); drink 40 vs 25: 67.0-88.8% and
    36.6-63.4% are disjoint, p = 0.0017 (z = 3.145)."""
    def row(task: str, agent: str, k: int) -> dict:
        return {"env": "crafter", "task": task, "agent": agent, "episodes": 50, "successes": k,
                "success_percent": 2.0 * k,
                "wilson95_percent": [100 * x for x in wilson_interval(k, 50)]}

    rows = [row("collect_sapling", "csteve1", 38), row("collect_sapling", "cvpt", 27),
            row("collect_drink", "csteve1", 40), row("collect_drink", "cvpt", 25)]
    assert csteve1_tables.versus_cvpt(rows) == [
        "crafter: C-Steve-1 ahead of C-VPT on 2 of 2 tasks (collect_sapling, collect_drink), "
        "disjoint 95% intervals on 1 (collect_drink); two-proportion p: collect_sapling 0.021, "
        "collect_drink 0.002"]


def test_tables_help_lists_the_tables(capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["tables", "--help"])
    assert exit_info.value.code == 0
    out = capsys.readouterr().out
    for name in ("task-table", "cfg-sweep", "goal-check", "instructions"):
        assert f"    {name}" in out, name


def test_eval_is_one_command_that_needs_env(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    with pytest.raises(SystemExit) as exit_info:
        main(["eval", "--agent", "random", "--out", str(tmp_path / "run")])
    assert exit_info.value.code == 2
    assert "the following arguments are required: --env" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()
    with pytest.raises(SystemExit):
        main(["eval", "task-table", "--out", str(tmp_path)])  # the tables are `zoo tables`


@pytest.mark.parametrize(
    "argv, message",
    [
        (["task-table", "--rows", "cvpt"],
         "the cvpt row needs --cvpt (the unconditioned baseline)"),
        (["task-table", "--rows", "csteve1"], "C-Steve-1 rows need --csteve1"),
        (["task-table", "--rows", "cvpt", "--cvpt", "nope"], "--cvpt nope does not exist"),
    ],
)
def test_missing_checkpoints_are_one_line_errors(
    tmp_path: Path, capsys: pytest.CaptureFixture, argv: list[str], message: str
) -> None:
    assert main(["tables", *argv, "--out", str(tmp_path)]) == 2
    assert capsys.readouterr().err == f"zoo tables {argv[0]}: error: {message}\n"


def test_sweep_and_goal_check_require_their_checkpoints(
    tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    for argv in (["cfg-sweep"], ["goal-check", "--embeddings", str(tmp_path)]):
        with pytest.raises(SystemExit) as exit_info:
            main(["tables", *argv, "--out", str(tmp_path)])
        assert exit_info.value.code == 2
        assert "the following arguments are required: " in capsys.readouterr().err


@pytest.fixture(scope="module")
def tiny_models(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Random exports of the four networks the protocol loads, small enough to play fast; the
    C-Steve-1 records guidance scale 0.7, which its rows play at unless given another."""
    from zoo.envs.constants import NUM_ACTIONS
    from zoo.models.cclip import build_cclip
    from zoo.models.cvpt import CVPTConfig, CVPTModel
    from zoo.models.prior import CVAEPrior, PriorConfig
    from zoo.models.csteve1 import CSteve1Config, CSteve1Model
    from zoo.weights.export import save_exported

    root = tmp_path_factory.mktemp("models")
    torch.manual_seed(0)
    backbone = CVPTModel(CVPTConfig.from_name(
        "tiny", NUM_ACTIONS, d_model=32, d_ff=64, n_heads=2, n_layers=1, impala_channels=(2, 4, 4),
        encoder_hidden=32, memory_len=4, input_downsample=4,
    ))
    paths = {"cvpt": save_exported(backbone, root / "cvpt")}  # before LoRA wraps its layers
    models = {
        "csteve1": CSteve1Model(backbone, CSteve1Config(goal_dim=64, lora_rank=2)),
        "cclip": build_cclip("smoke", vision_layers=1, text_layers=1),
        "prior": CVAEPrior(PriorConfig(embed_dim=64, hidden=16, latent_dim=4)),
    }
    inference = {"csteve1": {"cfg_scale": 0.7}}
    return paths | {name: save_exported(model, root / name, inference=inference.get(name))
                    for name, model in models.items()}


def test_task_table_writes_its_cells_and_summary_and_a_rerun_skips_them(
    tiny_models: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture,
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    argv = ["tables", "task-table", *(f"--{k}={v}" for k, v in tiny_models.items()),
            "--env", "crafter", "--tasks", "collect_sapling", "--episodes", "2", "--num-envs", "2",
            "--out", str(tmp_path)]
    assert main(argv) == 0
    summary = json.loads((tmp_path / "summary_table.json").read_text())
    assert [r["agent"] for r in summary] == list(csteve1_tables.TABLE_ROWS)
    assert [r["instruction"] for r in summary] == [None, None, "obtain sapling", "obtain drink"]
    for row in csteve1_tables.TABLE_ROWS:
        report = json.loads((tmp_path / "crafter" / "collect_sapling" / row / "report.json")
                            .read_text())
        assert report["episodes"] == 2 and report["agent"] == row
        played_at = {"cfg_scale": 0.7, "temperature": 1.0} if row in csteve1_tables.STEVE_ROWS else {}
        assert {k: report[k] for k in ("cfg_scale", "temperature") if k in report} == played_at
    table = (tmp_path / "summary_table.md").read_text()
    assert table.startswith(csteve1_tables.SUMMARY_HEADER)
    assert "crafter: C-Steve-1 ahead of C-VPT on" in table and "of 1 tasks" in table
    assert "summary_table.md" in capsys.readouterr().out

    def no_playing(*args: object, **kwargs: object) -> None:
        raise AssertionError("a reported cell was played again")

    monkeypatch.setattr(csteve1_tables, "evaluate_task", no_playing)
    (tmp_path / "summary_table.md").unlink()
    assert main(argv) == 0
    assert (tmp_path / "summary_table.md").read_text() == table


def _embedding_shard(path: Path, num_captions: int, dim: int) -> None:
    """One `zoo goals embed` episode in which every caption has two steps."""
    from zoo.goals.embed import sample_members

    caption = np.repeat(np.arange(num_captions), 2)
    goal = np.random.default_rng(0).standard_normal((len(caption), dim))
    with tarfile.open(path, "w") as tar:
        for name, data in sample_members(0, 0, goal, caption):
            info = tarfile.TarInfo(name)
            info.size = len(data)
            tar.addfile(info, io.BytesIO(data))


def test_goal_check_ranks_every_task_instruction(
    tiny_models: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture
) -> None:
    from zoo.captions.vocabulary import load_vocabulary

    (tmp_path / "embed").mkdir()
    argv = ["tables", "goal-check", "--cclip", str(tiny_models["cclip"]), "--prior",
            str(tiny_models["prior"]), "--embeddings", str(tmp_path / "embed"), "--samples", "2",
            "--out", str(tmp_path / "out")]
    assert main(argv) == 2
    assert "--embeddings: no embed-*.tar shards in" in capsys.readouterr().err
    _embedding_shard(tmp_path / "embed" / "embed-000000.tar", len(load_vocabulary().texts()), 64)
    assert main([*argv, "--min-count", "2"]) == 0
    rows = json.loads((tmp_path / "out" / "summary_goals.json").read_text())
    instructions = {s.instruction for t in csteve1_tables.TASKS.values() for s in t.subtasks}
    assert [r["instruction"] for r in rows] == sorted(instructions)
    assert all(r["caption_steps"] == 2 and 0 <= r["rank_of_mean_goal"] for r in rows)
    assert all(0 <= r["sampled_nearest_share"] <= 1 for r in rows)
    assert not (tmp_path / "out" / "summary_goals.md").exists()


def test_cfg_sweep_names_a_row_per_scale_and_plots_them(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    played = []

    def cell(self: csteve1_tables.Setting, env_name: str, task: str, row: str, agent: object,
             instruction: str | None) -> dict:
        played.append((env_name, task, row, instruction))
        return {"episodes": 2, "successes": 1, "success_percent": 50.0,
                "wilson95_percent": [9.5, 90.5],
                "median_steps_to_success": 7.0}

    monkeypatch.setattr(csteve1_tables.Setting, "steve", lambda self, cfg_scale: None)
    monkeypatch.setattr(csteve1_tables.Setting, "cell", cell)
    assert main(["tables", "cfg-sweep", "--csteve1", ".", "--cclip", ".", "--prior", ".",
                 "--env", "crafter", "--cfg-scales", "0", "1.5", "--out", str(tmp_path)]) == 0
    assert [p[2] for p in played] == ["csteve1_cfg0"] * 4 + ["csteve1_cfg1.5"] * 4
    assert [p[1] for p in played[:4]] == list(csteve1_tables.CFG_TASKS)
    rows = json.loads((tmp_path / "summary_sweep.json").read_text())
    assert [r["cfg_scale"] for r in rows] == [0] * 4 + [1.5] * 4
    assert "| crafter | collect_sapling | csteve1_cfg0 | obtain sapling | 50 (10-90) | 7 | 2 |" in (
        tmp_path / "summary_sweep.md").read_text()
    assert (tmp_path / "cfg_sweep.png").stat().st_size > 0
