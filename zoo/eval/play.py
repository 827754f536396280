"""`zoo play`: watch an agent follow an instruction for one episode, as a GIF and a JSON log.

The GIF shows the instruction on every frame; the JSON lists which achievements were unlocked
at which step, the actions taken and how the episode ended, so a person can check at a glance
whether C-Steve-1 did what it was told. Given several instructions, each plays the same world
(the same seed) and the GIF shows them side by side: what changes is what the instruction did.
"""

from __future__ import annotations

import argparse
import json
import sys

import numpy as np

from zoo.agents.spec import add_agent_flags
from zoo.argtypes import add_out_flag
from zoo.envs.base import episode_seed
from zoo.envs.constants import ACHIEVEMENT_NAMES, ACTION_NAMES
from zoo.envs.flags import add_game_flag, add_max_steps_flag, add_seed_flag

CAPTION_BAR = 14  # pixels of the text bar above each (upscaled) frame


def caption_frames(frames: np.ndarray, text: str, scale: int = 2) -> np.ndarray:
    """Frames (T, H, W, 3) upscaled ``scale``x with ``text`` written in a bar above each."""
    from PIL import Image, ImageDraw

    frames = np.asarray(frames).repeat(scale, axis=1).repeat(scale, axis=2)
    t, _, w, _ = frames.shape
    bar = Image.new("RGB", (w, CAPTION_BAR), (0, 0, 0))
    ImageDraw.Draw(bar).text((3, 1), text, fill=(255, 255, 255))
    bar_pixels = np.asarray(bar, dtype=np.uint8)
    return np.concatenate([np.broadcast_to(bar_pixels, (t, *bar_pixels.shape)), frames], axis=1)


def side_by_side(clips: list[np.ndarray], gap: int = 4) -> np.ndarray:
    """Frames (T, H, W, 3) of several episodes as one (max T, H, n W + gaps, 3) movie; a
    shorter episode holds its last frame."""
    length = max(len(c) for c in clips)
    padded = [np.concatenate([c, np.repeat(c[-1:], length - len(c), axis=0)]) for c in clips]
    spacer = np.full((length, clips[0].shape[1], gap, 3), 255, np.uint8)
    tiles = [part for clip in padded for part in (clip, spacer)][:-1]
    return np.concatenate(tiles, axis=2)


def play_episode(
    agent, env, seed: int, instruction: str | None, max_steps: int, progress: bool = False
) -> dict:
    """Run one episode of ``agent`` in a 1-env ``env``; frames, actions and unlock steps.

    ``progress`` shows a bar of steps: a C-Steve-1 on CPU takes minutes for 500."""
    from tqdm import tqdm

    seeds = np.array([episode_seed(seed, 0)])
    step = env.reset(seeds)
    agent.reset(seeds)
    if instruction is not None:
        agent.instruct([instruction])
    frames, actions, unlocked = [step.frames[0].copy()], [], {}
    before = step.state["achievements"][0].copy()
    with tqdm(total=max_steps, unit="step", desc="play", disable=not progress) as bar:
        for t in range(max_steps):
            action = agent.act(step)
            step = env.step(action)
            bar.update(1)
            actions.append(int(action[0]))
            frames.append(step.frames[0].copy())
            now = step.state["achievements"][0]
            for index in np.flatnonzero(now & ~before):
                unlocked[ACHIEVEMENT_NAMES[index]] = t + 1
            before = now.copy()
            if step.done[0]:
                break
    return {
        "frames": np.stack(frames),
        "actions": actions,
        "unlocked": unlocked,
        "survived": int(step.state["player_vitals"][0][0]) > 0,
    }


def inference_meta(agent, temperature: float | None) -> dict[str, float]:
    """How ``agent`` chose its actions, for a report: a C-Steve-1's guidance scale and
    temperature as it resolved them (its export's unless given), else the temperature asked
    for (1 if none)."""
    return getattr(agent, "inference", None) or {
        "temperature": 1.0 if temperature is None else temperature
    }


def register(subparsers) -> None:
    p = subparsers.add_parser(
        "play",
        help="watch an agent follow an instruction: GIF + JSON of what it unlocked when",
        description=(
            "Play one episode with a C-Steve-1 checkpoint given --instruction (text read by "
            "C-CLIP's text tower and turned into a goal by the CVAE prior), or any agent zoo "
            "eval accepts. Writes OUT/play.gif (the instruction above the frames) and "
            "OUT/play.json (achievements unlocked and their steps, actions, outcome). Several "
            "--instruction play the same world one after another, side by side in the GIF "
            "(OUT/play.json then lists one episode per instruction)."
        ),
    )
    add_agent_flags(p, agent=None, required=True,
                    checkpoint="C-Steve-1 .ckpt or export (or a C-VPT one, no instruction)")
    p.add_argument(
        "--instruction", action="append", default=None,
        help='e.g. "obtain wood" (a caption or free text); repeat it to play each on the same '
        "world, side by side in one GIF",
    )
    add_game_flag(p, default="craftax")
    add_seed_flag(p)  # plays episode 0 of the seed
    add_max_steps_flag(p, default=500)
    add_out_flag(p, "folder of play.gif and play.json")
    p.set_defaults(handler=run_play)


def run_play(args: argparse.Namespace) -> int:
    from zoo.agents import AgentSpec
    from zoo.envs import make_env
    from zoo.eval.plots import write_gif

    instructions = args.instruction or [None]
    try:  # a bad checkpoint is one line naming its file, not a traceback
        spec = AgentSpec.from_args(args)
        if args.instruction:
            if spec.kind != "csteve1":
                raise ValueError(
                    f"--instruction needs a C-Steve-1 checkpoint; {args.checkpoint} is {spec.kind}"
                )
            spec.require_text()
        agent = spec.build(1)
    except (ValueError, FileNotFoundError) as err:
        raise SystemExit(f"zoo play: error: {err}") from None
    if args.instruction:
        from zoo.agents.csteve1_agent import instruction_note

        for instruction in instructions:
            note = instruction_note(agent.goals, instruction)
            if note:
                print(f"zoo play: note: {note}", file=sys.stderr)
    env = make_env(args.env, 1, pixels=True, max_steps=args.max_steps)
    args.out.mkdir(parents=True, exist_ok=True)
    clips, logs = [], []
    for instruction in instructions:
        result = play_episode(agent, env, args.seed, instruction, args.max_steps, progress=True)
        label = instruction or "(no instruction)"
        clips.append(caption_frames(result["frames"], label))
        logs.append({
            "instruction": instruction,
            "checkpoint": str(args.checkpoint),
            "env": args.env,
            "seed": args.seed,
            **inference_meta(agent, args.temperature),
            "steps": len(result["actions"]),
            "survived": result["survived"],
            "unlocked": result["unlocked"],
            "actions": [ACTION_NAMES[a] for a in result["actions"]],
        })
        print(f"{label}: {len(result['actions'])} steps, unlocked {result['unlocked']}")
    write_gif(side_by_side(clips) if len(clips) > 1 else clips[0], args.out / "play.gif", scale=1)
    log = logs[0] if len(logs) == 1 else {"episodes": logs}
    (args.out / "play.json").write_text(json.dumps(log, indent=2) + "\n")
    print(f"wrote {args.out / 'play.gif'} and {args.out / 'play.json'}")
    return 0


__all__ = [
    "caption_frames", "inference_meta", "play_episode", "register", "run_play", "side_by_side",
]
