"""The C-Steve-1 task tables of docs/results.md: who solves the single-step tasks, and how CFG helps.

``table`` mode, per game and single-step task: random play, unconditioned C-VPT (the backbone
C-Steve-1 was trained from), C-Steve-1 given the task's own instruction, and C-Steve-1 given a
*different* task's instruction (the control: if that scores like the right one, the agent
follows its prior, not the words). ``sweep`` mode: C-Steve-1 on the paper's four CFG tasks at
several guidance scales, plotted. ``goals`` mode checks the goal pipeline without playing:
does the prior's goal for each task instruction land nearest that caption's video embeddings
(per-caption means over a ``zoo goals embed`` folder)? Every cell is a ``zoo eval --task``
report under OUT (episode j seeded from (seed, j), so rows share worlds); the summary is
OUT/summary_<mode>.md and .json, and a table ends with how many tasks C-Steve-1 wins against
C-VPT (``compare_success``).

  .venv/bin/python scripts/steve_tasks.py table --cvpt C.ckpt --csteve1 S.ckpt --cclip CC.ckpt \
      --prior P.ckpt --env craftax crafter --episodes 100 --out runs/steve_tasks
  .venv/bin/python scripts/steve_tasks.py sweep ... --cfg-scales 0 0.5 1 1.5 2 3
  .venv/bin/python scripts/steve_tasks.py goals --cclip CC --prior P --embeddings DIR --out ...
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from zoo.agents import make_agent
from zoo.envs.tasks import SINGLE_STEP_TASKS, TASKS, make_task_env
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
CFG_TASKS = ("collect_sapling", "collect_drink", "make_wood_pickaxe", "make_wood_sword")


def run_cell(args, env_name: str, task: str, row: str, agent, instruction: str | None) -> dict:
    out = args.out / env_name / task / row
    if (out / "report.json").is_file():  # a rerun continues where a killed one stopped
        return json.loads((out / "report.json").read_text())
    env = make_task_env(TASKS[task], env_name, min(args.num_envs, args.episodes), pixels=True)
    start = time.perf_counter()
    results, rollouts = evaluate_task(agent, env, args.episodes, args.seed, instruction=instruction)
    meta = {
        "task": task, "env": env_name, "agent": row, "instruction": instruction,
        "instructions": list(TASKS[task].instructions), "seed": args.seed,
        "max_steps": TASKS[task].max_steps, "seconds": time.perf_counter() - start,
        "instruction_mode": "single instruction" if instruction else "none",
    }
    return write_task_report(results, rollouts, out, meta)


def steve_agent(args, num_envs: int, cfg_scale: float):
    return make_agent(
        "csteve1", num_envs, str(args.csteve1), args.temperature, cclip=str(args.cclip),
        prior=str(args.prior), cfg_scale=cfg_scale,
    )


def table(args) -> list[dict]:
    n = min(args.num_envs, args.episodes)
    agents = {}
    if "random" in args.rows:
        agents["random"] = make_agent("random", n)
    if "cvpt" in args.rows:
        agents["cvpt"] = make_agent("cvpt", n, str(args.cvpt), args.temperature)
    if {"csteve1", "csteve1_other"} & set(args.rows):
        agents["csteve1"] = agents["csteve1_other"] = steve_agent(args, n, args.cfg_scale)
    rows = []
    for env_name in args.env:
        for task in args.tasks:
            instructions = {"csteve1": TASKS[task].instructions[0],
                            "csteve1_other": OTHER_INSTRUCTION[task]}
            for row in args.rows:
                report = run_cell(args, env_name, task, row, agents[row], instructions.get(row))
                rows.append(_row(env_name, task, row, instructions.get(row), report))
                print(_line(rows[-1]), flush=True)
    return rows


def sweep(args) -> list[dict]:
    n = min(args.num_envs, args.episodes)
    rows = []
    for scale in args.cfg_scales:
        steve = steve_agent(args, n, scale)
        for env_name in args.env:
            for task in CFG_TASKS:
                row = f"csteve1_cfg{scale:g}"
                report = run_cell(args, env_name, task, row, steve, TASKS[task].instructions[0])
                rows.append({**_row(env_name, task, row, TASKS[task].instructions[0], report),
                             "cfg_scale": scale})
                print(_line(rows[-1]), flush=True)
    _plot_sweep(rows, args.out / "cfg_sweep.png")
    return rows


def goals(args) -> list[dict]:
    """Per task instruction: the rank of its caption among the caption centroids nearest the
    prior's mean goal, and the share of sampled goals whose nearest centroid is its caption."""
    import torch

    from zoo.agents.steve_agent import GoalEncoder
    from zoo.captions.vocabulary import load_vocabulary
    from zoo.goals.embed import read_embedding_shard
    from zoo.eval.goal_check import caption_centroids, nearest_captions, rank_of_caption

    texts = load_vocabulary().texts()
    shards = sorted(args.embeddings.glob("embed-*.tar"))[: args.max_shards]
    if not shards:
        raise SystemExit(f"no embed-*.tar shards in {args.embeddings}")
    episodes = (e for path in shards for e in read_embedding_shard(path).values())
    centroids, counts = caption_centroids(episodes, len(texts))
    present = torch.tensor(counts >= args.min_count)
    mean_goal = GoalEncoder.load(args.cclip, args.prior, sample_prior=False)
    sampled = GoalEncoder(mean_goal.cclip, mean_goal.prior, sample_prior=True)  # load once
    rows = []
    for text in sorted({s.instruction for t in TASKS.values() for s in t.subtasks}):
        i = texts.index(text)
        goal = mean_goal.from_text([text])[0]
        draws = torch.cat([sampled.from_text([text], seed=k) for k in range(args.samples)])
        rows.append({
            "instruction": text, "caption_steps": int(counts[i]),
            "rank_of_mean_goal": rank_of_caption(centroids, goal, i, present) if present[i]
            else None,
            "nearest": texts[int(nearest_captions(centroids, goal[None], present)[0])],
            "sampled_nearest_share": float((nearest_captions(centroids, draws, present) == i)
                                           .float().mean()) if present[i] else None,
        })
        print(rows[-1], flush=True)
    return rows


