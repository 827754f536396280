"""``zoo eval``: play an agent for N episodes and write the Crafter evaluation report, or, with
``--task``, its success on a task suite (``zoo.envs.tasks``); ``zoo tables``: many such
reports under one folder, C-Steve-1's results protocol (``zoo.eval.csteve1_tables``) and the
instruction matrix (``zoo.eval.instruction_matrix``)."""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import asdict
from datetime import UTC, datetime
from pathlib import Path

from zoo.agents import AgentSpec
from zoo.agents.spec import add_agent_flags
from zoo.argtypes import (add_out_flag, add_wandb_flag, existing_dir, non_negative_int,
                          positive_int)
from zoo.envs.flags import (
    add_episodes_flag, add_game_flag, add_max_steps_flag, add_num_envs_flag, add_seed_flag,
)
from zoo.envs.tasks import SINGLE_STEP_TASKS, TASKS
from zoo.eval.play import inference_meta
from zoo.eval.csteve1_tables import STEVE_ROWS, TABLE_ROWS
from zoo.weights.guidance import PAPER_CFG_SCALE

DESCRIPTION = """\
Play an agent in Craftax-Classic or original crafter and score it the paper's way: Crafter
Score and normalized Return as mean ± std over 5 chunks of the episodes (100 episodes = 5 x 20).
Writes OUT/report.json (also how episodes ended: survived, lava, zombie, arrow, a need at 0),
OUT/stats.jsonl (crafter's Recorder format), OUT/achievements.png and OUT/episode.gif. Episode j is seeded from (--seed, j), so --num-envs changes speed, not results.
Frames are rendered when the agent reads pixels or a GIF is wanted; a state-only expert with
--no-gif skips rendering, which plays several times faster. Several evaluations at once on a
few cores: export OMP_WAIT_POLICY=PASSIVE, or torch's spinning threads starve each other
(docs/results/benchmarks.md).

With --task NAME it plays a task instead (docs/tasks.md) and writes OUT/report.json and
OUT/report.md: success rate with a Wilson 95% interval, median steps to success, sub-task
completion, and how the failed episodes ended. An instructable agent gets --instruction after every reset, or with --chain the
heuristic planner's instructions; with neither, each sub-task's own caption in turn.

Many such reports under one OUT with a summary (C-Steve-1's task table, CFG sweep and goal
check; the instruction matrix of any instructable agent) are `zoo tables`.
"""
USAGE = "%(prog)s --env {craftax,crafter} (--agent NAME | --checkpoint PATH) [options]"
TABLES_DESCRIPTION = """\
Results tables: many `zoo eval` reports under one OUT and a summary. C-Steve-1's results
protocol (docs/results/csteve1.md): task-table, cfg-sweep, goal-check; and the instruction
matrix of any instructable agent: instructions. See `zoo tables TABLE --help`."""
PROTOCOLS = {  # subcommand -> (its summary's mode name, one-line help)
    "task-table": ("table", (
        "single-step tasks: random, C-VPT, C-Steve-1 with its instruction and with another task's"
    )),
    "cfg-sweep": ("sweep", "C-Steve-1 on the paper's four CFG tasks at several guidance scales"),
    "goal-check": ("goals", (
        "without playing: whether the prior's goal for each instruction lands nearest its caption"
    )),
}


class UsageError(Exception):
    """Bad arguments found after parsing; reported as ``zoo eval: error: ...`` with exit code 2."""


