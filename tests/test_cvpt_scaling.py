"""bench/cvpt_scaling.py: the plan's cells and commands, resuming after finished cells, and a
whole (tiny) cell through real `zoo data generate`, `zoo fit` and `zoo eval`."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
PLAN = ROOT / "configs" / "studies" / "cvpt_scaling.yaml"


def _load():
    spec = importlib.util.spec_from_file_location("cvpt_scaling", ROOT / "bench" / "cvpt_scaling.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["cvpt_scaling"] = module  # dataclasses look their module up there
    spec.loader.exec_module(module)
    return module


scaling = _load()


def test_the_shipped_plan_has_three_points_per_axis_and_two_seeds() -> None:
    plan = scaling.load_plan(PLAN)
    cells = scaling.cells(plan)
    assert len(cells) == 2 * len(plan["points"])
    assert [c.seed for c in cells[: len(plan["points"])]] == [0] * len(plan["points"])
    for axis in scaling.AXES:
        assert sum(axis in spec["axes"] for spec in plan["points"].values()) >= 3, axis
    epoch = yaml.safe_load((ROOT / plan["recipe"]).read_text())["data"]["init_args"][
        "train_batches_per_epoch"]
    assert all(c.steps % epoch == 0 for c in cells)  # each run ends on its last checkpoint


def test_a_point_on_an_undefined_dataset_names_it(tmp_path: Path) -> None:
    plan = yaml.safe_load(PLAN.read_text())
    plan["points"]["frames_1250"]["data"] = {"nowhere": 1.0}
    path = tmp_path / "plan.yaml"
    path.write_text(yaml.safe_dump(plan))
    with pytest.raises(ValueError, match=r"point 'frames_1250' uses undefined datasets \['nowhere'\]"):
        scaling.load_plan(path)


def test_fit_command_trains_the_cell_on_its_weighted_data() -> None:
    plan = scaling.load_plan(PLAN)
    cell = next(c for c in scaling.cells(plan) if c.name == "horizon_2000_seed1")
    command = scaling.fit_command(plan, cell, Path("data/scaling"), Path("runs/x"))
    assert command[command.index("--config") + 1] == "configs/cvpt_tiny_tiles_cpu.yaml"
    assert {"--seed_everything=1", "--trainer.max_steps=2500",
            "--model.init_args.cosine_steps=2500", "--data.init_args.root=null"} <= set(command)
    sources = json.loads(next(a for a in command if a.startswith("--data.init_args.sources="))
                         .split("=", 1)[1])
    assert sources == [{"root": "data/scaling/cx2000_240", "weight": 2.0},
                       {"root": "data/scaling/cr2000_60", "weight": 1.0}]


def _tiny_plan(tmp_path: Path) -> Path:
    """The smoke recipe, one point of 4 steps on 8 random-play crafter episodes, scored on 2."""
    recipe = yaml.safe_load((ROOT / "configs" / "cvpt_smoke.yaml").read_text())
    recipe["trainer"]["logger"] = False
    recipe["trainer"]["limit_val_batches"] = 1
    recipe["data"]["init_args"].update(train_batches_per_epoch=2, num_workers=0, val_fraction=0.25)
    (tmp_path / "recipe.yaml").write_text(yaml.safe_dump(recipe))
    plan = {
        "recipe": str(tmp_path / "recipe.yaml"), "seeds": [0],
        "eval": {"episodes": 2, "seed": 0, "games": ["crafter"]},
        "datasets": {"cr": {"env": "crafter", "episodes": 8, "max_steps": 40, "seed": 3}},
        "points": {"frames_4": {"steps": 4, "data": {"cr": 1.0}, "axes": ["frames"]}},
    }
    path = tmp_path / "plan.yaml"
    path.write_text(yaml.safe_dump(plan))
    return path


@pytest.mark.slow
def test_a_tiny_cell_runs_end_to_end_and_a_rerun_skips_it(tmp_path: Path, monkeypatch) -> None:
    monkeypatch.chdir(ROOT)
    plan, out = _tiny_plan(tmp_path), tmp_path / "results.json"
    args = ["--plan", str(plan), "--out", str(out), "--data-dir", str(tmp_path / "data"),
            "--runs", str(tmp_path / "runs"), "--workers", "1"]
    assert scaling.main(args) == 0
    record = json.loads(out.read_text())["cells"]["frames_4_seed0"]
    assert record["steps"] == 4 and record["frames"] == 4 * 4 * 32
    assert record["unique_episodes"] == 8 and record["max_steps"] == 40
    assert 0.0 <= record["scores"]["crafter"]["crafter_score"] <= 100.0
    before = out.read_text()
    assert scaling.main(args) == 0  # every cell done: nothing runs, nothing changes
    assert out.read_text() == before
    assert scaling.main([*args, "--plot", str(tmp_path / "curves.png")]) == 0
    assert (tmp_path / "curves.png").stat().st_size > 0


def test_the_log_fit_matches_a_hand_computed_line() -> None:
    """Scores 10 and 20 at 1M and 10M frames (one seed each), 16 and 14 at 10M (two seeds):
    the least-squares line through (6, 10), (7, 16), (7, 14) is 10 + 5 per tenfold, so 180M
    frames (log10 = 8.255) extrapolate to 10 + 5 * 2.255 = 21.28."""
    fit = scaling.log_fit({1e6: [10.0], 1e7: [16.0, 14.0]}, 180e6)
    assert fit["per_tenfold"] == pytest.approx(5.0)
    assert fit["extrapolated"] == pytest.approx(10 + 5 * (np.log10(180e6) - 6))
    assert fit["rms_residual"] == pytest.approx(np.sqrt(2 / 3))
    with pytest.raises(ValueError, match="two distinct x"):
        scaling.log_fit({1e6: [1.0, 2.0]}, 1e8)


def test_the_table_lists_each_seed_and_marks_the_cells_not_run() -> None:
    record = {"point": "frames_1250", "seed": 0, "frames": 640_000, "unique_episodes": 2400,
              "data_steps": 1_368_492, "max_steps": 600,
              "scores": {"craftax": {"crafter_score": 4.21, "crafter_score_std": 0.49}}}
    results = {"plan": {"seeds": [0, 1], "eval": {"games": ["craftax"]}},
               "cells": {"frames_1250_seed0": record}}
    lines = scaling.table(results).splitlines()
    assert lines[0] == ("| point | frames | unique episodes | data steps | cap | craftax seed 0 "
                        "| craftax seed 1 |")
    assert lines[2] == "| frames_1250 | 0.64M | 2,400 | 1,368,492 | 600 | 4.2 ± 0.5 | not run |"
