"""Task suites: play an agent on a task (``zoo.envs.tasks``) and report success the paper's way.

The episodes are run by ``zoo.eval.rollout.evaluate`` itself (same seeding, batching and GIF),
on a ``TaskEnv`` that ends an episode when its last sub-task completes; each finished
episode's sub-task steps are read from the env's ``progress`` in the slot that held its seed.
Success rates come with a Wilson 95% interval: with 20 episodes a rate of 90% is only known
to within about 70-97%, and the normal approximation would put the bound above 100%.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

from zoo.agents.base import Agent, InstructableAgent
from zoo.envs.base import Step
from zoo.envs.tasks import TaskEnv
from zoo.eval.death import death_shares
from zoo.eval.plots import write_gif
from zoo.eval.rollout import EpisodeResult, evaluate
from zoo.eval.stats import disjoint_above, two_proportion_p


def wilson_interval(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """Wilson score interval of a binomial rate ``successes / n`` (default: 95%)."""
    if n < 1 or not 0 <= successes <= n:
        raise ValueError(f"need 0 <= successes <= n and n >= 1, got successes={successes}, n={n}")
    p, z2 = successes / n, z * z
    denom = 1 + z2 / n
    center = (p + z2 / (2 * n)) / denom
    half = z / denom * math.sqrt(p * (1 - p) / n + z2 / (4 * n * n))
    return max(0.0, center - half), min(1.0, center + half)


@dataclass
class TaskEpisode:
    """One episode of a task: ``subtask_steps[k]`` is the step sub-task k completed (None if
    never); ``steps_to_success`` is the last one when all completed in order, else None."""

    index: int
    seed: int
    success: bool
    steps_to_success: int | None
    subtask_steps: list[int | None]
    length: int
    end: str
    """Why it ended: "success", or for a failure ``zoo.eval.death``'s cause ("survived" is the
    step limit)."""


class SubtaskInstructor:
    """Hands an InstructableAgent each env's current sub-task caption (the task's own plan),
    or one fixed instruction, after every reset; the goal-directed reference of a task."""

    def __init__(self, inner: InstructableAgent, env: TaskEnv, instruction: str | None = None):
        self.inner, self.env, self.instruction = inner, env, instruction
        self.name = inner.name
        self.needs_pixels = inner.needs_pixels
        self._given: list[str | None] = [None] * env.num_envs

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> None:
        self.inner.reset(seeds, mask)
        mask = np.ones(self.env.num_envs, bool) if mask is None else np.asarray(mask, bool)
        self._instruct(mask, force=True)

    def act(self, step: Step) -> np.ndarray:
        if self.instruction is None:
            self._instruct(np.ones(self.env.num_envs, bool), force=False)
        return self.inner.act(step)

    def _instruct(self, mask: np.ndarray, force: bool) -> None:
        wanted = (
            [self.instruction] * self.env.num_envs
            if self.instruction is not None
            else self.env.progress.current_instructions()
        )
        changed = mask & np.array([force or w != g for w, g in zip(wanted, self._given)])
        if changed.any():
            self.inner.instruct(wanted, changed)
            self._given = [w if c else g for w, g, c in zip(wanted, self._given, changed)]


def evaluate_task(
    agent: Agent,
    env: TaskEnv,
    episodes: int,
    seed: int,
    instruction: str | None = None,
    follow_subtasks: bool = False,
    record_gif_episode: int | None = None,
    progress: bool = True,
) -> tuple[list[TaskEpisode], list[EpisodeResult]]:
    """Play ``episodes`` episodes of ``env.task``; episode j is seeded ``episode_seed(seed, j)``.

    Args:
        agent: plays all envs; an InstructableAgent when ``instruction`` or ``follow_subtasks``.
        env: the task env (``zoo.envs.tasks.make_task_env``), ending episodes on success.
        instruction: given to the agent after every reset (the single-instruction baseline).
        follow_subtasks: give the agent each env's current sub-task caption instead.
    Returns:
        Task results and rollout results (for the GIF), both sorted by episode index.
    """
    if not env.end_on_success:
        raise ValueError("evaluate_task needs a TaskEnv made with end_on_success=True")
    if instruction is not None and follow_subtasks:
        raise ValueError("give either an instruction or follow_subtasks, not both")
    if instruction is not None or follow_subtasks:
        if not hasattr(agent, "instruct"):
            raise ValueError(f"agent {agent.name!r} does not follow instructions (no instruct)")
        agent = SubtaskInstructor(agent, env, instruction)
    task_results: list[TaskEpisode] = []

    def collect(result: EpisodeResult) -> None:
        slot = int(np.flatnonzero(env.seeds == result.seed)[0])
        done_at = env.progress.done_at[slot]
        steps = [int(s) if s >= 0 else None for s in done_at]
        success = bool(env.progress.success[slot])
        task_results.append(
            TaskEpisode(
                index=result.index,
                seed=result.seed,
                success=success,
                steps_to_success=steps[-1] if success else None,
                subtask_steps=steps,
                length=result.length,
                end="success" if success else result.death,
            )
        )

    results = evaluate(
        agent, env, episodes, seed, on_episode=collect,
        record_gif_episode=record_gif_episode, progress=progress,
    )
    return sorted(task_results, key=lambda r: r.index), results


def summarize_task(results: list[TaskEpisode], subtasks: list[str]) -> dict:
    """Success rate with its Wilson 95% interval, median steps, and per-sub-task rates."""
    if not results:
        raise ValueError("no task episodes to summarize")
    n = len(results)
    wins = sum(r.success for r in results)
    low, high = wilson_interval(wins, n)
    steps = [r.steps_to_success for r in results if r.success]
    per_sub = []
    for k, text in enumerate(subtasks):
        done = [r.subtask_steps[k] for r in results if r.subtask_steps[k] is not None]
        per_sub.append(
            {
                "instruction": text,
                "completed_percent": 100.0 * len(done) / n,
                "median_step": float(np.median(done)) if done else None,
            }
        )
    failures = [r.end for r in results if not r.success]
    return {
        "episodes": n,
        "successes": wins,
        "success_percent": 100.0 * wins / n,
        "wilson95_percent": [100.0 * low, 100.0 * high],
        "median_steps_to_success": float(np.median(steps)) if steps else None,
        "subtasks": per_sub,
        # a long task is often lost to a death on the way: which one says what to fix
        "failure_end_percent": death_shares(failures) if failures else {},
    }


def write_task_report(
    results: list[TaskEpisode],
    rollouts: list[EpisodeResult],
    out_dir: str | Path,
    meta: dict,
    gif_scale: int = 2,
) -> dict:
    """Write report.json (summary + meta + episodes), report.md and, if kept, episode.gif."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    report = summarize_task(results, meta["instructions"])
    clashes = sorted(set(meta) & (set(report) | {"written_at", "files", "episode_results"}))
    if clashes:
        raise ValueError(f"meta keys {clashes} clash with report fields; rename them")
    report.update(meta)
    report["written_at"] = datetime.now(UTC).isoformat(timespec="seconds")
    files = ["report.json", "report.md"]
    gif_episode = next((r for r in rollouts if r.frames is not None), None)
    if gif_episode is not None:
        write_gif(gif_episode.frames, out_dir / "episode.gif", scale=gif_scale)
        report["gif_episode"] = gif_episode.index
        files.append("episode.gif")
    report["files"] = files
    report["episode_results"] = [asdict(r) for r in results]
    (out_dir / "report.json").write_text(json.dumps(report, indent=2) + "\n")
    (out_dir / "report.md").write_text(format_task_table(report) + "\n")
    return report