def register(subparsers) -> None:
    """Add ``zoo eval`` to the ``zoo`` command."""
    p = subparsers.add_parser(
        "eval",
        help="score an agent: Crafter Score, Return, success rates, GIF",
        description=DESCRIPTION,
        usage=USAGE,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    add_agent_flags(p)
    add_game_flag(p)
    add_episodes_flag(p)
    add_seed_flag(p)
    add_out_flag(p, "output folder", default="runs/eval/<agent>-<env>-<UTC time>")
    add_num_envs_flag(p, default=8)
    add_max_steps_flag(p, default=None, what="episode step limit (default 10000; with --task the "
                       "task's: 500 single-step, 1000 T1-T4)")
    p.add_argument("--no-gif", action="store_true", help="skip episode.gif")
    p.add_argument("--overwrite", action="store_true", help="replace a report already in --out")
    add_wandb_flag(p, "report, plot and GIF as a run")
    p.add_argument("--task", choices=sorted(TASKS), help="play this task and report its success")
    p.add_argument(
        "--instruction", metavar="TEXT",
        help="with --task: the caption given to an instructable agent after every reset",
    )
    p.add_argument(
        "--chain", action="store_true",
        help="with --task: the heuristic planner chains instructions to the agent",
    )
    p.add_argument(
        "--chain-coal-direct", action="store_true",
        help="with --chain: say 'obtain coal' from the start (the planner before 2026-12-08), "
        "not 'obtain stone' until coal is in view",
    )
    p.set_defaults(handler=run_eval)
    tables = subparsers.add_parser(
        "tables", help="results tables: C-Steve-1's task table, CFG sweep, goal check; the "
        "instruction matrix", description=TABLES_DESCRIPTION,
    )
    protocols = tables.add_subparsers(dest="protocol", metavar="TABLE", required=True)
    for name, (mode, line) in PROTOCOLS.items():
        sub = protocols.add_parser(name, help=line, description=_protocol_description(mode, line))
        add_out_flag(sub, "folder of all reports")
        sub.set_defaults(handler=run_protocol)
        ADD_PROTOCOL_ARGS[name](sub)
    _register_instruction_matrix(protocols)


def _protocol_description(mode: str, line: str) -> str:
    summary = f"Summary: OUT/summary_{mode}.json"
    if mode == "goals":
        return f"{line}. {summary}."
    return (
        f"{line}. Each cell is a `zoo eval --task` report at OUT/<env>/<task>/<row>/report.json "
        "(episode j seeded from (--seed, j), so rows play the same worlds); a rerun reads the "
        f"cells already reported instead of playing them. {summary} and .md."
    )


def _add_goal_models(p: argparse.ArgumentParser, required: bool) -> None:
    default = "" if required else " (default: the one the C-Steve-1 export records)"
    p.add_argument("--cclip", type=Path, required=required, metavar="CKPT",
                   help=f"C-CLIP of C-Steve-1's goals{default}")
    p.add_argument("--prior", type=Path, required=required, metavar="CKPT",
                   help=f"CVAE prior: text -> goal{default}")


def _add_play_args(p: argparse.ArgumentParser, steve_required: bool) -> None:
    """What the played protocols share: the games, episodes and C-Steve-1's checkpoints."""
    p.add_argument("--csteve1", type=Path, required=steve_required, metavar="CKPT",
                   help="C-Steve-1 checkpoint or export")
    _add_goal_models(p, required=False)
    _add_episode_args(p)


def _add_episode_args(p: argparse.ArgumentParser, temperature: bool = True) -> None:
    """The games and the episodes every row or cell plays (and the temperature, unless the
    agent flags declare it)."""
    add_game_flag(p, many=True)
    add_episodes_flag(p, what="episodes per cell")
    add_seed_flag(p)
    add_num_envs_flag(p, default=20)
    if temperature:
        p.add_argument("--temperature", type=float,
                       help="C-VPT and C-Steve-1 sample from softmax(logits / T) (default 1, or "
                       "the temperature a C-Steve-1 export records)")


def _add_table_args(p: argparse.ArgumentParser) -> None:
    _add_play_args(p, steve_required=False)
    p.add_argument("--cvpt", type=Path, metavar="CKPT", help="C-VPT checkpoint (the cvpt row)")
    p.add_argument("--tasks", nargs="+", choices=SINGLE_STEP_TASKS, metavar="TASK",
                   default=list(SINGLE_STEP_TASKS),
                   help=f"single-step tasks (default: all, {', '.join(SINGLE_STEP_TASKS)})")
    p.add_argument("--rows", nargs="+", choices=TABLE_ROWS, default=list(TABLE_ROWS),
                   metavar="ROW", help=f"table rows to run (default: all, {', '.join(TABLE_ROWS)}; "
                   "e.g. the baselines while C-Steve-1 trains)")
    p.add_argument("--cfg-scale", type=float,
                   help="C-Steve-1's classifier-free guidance scale (default: the scale its "
                   f"export records, else the paper's {PAPER_CFG_SCALE})")


def _add_sweep_args(p: argparse.ArgumentParser) -> None:
    _add_play_args(p, steve_required=True)
    p.add_argument("--cfg-scales", type=float, nargs="+", default=[0, 0.5, 1, 1.5, 2, 3],
                   help="guidance scales (default 0 0.5 1 1.5 2 3)")


def _add_goal_args(p: argparse.ArgumentParser) -> None:
    _add_goal_models(p, required=True)
    p.add_argument("--embeddings", type=existing_dir, required=True, metavar="DIR",
                   help="a `zoo goals embed` folder")
    p.add_argument("--max-shards", type=positive_int, default=12,
                   help="shards read (default 12)")
    p.add_argument("--min-count", type=non_negative_int, default=50,
                   help="captions with fewer steps have no centroid (default 50)")
    p.add_argument("--samples", type=positive_int, default=20,
                   help="prior draws per instruction (default 20)")


ADD_PROTOCOL_ARGS = {
    "task-table": _add_table_args, "cfg-sweep": _add_sweep_args, "goal-check": _add_goal_args,
}


def _check_out(out: Path, overwrite: bool) -> None:
    """A report already in ``out`` is kept unless told (argparse refused a file as ``out``)."""
    if (out / "report.json").exists() and not overwrite:
        raise UsageError(f"--out {out} already holds report.json; pass --overwrite to replace it")


def _build_agent(args: argparse.Namespace, num_envs: int):
    """The spec and agent named by --agent, or, with only --checkpoint, the one the checkpoint
    holds (``zoo.agents.AgentSpec``); on a task it must read instructions as text."""
    try:
        spec = AgentSpec.from_args(args)
        if args.task:
            spec.require_text()
        return spec, spec.build(num_envs)
    except (ValueError, FileNotFoundError) as err:  # a bad checkpoint names its file
        raise UsageError(str(err)) from None
    except ImportError as err:
        who = repr(args.agent) if args.agent else f"of {args.checkpoint}"
        raise UsageError(f"the agent {who} is not available in this install: {err}") from None


def _check_task_args(args: argparse.Namespace) -> None:
    if args.task is None:
        for flag, value in (("--instruction", args.instruction), ("--chain", args.chain),
                            ("--chain-coal-direct", args.chain_coal_direct)):
            if value:
                raise UsageError(f"{flag} needs --task NAME (one of {', '.join(sorted(TASKS))})")
    if args.instruction is not None and args.chain:
        raise UsageError("give --instruction or --chain, not both")
    if args.chain_coal_direct and not args.chain:
        raise UsageError("--chain-coal-direct changes the --chain planner; give --chain too")


def run_eval(args: argparse.Namespace) -> int:
    from zoo.envs import make_env
    from zoo.eval.report import format_table, write_report
    from zoo.eval.rollout import evaluate

    num_envs = min(args.num_envs, args.episodes)
    now = datetime.now(UTC)
    try:
        if args.out is None:
            who = args.agent or "checkpoint"
            what = args.env if args.task is None else f"{args.task}-{args.env}"
            args.out = Path("runs", "eval", f"{who}-{what}-{now:%Y%m%d-%H%M%S}")
        _check_task_args(args)
        _check_out(args.out, args.overwrite)
        spec, agent = _build_agent(args, num_envs)
        if args.task is not None:
            return run_task_eval(args, spec, agent, num_envs, now)
    except UsageError as err:
        print(f"zoo eval: error: {err}", file=sys.stderr)
        return 2
    args.max_steps = args.max_steps or 10_000
    started_at = now.isoformat(timespec="seconds")
    clock = time.perf_counter()
    pixels = not args.no_gif or getattr(agent, "needs_pixels", True)
    env = make_env(args.env, num_envs, pixels=pixels, max_steps=args.max_steps)
    results = evaluate(
        agent, env, args.episodes, args.seed, record_gif_episode=None if args.no_gif else 0
    )
    meta = {
        "env": args.env,
        "agent": args.agent or getattr(agent, "name", "checkpoint"),
        "checkpoint": None if args.checkpoint is None else str(args.checkpoint),
        **inference_meta(agent, args.temperature),
        "agent_spec": spec.record(),
        "seed": args.seed,
        "num_envs": num_envs,
        "max_steps": args.max_steps,
        "started_at": started_at,
        "finished_at": datetime.now(UTC).isoformat(timespec="seconds"),
        "wall_seconds": round(time.perf_counter() - clock, 2),
    }
    report = write_report(results, args.out, meta)
    print(format_table(report))
    _announce(args, report)
    return 0


def _announce(args: argparse.Namespace, report: dict) -> None:
    """Say what was written; with ``--wandb`` log it as a W&B run too."""
    print(f"wrote {', '.join(str(args.out / name) for name in report['files'])}")
    if args.wandb:
        from zoo.eval.wandb_log import log_report

        print(f"W&B run in {log_report(report, args.out)} (sync: wandb sync <that folder>)")


def run_task_eval(
    args: argparse.Namespace, spec: AgentSpec, agent, num_envs: int, now: datetime
) -> int:
    """``zoo eval --task``: success of ``agent`` on the task (see ``zoo.eval.task_eval``)."""
    from zoo.envs.tasks import make_task_env
    from zoo.eval.task_eval import evaluate_task, format_task_table, write_task_report

    task = TASKS[args.task]
    instructable = hasattr(agent, "instruct")
    played = inference_meta(agent, args.temperature)  # before chaining wraps the agent
    if (args.instruction is not None or args.chain) and not instructable:
        who = args.agent or args.checkpoint
        raise UsageError(f"agent {who} does not follow instructions (no instruct method)")
    planner: dict = {}  # the chaining planner's settings, recorded in the report
    if args.instruction is not None:
        mode = f"instruction {args.instruction!r}"
        try:  # an unknown text fails here, before any env is built
            agent.instruct([args.instruction] * num_envs)
        except ValueError as err:
            raise UsageError(f"--instruction: {err}") from None
        if getattr(agent, "name", None) == "csteve1":  # reads free text: say what it resembles
            from zoo.agents.csteve1_agent import instruction_note

            note = instruction_note(agent.goals, args.instruction)
            if note:
                print(f"zoo eval: note: {note}", file=sys.stderr)
    elif args.chain:
        from zoo.agents.chaining import ChainConfig, ChainingAgent

        chain = ChainConfig(coal_via_stone=not args.chain_coal_direct)
        agent, mode = ChainingAgent(agent, task, chain), "chained instructions"
        planner = {"chain_config": asdict(chain)}
    else:
        mode = "sub-task instructions" if instructable else "no instruction"
    clock = time.perf_counter()
    pixels = not args.no_gif or getattr(agent, "needs_pixels", True)
    env = make_task_env(task, args.env, num_envs, pixels=pixels, max_steps=args.max_steps)
    results, rollouts = evaluate_task(
        agent, env, args.episodes, args.seed,
        instruction=args.instruction,
        follow_subtasks=args.instruction is None and not args.chain and instructable,
        record_gif_episode=None if args.no_gif else 0,
    )
    meta = {
        "task": task.name,
        "instructions": list(task.instructions),
        "instruction_mode": mode,
        **planner,
        "env": args.env,
        "agent": args.agent or getattr(agent, "name", "checkpoint"),
        "checkpoint": None if args.checkpoint is None else str(args.checkpoint),
        **played,
        "agent_spec": spec.record(),
        "seed": args.seed,
        "num_envs": num_envs,
        "max_steps": args.max_steps or task.max_steps,
        "started_at": now.isoformat(timespec="seconds"),
        "finished_at": datetime.now(UTC).isoformat(timespec="seconds"),
        "wall_seconds": round(time.perf_counter() - clock, 2),
    }
    report = write_task_report(results, rollouts, args.out, meta)
    print(format_task_table(report))
    _announce(args, report)
    return 0


def run_protocol(args: argparse.Namespace) -> int:
    """``zoo tables task-table|cfg-sweep|goal-check``: C-Steve-1's results protocol, written by
    ``zoo.eval.csteve1_tables`` under --out with a summary_<mode>.md/.json."""
    from zoo.eval import csteve1_tables

    mode = PROTOCOLS[args.protocol][0]
    try:
        _check_protocol_args(args)
        args.out.mkdir(parents=True, exist_ok=True)
        if mode == "goals":
            try:
                rows = csteve1_tables.goals(args.cclip, args.prior, args.embeddings,
                                          args.max_shards, args.min_count, args.samples)
            except FileNotFoundError as err:  # a folder without shards
                raise UsageError(f"--embeddings: {err}") from None
        else:
            setting = csteve1_tables.Setting(
                args.out, tuple(args.env), args.episodes, args.seed, args.num_envs,
                args.temperature, _protocol_steve(args),
            )
            rows = (csteve1_tables.table(setting, args.tasks, args.rows, args.cvpt, args.cfg_scale)
                    if mode == "table" else csteve1_tables.sweep(setting, args.cfg_scales))
    except UsageError as err:
        print(f"zoo tables {args.protocol}: error: {err}", file=sys.stderr)
        return 2
    written = csteve1_tables.write_summary(args.out, mode, rows)
    print(f"wrote {', '.join(str(path) for path in written)}")
    return 0


def _check_protocol_args(args: argparse.Namespace) -> None:
    for flag in ("cvpt", "csteve1", "cclip", "prior"):
        path = getattr(args, flag, None)  # goal-check has no --cvpt or --csteve1
        if path is not None and not path.exists():
            raise UsageError(f"--{flag} {path} does not exist")
    if args.protocol != "task-table":
        return  # the other two require their checkpoints in the parser
    if "cvpt" in args.rows and args.cvpt is None:
        raise UsageError("the cvpt row needs --cvpt (the unconditioned baseline)")
    if set(STEVE_ROWS) & set(args.rows) and args.csteve1 is None:
        raise UsageError("C-Steve-1 rows need --csteve1")


def _protocol_steve(args: argparse.Namespace) -> AgentSpec | None:
    """The C-Steve-1 a table or sweep plays (None: no C-Steve-1 row), able to read text."""
    if args.csteve1 is None:
        return None
    try:
        spec = AgentSpec("csteve1", args.csteve1, args.temperature, cclip=args.cclip,
                         prior=args.prior)
        spec.require_text()
    except ValueError as err:
        raise UsageError(str(err)) from None
    return spec


def _register_instruction_matrix(protocols) -> None:
    """``zoo tables instructions``: for any instructable agent, named as ``zoo eval`` names it."""
    from zoo.eval import instruction_matrix as matrix
    p = protocols.add_parser("instructions", help=matrix.HELP, description=matrix.DESCRIPTION)
    add_agent_flags(p, agent="who plays (scripted: goal-directed; default: the agent "
                    "--checkpoint holds)", checkpoint="a trained agent, e.g. a C-Steve-1 export")
    _add_episode_args(p, temperature=False)
    add_max_steps_flag(p, default=200, what="L: steps per episode")
    p.add_argument("--horizons", type=positive_int, nargs="+", default=[], help=matrix.HORIZONS)
    p.add_argument("--instructions", nargs="+", help="some of the default instructions only")
    add_out_flag(p, "folder of the rows and report")
    p.set_defaults(handler=run_instruction_matrix)


def run_instruction_matrix(args: argparse.Namespace) -> int:
    """``zoo tables instructions``: play or read every row, then write the report."""
    from zoo.eval import instruction_matrix as matrix
    num_envs = min(args.num_envs, args.episodes)
    try:
        spec = AgentSpec.from_args(args)
        setting = matrix.Setting(spec, args.seed, args.episodes, args.max_steps)
        columns = matrix.pick_columns(args.instructions)
        agent, setting = matrix.make_instructable(setting, num_envs, columns)
        matrix.check_saved(args.out, args.env, columns, setting)
        horizons = matrix.check_horizons(args.horizons, args.max_steps)
    except ValueError as err:
        print(f"zoo tables instructions: error: {err}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    report = matrix.run(agent, setting, args.env, columns, args.out, num_envs, horizons)
    print(f"wrote {', '.join(str(args.out / name) for name in report['files'])}")
    return 0
