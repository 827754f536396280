"""C-Steve-1's results protocol: who solves the single-step tasks, and how CFG helps (the
tables of docs/results/csteve1.md).

``table`` (``zoo tables task-table``), per game and single-step task: random play, unconditioned
C-VPT (the backbone C-Steve-1 was trained from), C-Steve-1 given the task's own instruction, and
C-Steve-1 given a *different* task's instruction (the control: if that scores like the right
one, the agent follows its prior, not the words). ``sweep`` (``zoo tables cfg-sweep``): C-Steve-1
on the paper's four CFG tasks at several guidance scales, plotted. ``goals`` (``zoo eval
goal-check``) checks the goal pipeline without playing: does the prior's goal for each task
instruction land nearest that caption's video embeddings (``zoo.eval.goal_check``)?

Every cell is a ``zoo eval --task`` report at OUT/<env>/<task>/<row>/report.json (episode j
seeded from (seed, j), so rows share worlds); a cell whose report exists is read, not played,
so a rerun continues where a killed one stopped. The summary is OUT/summary_<mode>.md and .json;
a table ends with how many tasks C-Steve-1 wins against C-VPT (``compare_success``).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, replace
from pathlib import Path

from zoo.agents import AgentSpec
from zoo.agents.base import Agent
from zoo.envs.tasks import TASKS, make_task_env
from zoo.eval.stats import p_text
from zoo.eval.task_eval import compare_success, evaluate_task, write_task_report

# The control instruction of each task: another task's, chosen to ask for something else
# (collect <-> craft), so following it cannot complete the task by accident.
OTHER_INSTRUCTION = {
    "collect_sapling": "obtain drink",
    "collect_drink": "obtain sapling",
    "make_wood_pickaxe": "obtain sapling",
    "make_wood_sword": "obtain drink",
    "make_stone_pickaxe": "obtain sapling",
    "make_stone_sword": "obtain drink",
}
TABLE_ROWS = ("random", "cvpt", "csteve1", "csteve1_other")
STEVE_ROWS = ("csteve1", "csteve1_other")
CFG_TASKS = ("collect_sapling", "collect_drink", "make_wood_pickaxe", "make_wood_sword")
SUMMARY_HEADER = (
    "| game | task | agent | instruction | success % (Wilson 95%) | median steps | episodes |\n"
    "|---|---|---|---|---|---|---|\n"
)


@dataclass(frozen=True)
class Setting:
    """What every cell of a table shares, so its rows play the same worlds."""

    out: Path
    envs: tuple[str, ...]
    episodes: int
    seed: int
    num_envs: int
    temperature: float | None  # the C-VPT row's (C-Steve-1's is its spec's)
    csteve1: AgentSpec | None = None  # C-Steve-1 reading text (its goal models given or its own)

    @property
    def batch(self) -> int:
        """Envs played at once: never more than there are episodes."""
        return min(self.num_envs, self.episodes)

    def steve(self, cfg_scale: float | None) -> Agent:
        """C-Steve-1 at guidance ``cfg_scale`` (None: its spec's, else its export's)."""
        if self.csteve1 is None:
            raise ValueError("C-Steve-1 rows need --csteve1")
        spec = self.csteve1 if cfg_scale is None else replace(self.csteve1, cfg_scale=cfg_scale)
        return spec.build(self.batch)

    def cell(
        self, env_name: str, task: str, row: str, agent: Agent, instruction: str | None
    ) -> dict:
        """One row's ``zoo eval --task`` report on one game and task; an existing one is read."""
        out = self.out / env_name / task / row
        if (out / "report.json").is_file():  # a rerun continues where a killed one stopped
            return json.loads((out / "report.json").read_text())
        env = make_task_env(TASKS[task], env_name, self.batch, pixels=True)
        start = time.perf_counter()
        results, rollouts = evaluate_task(
            agent, env, self.episodes, self.seed, instruction=instruction
        )
        meta = {
            "task": task, "env": env_name, "agent": row, "instruction": instruction,
            "instructions": list(TASKS[task].instructions), "seed": self.seed,
            "max_steps": TASKS[task].max_steps, "seconds": time.perf_counter() - start,
            "instruction_mode": "single instruction" if instruction else "none",
            **getattr(agent, "inference", {}),  # C-Steve-1's scale and temperature as played
        }
        return write_task_report(results, rollouts, out, meta)


