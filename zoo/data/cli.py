"""`zoo data generate|dagger|merge|info` (and `zoo data caption` when zoo.captions provides it)."""

from __future__ import annotations

import argparse
import importlib
import importlib.util
import json
import sys
from pathlib import Path

from zoo.agents import AGENT_NAMES, AgentSpec
from zoo.agents.spec import add_agent_flags
from zoo.argtypes import add_out_flag, add_progress_flag, existing_dir, positive_int, shard_range
from zoo.envs.flags import (
    REQUIRED, add_episodes_flag, add_game_flag, add_max_steps_flag, add_num_envs_flag,
    add_seed_flag,
)
from zoo.envs.tasks.starts import START_STATES


def _expert_option(text: str) -> tuple[str, object]:
    """KEY=VALUE for an ExpertConfig field, VALUE parsed to the field's type."""
    from dataclasses import fields

    from zoo.experts.scripted.config import ExpertConfig

    key, sep, raw = text.partition("=")
    types = {f.name: type(f.default) for f in fields(ExpertConfig)}
    if not sep or key not in types:
        raise argparse.ArgumentTypeError(
            f"expected KEY=VALUE with KEY one of {sorted(types)}, got {text!r}"
        )
    kind = types[key]
    if kind is bool:
        if raw.lower() not in ("true", "false"):
            raise argparse.ArgumentTypeError(f"{key} takes true or false, got {raw!r}")
        return key, raw.lower() == "true"
    try:
        return key, kind(raw)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{key} takes {kind.__name__} values, got {raw!r}") from None


def register(subparsers) -> None:
    data = subparsers.add_parser(
        "data", help="CrafterPlay datasets: generate, dagger, merge, info; CrafterCaption: caption"
    )
    data.set_defaults(handler=lambda args: data.print_help() or 2)
    data_sub = data.add_subparsers(dest="data_command", metavar="DATA_COMMAND")

    gen = data_sub.add_parser(
        "generate",
        help="play an expert and write CrafterPlay shards (resumable, deterministic)",
        description="Write DIR/crafterplay-NNNNNN.tar and DIR/manifest.json. Rerun the same "
        "command after an interruption to finish the dataset.",
    )
    gen.add_argument("--expert", required=True, choices=AGENT_NAMES)
    gen.add_argument("--checkpoint", help="expert checkpoint (needed by --expert ppo)")
    gen.add_argument("--expert-option", action="append", default=[], type=_expert_option,
                     metavar="KEY=VALUE",
                     help="override a scripted-expert tunable (zoo/experts/scripted/config.py), "
                     "e.g. plants_first=true; repeatable; recorded in the manifest")
    _add_instruction_args(gen)
    gen.add_argument("--start-states", choices=START_STATES, default="default",
                     help="default: the game's start; tasks: each episode starts with one of the "
                     "task suites' starting inventories (drawn from its seed)")
    _add_play_args(gen)
    gen.set_defaults(handler=_generate, _parser=gen)

    dagger = data_sub.add_parser(
        "dagger",
        help="DAgger rollouts: a C-VPT or C-Steve-1 plays, the scripted expert labels every state",
        description="Write CrafterPlay shards whose actions are the expert's labels of the "
        "states the learner reached (manifest: config.dagger with round, learner sha256, beta). "
        "Resumable and deterministic like `zoo data generate`; train on them together with "
        "the expert data through the datamodule's `sources`. With --instructions the expert "
        "follows a schedule and a C-Steve-1 learner is told the same instruction (goal-directed "
        "DAgger). See docs/dagger.md.",
    )
    add_agent_flags(dagger, agent=None, required=True, temperature=1.0,
                    checkpoint="the learner: a C-VPT or C-Steve-1 .ckpt from zoo fit or a zoo "
                    "export folder")
    dagger.add_argument("--expert", choices=("scripted",), default="scripted",
                        help="the labeller (it must read the state)")
    dagger.add_argument("--beta", type=float, default=0.0,
                        help="probability that the expert acts instead of the learner")
    dagger.add_argument("--mix", choices=("episode", "step"), default="episode",
                        help="one beta draw per episode or per step")
    dagger.add_argument("--round", type=int, default=1, help="DAgger round, for the manifest")
    _add_instruction_args(dagger, learner=True)
    _add_play_args(dagger)
    dagger.set_defaults(handler=_dagger, _parser=dagger)

    merge = data_sub.add_parser(
        "merge",
        help="join the shard-range folders of a job array (generate --shards A:B) into one",
        description="Hard-link (or copy) every shard of the SRC folders into --out and write one "
        "manifest. Refuses folders made with other generation arguments and shard indices that "
        "appear twice; checks every shard's sha256; says which shards no folder has yet.",
    )
    merge.add_argument("src", nargs="+", type=existing_dir, help="shard-range folders")
    add_out_flag(merge, "the merged dataset folder")
    merge.set_defaults(handler=_merge)

    info = data_sub.add_parser("info", help="counts, noop ratios, unlock rates; verify sha256")
    info.add_argument("dir", type=existing_dir, help="dataset folder")
    info.add_argument("--skip-corrupt", action="store_true",
                      help="report shards failing their checksum and summarise the rest (exit 0)")
    info.add_argument("--json", action="store_true", help="print JSON")
    info.set_defaults(handler=_info)

    if importlib.util.find_spec("zoo.captions.cli") is not None:
        importlib.import_module("zoo.captions.cli").register_data_commands(data_sub)


