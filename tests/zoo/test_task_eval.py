"""Task evaluation: the Wilson interval, the summary and report, and the goal-directed
scripted expert solving the tasks (a task the privileged expert fails is a broken task)."""

from __future__ import annotations

import json

import pytest

from zoo.envs.tasks import LONG_HORIZON_TASKS, SINGLE_STEP_TASKS, TASKS, make_task_env
from zoo.eval.task_eval import (
    TaskEpisode,
    compare_success,
    evaluate_task,
    summarize_task,
    wilson_interval,
    write_task_report,
)
from zoo.experts.scripted import ScriptedExpert


@pytest.mark.parametrize(
    "successes, n, low, high",
    [
        # by hand: center = (p + z²/2n) / (1 + z²/n), half = z/(1 + z²/n) sqrt(p(1-p)/n + z²/4n²)
        (0, 10, 0.0, 0.27753),  # upper = (z²/n) / (1 + z²/n) = 0.38416 / 1.38416
        (10, 10, 0.72247, 1.0),
        (5, 10, 0.23659, 0.76341),  # center 0.5, half 1.41602 * 0.186021
        (18, 20, 0.69897, 0.97214),  # center 0.83555, half 1.64419 * 0.083073
    ],
)
def test_wilson_interval_matches_hand_computed_values(successes, n, low, high):
    got = wilson_interval(successes, n)
    assert got == pytest.approx((low, high), abs=1e-4)


def test_wilson_interval_rejects_impossible_counts():
    for successes, n in ((1, 0), (-1, 5), (6, 5)):
        with pytest.raises(ValueError, match="need 0 <= successes <= n and n >= 1"):
            wilson_interval(successes, n)


def _episode(i: int, steps: list[int | None], end: str = "zombie") -> TaskEpisode:
    success = all(s is not None for s in steps)
    return TaskEpisode(i, i, success, steps[-1] if success else None, steps, 100,
                       "success" if success else end)


def test_compare_success_counts_ahead_and_separated_tasks():
    """Two-proportion p-values by hand, 100 episodes each: 39 vs 7, pooled 0.23, z = 0.32 /
    sqrt(0.23 * 0.77 * 0.02) = 5.3768, p = 7.58e-8; 50 vs 62, pooled 0.56, z = -0.12 / 0.070200
    = -1.7094, p = 0.0874; 99 vs 92, pooled 0.955, z = 0.07 / 0.029317 = 2.3877, p = 0.0170
    (below 0.05 though the Wilson intervals overlap); 62 vs 62, z = 0, p = 1."""
    def cell(successes: int, n: int = 100) -> dict:
        return {"successes": successes, "episodes": n, "success_percent": 100 * successes / n,
                "wilson95_percent": [100 * x for x in wilson_interval(successes, n)]}

    steve = {"a": cell(39), "b": cell(50), "c": cell(99), "d": cell(30), "e": cell(62)}
    cvpt = {"a": cell(7), "b": cell(62), "c": cell(92), "e": cell(62)}  # no "d": not compared
    result = compare_success(steve, cvpt)
    assert result["tasks"] == ["a", "b", "c", "e"]
    assert result["ahead"] == ["a", "c"]  # a tie (e) is not ahead
    # 99/100 -> 94.6-99.8% overlaps 92/100 -> 85.0-95.9%; 39/100 (30.0-48.8) clears 7/100 (3.4-13.7)
    assert result["separated"] == ["a"]
    assert result["p_two_proportion"] == pytest.approx(
        {"a": 7.5812e-8, "b": 0.087375, "c": 0.016955, "e": 1.0}, rel=1e-4)


def test_summary_and_report(tmp_path):
    results = [_episode(0, [3, 10]), _episode(1, [5, None]), _episode(2, [4, 30])]
    meta = {"task": "T2", "env": "crafter", "agent": "x", "instruction_mode": "m",
            "instructions": list(TASKS["T2"].instructions)}
    report = write_task_report(results, [], tmp_path, meta)
    assert report["successes"] == 2 and report["success_percent"] == pytest.approx(200 / 3)
    assert report["median_steps_to_success"] == 20.0
    assert [s["completed_percent"] for s in report["subtasks"]] == pytest.approx([100, 200 / 3])
    assert report["subtasks"][0]["median_step"] == 4.0
    saved = json.loads((tmp_path / "report.json").read_text())
    assert saved["episode_results"][1]["subtask_steps"] == [5, None]
    table = (tmp_path / "report.md").read_text()
    assert "| **task** | 66.7 |" in table and "| 2. place table on grass | 66.7 |" in table
    with pytest.raises(ValueError, match="no task episodes"):
        summarize_task([], [])