def table(
    setting: Setting,
    tasks: list[str],
    rows: list[str],
    cvpt: Path | None,
    cfg_scale: float | None,
) -> list[dict]:
    """The ``rows`` of each task in each game (``rows`` from TABLE_ROWS; the cvpt row needs
    ``cvpt``, the C-Steve-1 rows the setting's checkpoints)."""
    agents: dict[str, Agent] = {}
    if "random" in rows:
        agents["random"] = AgentSpec("random").build(setting.batch)
    if "cvpt" in rows:
        agents["cvpt"] = AgentSpec("cvpt", cvpt, setting.temperature).build(setting.batch)
    if set(STEVE_ROWS) & set(rows):
        agents["csteve1"] = agents["csteve1_other"] = setting.steve(cfg_scale)
    summary = []
    for env_name in setting.envs:
        for task in tasks:
            instructions = {"csteve1": TASKS[task].instructions[0],
                            "csteve1_other": OTHER_INSTRUCTION[task]}
            for row in rows:
                instruction = instructions.get(row)
                report = setting.cell(env_name, task, row, agents[row], instruction)
                summary.append(_row(env_name, task, row, instruction, report))
                print(_line(summary[-1]), flush=True)
    return summary


def sweep(setting: Setting, cfg_scales: list[float]) -> list[dict]:
    """C-Steve-1 on CFG_TASKS at each guidance scale; plotted to OUT/cfg_sweep.png."""
    summary = []
    for scale in cfg_scales:
        steve = setting.steve(scale)
        for env_name in setting.envs:
            for task in CFG_TASKS:
                row, instruction = f"csteve1_cfg{scale:g}", TASKS[task].instructions[0]
                report = setting.cell(env_name, task, row, steve, instruction)
                summary.append(
                    {**_row(env_name, task, row, instruction, report), "cfg_scale": scale}
                )
                print(_line(summary[-1]), flush=True)
    _plot_sweep(summary, setting.out / "cfg_sweep.png")
    return summary


def goals(
    cclip: Path, prior: Path, embeddings: Path, max_shards: int, min_count: int, samples: int
) -> list[dict]:
    """Per task instruction: the rank of its caption among the caption centroids (per-caption
    means over the first ``max_shards`` shards of a ``zoo goals embed`` folder; captions with
    fewer than ``min_count`` steps have none) nearest the prior's mean goal, and the share of
    ``samples`` sampled goals whose nearest centroid is its caption."""
    import torch

    from zoo.agents.csteve1_agent import GoalEncoder
    from zoo.captions.vocabulary import load_vocabulary
    from zoo.eval.goal_check import caption_centroids, nearest_captions, rank_of_caption
    from zoo.goals.embed import read_embedding_shard

    texts = load_vocabulary().texts()
    shards = sorted(embeddings.glob("embed-*.tar"))[:max_shards]
    if not shards:
        raise FileNotFoundError(f"no embed-*.tar shards in {embeddings}")
    episodes = (e for path in shards for e in read_embedding_shard(path).values())
    centroids, counts = caption_centroids(episodes, len(texts))
    present = torch.tensor(counts >= min_count)
    mean_goal = GoalEncoder.load(cclip, prior, sample_prior=False)
    sampled = GoalEncoder(mean_goal.cclip, mean_goal.prior, sample_prior=True)  # load once
    summary = []
    for text in sorted({s.instruction for t in TASKS.values() for s in t.subtasks}):
        i = texts.index(text)
        goal = mean_goal.from_text([text])[0]
        draws = torch.cat([sampled.from_text([text], seed=k) for k in range(samples)])
        summary.append({
            "instruction": text, "caption_steps": int(counts[i]),
            "rank_of_mean_goal": rank_of_caption(centroids, goal, i, present) if present[i]
            else None,
            "nearest": texts[int(nearest_captions(centroids, goal[None], present)[0])],
            "sampled_nearest_share": float((nearest_captions(centroids, draws, present) == i)
                                           .float().mean()) if present[i] else None,
        })
        print(summary[-1], flush=True)
    return summary