def _add_instruction_args(parser: argparse.ArgumentParser, learner: bool = False) -> None:
    """``--instructions`` and its timeout, shared by `generate` and `dagger`."""
    told = " (a C-Steve-1 learner is told the same instruction)" if learner else ""
    parser.add_argument("--instructions", metavar="captions|subgoals|FILE",
                        help="goal-directed play: tell the scripted expert one caption after "
                        "another, drawn from captions (all it follows), subgoals (the task "
                        "suites' sub-goals) or FILE (one caption per line, or 'caption | weight' "
                        f"to draw it more often); every step records its caption id{told}")
    parser.add_argument("--instruction-timeout", type=positive_int, default=300, metavar="N",
                        help="actions spent on an instruction before the next is drawn "
                        "(with --instructions)")


def _add_play_args(parser: argparse.ArgumentParser) -> None:
    """Arguments shared by `generate` and `dagger`: how many episodes, where, how."""
    add_episodes_flag(parser, default=REQUIRED)
    add_seed_flag(parser, default=REQUIRED)
    add_out_flag(parser, "dataset folder")
    parser.add_argument("--workers", type=positive_int, default=1, help="shard processes")
    add_game_flag(parser, default="craftax")
    parser.add_argument("--episodes-per-shard", type=positive_int, default=16)
    parser.add_argument("--chunk-length", type=positive_int, default=256, help="steps per sample")
    add_max_steps_flag(parser, default=10_000)
    add_num_envs_flag(parser, default=8)
    parser.add_argument("--frames", choices=("stored", "rendered"), default="stored",
                        help="stored: frames as images; rendered (--env craftax only): residuals "
                        "against re-renders from the stored state, far fewer bytes, "
                        "re-rendered when read (docs/data.md)")
    parser.add_argument("--shards", type=shard_range,
                        help="A:B: write only shards A..B-1 (one task of a job array; join the "
                        "folders with `zoo data merge`)")
    add_progress_flag(parser)


def _check_frames(args) -> None:
    if args.frames == "rendered" and args.env != "craftax":
        args._parser.error(
            f"--frames rendered needs --env craftax (a Craftax frame is a function of the stored "
            f"state; a {args.env} frame is not), got --env {args.env}; use --frames stored"
        )


def _generate(args) -> int:
    from zoo.data.generate import GenerationConfig

    checkpoint = None
    if args.checkpoint is not None:
        if not Path(args.checkpoint).exists():
            args._parser.error(f"--checkpoint {args.checkpoint} does not exist")
        checkpoint = str(Path(args.checkpoint).resolve())
    elif args.expert == "ppo":
        args._parser.error("--expert ppo needs --checkpoint PATH")
    if args.expert_option and args.expert != "scripted":
        args._parser.error(f"--expert-option applies to --expert scripted, not {args.expert}")
    if args.expert_option:
        from zoo.experts.scripted.config import ExpertConfig

        try:
            ExpertConfig(**dict(args.expert_option))
        except ValueError as err:
            args._parser.error(f"--expert-option: {err}")
    if args.instructions is not None and args.expert != "scripted":
        args._parser.error(f"--instructions needs --expert scripted, not {args.expert}")
    _check_frames(args)
    config = GenerationConfig(
        expert=args.expert, checkpoint=checkpoint, episodes=args.episodes, seed=args.seed,
        env=args.env, episodes_per_shard=args.episodes_per_shard,
        chunk_length=args.chunk_length, max_steps=args.max_steps, frames=args.frames,
        expert_options=dict(args.expert_option), instructions=_schedule(args),
        start_states=args.start_states,
    )
    return _run_generation(config, args, "generate")


