"""Agents by name, so CLIs and configs can say which one plays."""

from __future__ import annotations

from zoo.agents.base import Agent, RandomAgent

AGENT_NAMES = ("random", "scripted", "ppo")


def make_agent(name: str, num_envs: int, checkpoint: str | None = None) -> Agent:
    """Build the named agent for ``num_envs`` envs; ``checkpoint`` is required by trained ones."""
    if name == "random":
        return RandomAgent(num_envs)
    if name == "scripted":
        from zoo.experts.scripted import ScriptedExpert

        return ScriptedExpert(num_envs)
    if name == "ppo":
        if checkpoint is None:
            raise ValueError("agent 'ppo' needs --checkpoint PATH (a PPO expert checkpoint dir)")
        from zoo.experts.ppo import PPOExpert

        return PPOExpert.load(checkpoint, num_envs)
    raise ValueError(f"unknown agent {name!r}; expected one of {AGENT_NAMES}")


__all__ = ["AGENT_NAMES", "Agent", "RandomAgent", "make_agent"]