def test_the_report_says_how_failures_ended(tmp_path):
    """Shares are of the failures (3 of 4 episodes here), every cause listed; a success is
    not a cause."""
    results = [_episode(0, [3, 10]), _episode(1, [5, None], "needs"),
               _episode(2, [None, None], "needs"), _episode(3, [4, None], "survived")]
    meta = {"task": "T2", "env": "crafter", "agent": "x", "instruction_mode": "m",
            "instructions": list(TASKS["T2"].instructions)}
    report = write_task_report(results, [], tmp_path, meta)
    assert report["failure_end_percent"] == pytest.approx(
        {"survived": 100 / 3, "lava": 0, "zombie": 0, "arrow": 0, "needs": 200 / 3, "other": 0})
    assert "Failures ended by: survived 33%, needs 67% (survived: the step limit)." in (
        tmp_path / "report.md").read_text()
    assert summarize_task(results[:1], meta["instructions"])["failure_end_percent"] == {}


def _expert_success(task: str, game: str, episodes: int, num_envs: int = 4) -> list[TaskEpisode]:
    env = make_task_env(task, game, num_envs, pixels=False)
    results, _ = evaluate_task(
        ScriptedExpert(num_envs), env, episodes, seed=0, follow_subtasks=True, progress=False
    )
    return results


@pytest.mark.parametrize("task", ["make_wood_pickaxe", "T2"])
def test_goal_directed_expert_solves_tasks_quickly(task):
    results = _expert_success(task, "crafter", episodes=4, num_envs=2)
    assert [r.index for r in results] == [0, 1, 2, 3]
    assert all(r.success for r in results)
    for r in results:
        assert r.steps_to_success == r.length == r.subtask_steps[-1]  # success ends the episode
        assert r.end == "success"
        assert r.subtask_steps == sorted(r.subtask_steps)


def test_results_do_not_depend_on_the_batch_size():
    one = _expert_success("T3", "crafter", episodes=3, num_envs=1)
    three = _expert_success("T3", "crafter", episodes=3, num_envs=3)
    assert one == three


def test_a_failed_episode_carries_how_it_ended():
    """Random play fails T4; each failure's end is the rollout's death cause, the step limit
    ("survived") included, and the summary counts them."""
    from zoo.agents.base import RandomAgent
    from zoo.eval.death import DEATH_CAUSES

    env = make_task_env("T4", "crafter", 2, pixels=False, max_steps=60)
    results, rollouts = evaluate_task(RandomAgent(2), env, 2, seed=0, progress=False)
    assert not any(r.success for r in results)
    assert [r.end for r in results] == [r.death for r in rollouts] and set(
        r.end for r in results) <= set(DEATH_CAUSES)
    shares = summarize_task(results, list(TASKS["T4"].instructions))["failure_end_percent"]
    assert sum(shares.values()) == pytest.approx(100)


def test_instructions_need_an_instructable_agent():
    from zoo.agents.base import RandomAgent

    env = make_task_env("T2", "crafter", 1, pixels=False)
    with pytest.raises(ValueError, match="agent 'random' does not follow instructions"):
        evaluate_task(RandomAgent(1), env, 1, 0, instruction="obtain wood", progress=False)


@pytest.mark.slow
@pytest.mark.parametrize("game", ["crafter", "craftax"])
@pytest.mark.parametrize("task", SINGLE_STEP_TASKS + LONG_HORIZON_TASKS)
def test_goal_directed_expert_solves_every_task(task, game):
    results = _expert_success(task, game, episodes=20)
    assert sum(r.success for r in results) >= 18, [r for r in results if not r.success]


def test_expert_instruct_checks_its_arguments():
    expert = ScriptedExpert(2)
    with pytest.raises(ValueError, match=r"cannot follow \['dance'\]; known instructions: \["):
        expert.instruct(["dance", None])
    with pytest.raises(ValueError, match="got 1 instructions, expected 2"):
        expert.instruct(["obtain wood"])
    expert.instruct(["obtain wood", None], mask=[True, False])
    assert [p.instruction for p in expert._planners] == ["obtain wood", None]
    expert.reset([0, 1])  # a new episode plays normally until instructed again
    assert [p.instruction for p in expert._planners] == [None, None]
