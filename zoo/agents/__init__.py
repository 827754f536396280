"""Agents by name, so CLIs and configs can say which one plays."""

from __future__ import annotations

from pathlib import Path

from zoo.agents.base import Agent, RandomAgent

AGENT_NAMES = ("random", "scripted", "ppo", "cvpt")


def make_agent(
    name: str, num_envs: int, checkpoint: str | None = None, temperature: float = 1.0
) -> Agent:
    """Build the named agent for ``num_envs`` envs; ``checkpoint`` is required by trained ones.

    ``temperature`` scales a sampling policy's logits (C-VPT); 0 plays the most likely action.
    """
    if temperature < 0:
        raise ValueError(f"temperature must be >= 0, got {temperature}")
    if temperature != 1.0 and name != "cvpt":
        raise ValueError(f"temperature applies to the cvpt agent only, not {name!r}")
    if name == "random":
        return RandomAgent(num_envs)
    if name == "scripted":
        from zoo.experts.scripted import ScriptedExpert

        return ScriptedExpert(num_envs)
    if name in ("ppo", "cvpt") and checkpoint is None:
        kind = "a PPO expert checkpoint dir" if name == "ppo" else "a C-VPT .ckpt or export dir"
        raise ValueError(f"agent {name!r} needs --checkpoint PATH ({kind})")
    if name == "ppo":
        from zoo.experts.ppo import PPOExpert

        return PPOExpert.load(checkpoint, num_envs)
    if name == "cvpt":
        from zoo.agents.cvpt_agent import CVPTAgent

        greedy = temperature == 0
        return CVPTAgent.from_checkpoint(
            checkpoint, num_envs, temperature=1.0 if greedy else temperature, greedy=greedy
        )
    raise ValueError(f"unknown agent {name!r}; expected one of {AGENT_NAMES}")


def checkpoint_kind(path: str | Path) -> str:
    """Which trained agent a checkpoint holds, from its layout alone.

    A PPO run or checkpoint folder has ``meta.json`` files; a C-VPT export folder has
    ``model.safetensors``; a Lightning ``.ckpt`` file is a C-VPT run.
    """
    path = Path(path)
    if path.is_file() and path.suffix == ".ckpt":
        return "cvpt"
    if path.is_dir():
        if (path / "model.safetensors").is_file():
            return "cvpt"
        if (path / "meta.json").is_file() or any(path.glob("update_*/meta.json")):
            return "ppo"
    raise ValueError(
        f"cannot tell what {path} holds: expected a C-VPT .ckpt, a `zoo export` folder "
        "(model.safetensors) or a PPO checkpoint/run folder (meta.json); pass --agent"
    )


def load_checkpoint_agent(path: str | Path, num_envs: int, temperature: float = 1.0) -> Agent:
    """The trained agent stored at ``path`` (see ``checkpoint_kind``), for ``num_envs`` envs."""
    return make_agent(checkpoint_kind(path), num_envs, str(path), temperature)


__all__ = [
    "AGENT_NAMES",
    "Agent",
    "RandomAgent",
    "checkpoint_kind",
    "load_checkpoint_agent",
    "make_agent",
]
