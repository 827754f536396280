"""Agents by name, so CLIs and configs can say which one plays.

``AgentSpec`` (zoo/agents/spec.py) is the one description of an agent: its kind, its weights,
its settings, checked once and built with ``spec.build(num_envs)``. ``checkpoint_kind`` tells
which agent a checkpoint holds; ``dataset_agent`` is what plays a CrafterPlay dataset.
"""

from __future__ import annotations

from zoo.agents.base import Agent, RandomAgent
from zoo.agents.checkpoints import checkpoint_kind
from zoo.agents.spec import AGENT_NAMES, AgentSpec


def dataset_agent(config, num_envs: int) -> Agent:
    """The agent that plays the episodes of a CrafterPlay dataset
    (``zoo.data.generate.GenerationConfig``): its expert, or with ``dagger`` settings the
    learner/expert mixture (the learner as its manifest records it: ``AgentSpec.record``).
    What ``zoo data generate`` and ``zoo data dagger`` pass to ``zoo.data.generate.generate``
    as ``build_agent``."""
    expert = AgentSpec(config.expert, config.checkpoint,
                       expert_options=config.expert_options).build(num_envs)
    dagger = config.dagger
    if dagger is None:
        return expert
    from zoo.agents.dagger import DaggerMixture

    learner = AgentSpec.from_record(dagger.learner).build(num_envs)
    return DaggerMixture(learner, expert, num_envs, dagger.beta, dagger.mix)


__all__ = [
    "AGENT_NAMES",
    "Agent",
    "AgentSpec",
    "RandomAgent",
    "checkpoint_kind",
    "dataset_agent",
]
