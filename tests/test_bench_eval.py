"""bench/bench_eval.py's episodes/s estimate on hand cases."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

_SPEC = importlib.util.spec_from_file_location(
    "bench_eval", Path(__file__).resolve().parents[1] / "bench" / "bench_eval.py")
bench_eval = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(bench_eval)


def test_a_budget_stopped_loop_divides_steps_per_s_by_the_mean_length() -> None:
    """4 busy slots, every episode 50 steps long, 1,000 env steps in 10 s: each slot finishes
    250 / 50 = 5 episodes, 20 in 10 s = 2 episodes/s, and 100 steps/s / 50 steps = 2 too.
    Finished lengths 100, 150, 200 (mean 150) at 1,000 steps in 4 s: 250 / 150 = 5/3."""
    assert bench_eval.episodes_per_s([50] * 20, 1000, 10.0, all_finished=False)[0] == 2.0
    rate, method = bench_eval.episodes_per_s([100, 150, 200], 1000, 4.0, all_finished=False)
    assert rate == pytest.approx(5 / 3) and method.startswith("budget reached")


def test_finished_runs_count_episodes_and_an_empty_run_has_no_estimate() -> None:
    """3 episodes (of 40, 60, 80 steps) all done in 2 s: 1.5 episodes/s, whatever the steps."""
    assert bench_eval.episodes_per_s([40, 60, 80], 180, 2.0, all_finished=True) == (
        1.5, "all episodes finished: episodes / wall")
    assert bench_eval.episodes_per_s([], 500, 3.0, all_finished=False) == (
        None, "budget reached before any episode finished")