def write_summary(out: Path, mode: str, rows: list[dict]) -> list[Path]:
    """OUT/summary_<mode>.json, and for the played modes the markdown table (a ``table`` ends
    with ``versus_cvpt``); returns the files written."""
    written = [out / f"summary_{mode}.json"]
    if mode != "goals":
        lines = [SUMMARY_HEADER, *(_line(r) + "\n" for r in rows)]
        if mode == "table":
            lines += ["\n", *(line + "\n" for line in versus_cvpt(rows))]
        written.insert(0, out / f"summary_{mode}.md")
        written[0].write_text("".join(lines))
    written[-1].write_text(json.dumps(rows, indent=2) + "\n")
    return written


def versus_cvpt(rows: list[dict]) -> list[str]:
    """Per game, the verdict: on how many tasks the instructed C-Steve-1 beats the
    unconditioned C-VPT, on how many with disjoint Wilson 95% intervals, and each task's
    two-proportion p-value (38/50 vs 27/50: intervals overlap, yet p = 0.021)."""
    lines = []
    for env_name in sorted({r["env"] for r in rows}):
        by_agent = {a: {r["task"]: r for r in rows if r["env"] == env_name and r["agent"] == a}
                    for a in ("csteve1", "cvpt")}
        result = compare_success(by_agent["csteve1"], by_agent["cvpt"])
        lines.append(
            f"{env_name}: C-Steve-1 ahead of C-VPT on {len(result['ahead'])} of "
            f"{len(result['tasks'])} tasks ({', '.join(result['ahead']) or '-'}), disjoint 95% "
            f"intervals on {len(result['separated'])} ({', '.join(result['separated']) or '-'}); "
            "two-proportion p: " + (", ".join(f"{t} {p_text(p)}" for t, p in
                                               result["p_two_proportion"].items()) or "-")
        )
    return lines


def _row(env_name: str, task: str, row: str, instruction: str | None, report: dict) -> dict:
    return {
        "env": env_name, "task": task, "agent": row, "instruction": instruction,
        "episodes": report["episodes"], "successes": report["successes"],
        "success_percent": report["success_percent"],
        "wilson95_percent": report["wilson95_percent"],
        "median_steps_to_success": report["median_steps_to_success"],
    }


def _line(r: dict) -> str:
    low, high = r["wilson95_percent"]
    steps = "-" if r["median_steps_to_success"] is None else f"{r['median_steps_to_success']:g}"
    return (f"| {r['env']} | {r['task']} | {r['agent']} | {r['instruction'] or '-'} | "
            f"{r['success_percent']:.0f} ({low:.0f}-{high:.0f}) | {steps} | {r['episodes']} |")


def _plot_sweep(rows: list[dict], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    envs = sorted({r["env"] for r in rows})
    fig, axes = plt.subplots(1, len(envs), figsize=(5 * len(envs), 3.5), squeeze=False)
    for ax, env_name in zip(axes[0], envs, strict=True):
        for task in CFG_TASKS:
            points = sorted((r["cfg_scale"], r["success_percent"]) for r in rows
                            if r["env"] == env_name and r["task"] == task)
            ax.plot(*zip(*points, strict=True), marker="o", label=task)
        ax.set(title=env_name, xlabel="guidance scale λ", ylabel="success %", ylim=(-2, 102))
        ax.grid(alpha=0.3)
    axes[0][-1].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