def versus_cvpt(rows: list[dict]) -> list[str]:
    """Per game, the issue's test: on how many tasks the instructed C-Steve-1 beats the
    unconditioned C-VPT, and on how many with separated Wilson 95% intervals."""
    lines = []
    for env_name in sorted({r["env"] for r in rows}):
        by_agent = {a: {r["task"]: r for r in rows if r["env"] == env_name and r["agent"] == a}
                    for a in ("csteve1", "cvpt")}
        result = compare_success(by_agent["csteve1"], by_agent["cvpt"])
        lines.append(
            f"{env_name}: C-Steve-1 ahead of C-VPT on {len(result['ahead'])} of "
            f"{len(result['tasks'])} tasks ({', '.join(result['ahead']) or '-'}), separated 95% "
            f"intervals on {len(result['separated'])} ({', '.join(result['separated']) or '-'})"
        )
    return lines


def _row(env_name: str, task: str, row: str, instruction: str | None, report: dict) -> dict:
    return {
        "env": env_name, "task": task, "agent": row, "instruction": instruction,
        "episodes": report["episodes"], "success_percent": report["success_percent"],
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("mode", choices=("table", "sweep", "goals"))
    parser.add_argument("--cvpt", type=Path, help="C-VPT checkpoint (table mode)")
    parser.add_argument("--csteve1", type=Path, help="C-Steve-1 checkpoint or export")
    parser.add_argument("--cclip", type=Path, help="C-CLIP of C-Steve-1's goals")
    parser.add_argument("--prior", type=Path, help="CVAE prior: text -> goal")
    parser.add_argument("--env", nargs="+", default=["craftax", "crafter"])
    parser.add_argument("--tasks", nargs="+", default=list(SINGLE_STEP_TASKS))
    parser.add_argument("--episodes", type=int, default=100)
    parser.add_argument("--rows", nargs="+", choices=TABLE_ROWS, default=list(TABLE_ROWS),
                        help="table rows to run (e.g. the baselines while C-Steve-1 trains)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--num-envs", type=int, default=20)
    parser.add_argument("--temperature", type=float, default=1.0)
    parser.add_argument("--cfg-scale", type=float, default=1.5)
    parser.add_argument("--cfg-scales", type=float, nargs="+", default=[0, 0.5, 1, 1.5, 2, 3])
    parser.add_argument("--embeddings", type=Path, help="zoo goals embed folder (goals mode)")
    parser.add_argument("--max-shards", type=int, default=12, help="goals mode: shards read")
    parser.add_argument("--min-count", type=int, default=50,
                        help="goals mode: captions with fewer steps have no centroid")
    parser.add_argument("--samples", type=int, default=20, help="goals mode: prior draws")
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    if args.mode == "goals":
        if None in (args.cclip, args.prior, args.embeddings):
            parser.error("goals mode needs --cclip, --prior and --embeddings")
        rows = goals(args)
        (args.out / "summary_goals.json").write_text(json.dumps(rows, indent=2) + "\n")
        return
    if args.mode == "table" and "cvpt" in args.rows and args.cvpt is None:
        parser.error("the cvpt row needs --cvpt (the unconditioned baseline)")
    steve_rows = args.mode == "sweep" or {"csteve1", "csteve1_other"} & set(args.rows)
    if steve_rows and None in (args.csteve1, args.cclip, args.prior):
        parser.error("C-Steve-1 rows need --csteve1, --cclip and --prior")
    rows = table(args) if args.mode == "table" else sweep(args)
    header = "| game | task | agent | instruction | success % (Wilson 95%) | median steps | episodes |\n"
    lines = [header, "|---|---|---|---|---|---|---|\n", *(_line(r) + "\n" for r in rows)]
    if args.mode == "table":
        lines += ["\n", *(line + "\n" for line in versus_cvpt(rows))]
    (args.out / f"summary_{args.mode}.md").write_text("".join(lines))
    (args.out / f"summary_{args.mode}.json").write_text(json.dumps(rows, indent=2) + "\n")


if __name__ == "__main__":
    main()