def _schedule(args):
    """``--instructions``' schedule (None without it); a bad one is a usage error."""
    if args.instructions is None:
        return None
    from zoo.agents.instructions import instruction_schedule

    try:
        return instruction_schedule(args.instructions, args.instruction_timeout)
    except ValueError as err:
        args._parser.error(f"--instructions: {err}")


def _learner(args):
    """The learner's ``AgentSpec``, checked: a C-VPT, or a C-Steve-1 told a schedule that it
    can read (its goal models given, or recorded in its export)."""
    if args.temperature <= 0:
        args._parser.error(f"--temperature must be > 0, got {args.temperature}")
    try:
        spec = AgentSpec.from_args(args)
        if spec.kind not in ("cvpt", "csteve1"):
            raise ValueError(f"--checkpoint {args.checkpoint} holds a {spec.kind} agent; the "
                             "learner must be a C-VPT or C-Steve-1")
        if spec.kind == "csteve1":
            if args.instructions is None:
                raise ValueError("a C-Steve-1 learner needs --instructions: the schedule it is "
                                 "told")
            spec.require_text()
    except ValueError as err:
        args._parser.error(str(err))
    return spec


def _dagger(args) -> int:
    import os

    from zoo.data.generate import GenerationConfig
    from zoo.data.shard_generator import DaggerSettings

    if not 0.0 <= args.beta <= 1.0:
        args._parser.error(f"--beta must be in [0, 1], got {args.beta}")
    _check_frames(args)
    learner = _learner(args)
    config = GenerationConfig(
        expert=args.expert, episodes=args.episodes, seed=args.seed, env=args.env,
        episodes_per_shard=args.episodes_per_shard, chunk_length=args.chunk_length,
        max_steps=args.max_steps, frames=args.frames, instructions=_schedule(args),
        dagger=DaggerSettings(learner=learner.record(), beta=args.beta, mix=args.mix,
                              round=args.round),
    )
    if args.workers > 1:  # each spawned worker runs the learner: share the cores, not oversubscribe
        os.environ.setdefault("OMP_NUM_THREADS", str(max(1, (os.cpu_count() or 1) // args.workers)))
    return _run_generation(config, args, "dagger")


def _run_generation(config, args, command: str) -> int:
    from zoo.agents import dataset_agent
    from zoo.data.generate import generate
    from zoo.data.manifest import DatasetMismatchError

    if args.shards is not None and args.shards[0] >= config.num_shards:
        args._parser.error(
            f"--shards {args.shards[0]}:{args.shards[1]} holds none of the dataset's shards "
            f"0:{config.num_shards}"
        )
    try:
        manifest = generate(config, args.out, args.workers, args.num_envs, not args.no_progress,
                            shards=args.shards, build_agent=dataset_agent)
    except DatasetMismatchError as err:
        print(f"zoo data {command}: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("interrupted; rerun the same command to finish the dataset", file=sys.stderr)
        return 130
    steps = sum(e["steps"] for e in manifest["shards"])
    shards = len(manifest["shards"])
    episodes = sum(e["episodes"] for e in manifest["shards"])
    print(f"{args.out}: {shards} of {config.num_shards} shards, {episodes} episodes, {steps} steps")
    if config.dagger is not None:
        agreement = sum(e["dagger"]["learner_agreement"] * e["steps"] for e in manifest["shards"])
        print(f"learner agreed with the expert's label on {agreement / max(steps, 1):.1%} of steps")
    return 0


def _merge(args) -> int:
    from zoo.data.manifest import DatasetMismatchError
    from zoo.data.merge import merge_datasets

    try:
        manifest = merge_datasets(args.src, args.out)
    except (DatasetMismatchError, FileNotFoundError, ValueError) as err:
        print(f"zoo data merge: {err}", file=sys.stderr)
        return 2
    steps = sum(e["steps"] for e in manifest["shards"])
    print(f"{args.out}: {len(manifest['shards'])} shards, {steps} steps")
    if manifest["missing"]:
        print(f"zoo data merge: shards {manifest['missing']} are in no folder yet: run their "
              "--shards jobs and merge again", file=sys.stderr)
        return 1
    return 0


def _info(args) -> int:
    from zoo.data.info import dataset_info, format_info

    try:
        info = dataset_info(args.dir, skip_corrupt=args.skip_corrupt)
    except (FileNotFoundError, ValueError) as err:
        print(f"zoo data info: {err}", file=sys.stderr)
        return 2
    print(json.dumps(info, indent=1) if args.json else format_info(info))
    if not info["ok"]:
        for bad in info["bad_shards"]:
            print(f"zoo data info: checksum failed: {bad['file']} ({bad['why']})", file=sys.stderr)
        return 1
    return 0