def format_task_table(report: dict) -> str:
    """The report as a markdown table (readable in a terminal too)."""
    low, high = report["wilson95_percent"]
    median = report["median_steps_to_success"]
    title = (
        f"task {report['task']} in {report['env']}, agent {report['agent']}"
        f" ({report['instruction_mode']}), {report['episodes']} episodes"
    )
    median_text = "-" if median is None else f"{median:.0f}"
    lines = [
        title,
        "",
        "| | success % | Wilson 95% | median steps |",
        "|---|---:|---:|---:|",
        f"| **task** | {report['success_percent']:.1f} | {low:.1f}-{high:.1f} | {median_text} |",
    ]
    for k, sub in enumerate(report["subtasks"], 1):
        step = sub["median_step"]
        lines.append(
            f"| {k}. {sub['instruction']} | {sub['completed_percent']:.1f} | |"
            f" {'-' if step is None else f'{step:.0f}'} |"
        )
    ends = {cause: share for cause, share in report.get("failure_end_percent", {}).items() if share}
    if ends:
        text = ", ".join(f"{cause} {share:.0f}%" for cause, share in ends.items())
        lines += ["", f"Failures ended by: {text} (survived: the step limit)."]
    return "\n".join(lines)


def compare_success(agent: dict[str, dict], baseline: dict[str, dict]) -> dict:
    """Tasks (keys present in both) where ``agent``'s task report has a higher success rate
    than ``baseline``'s ("ahead"), and where its Wilson 95% interval lies wholly above the
    baseline's ("separated": disjoint 95% intervals, much stricter than a 95% test), with each
    task's two-sided two-proportion p-value: the C-Steve-1 issue's test against unconditioned
    C-VPT."""
    tasks = [t for t in agent if t in baseline]
    return {
        "tasks": tasks,
        "ahead": [t for t in tasks if agent[t]["success_percent"] > baseline[t]["success_percent"]],
        "separated": [t for t in tasks if disjoint_above(agent[t]["wilson95_percent"],
                                                         baseline[t]["wilson95_percent"])],
        "p_two_proportion": {t: two_proportion_p(agent[t]["successes"], agent[t]["episodes"],
                                                 baseline[t]["successes"], baseline[t]["episodes"])
                             for t in tasks},
    }
