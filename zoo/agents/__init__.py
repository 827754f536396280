"""Agents by name, so CLIs and configs can say which one plays.

``make_agent`` looks a name up in ``FACTORIES``. The agents of ``zoo rl train`` runs live above
this package (``zoo/rl/play.py``: they are built from RL policies) and must not be imported
from here (tests/test_layers.py), so their entry names its module and is imported only when
such an agent is asked for.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from pathlib import Path

from zoo.agents.base import Agent, RandomAgent

Factory = Callable[..., Agent]
"""``factory(checkpoint, num_envs, temperature, greedy, **options) -> Agent``; ``temperature`` is
None only for C-Steve-1 (the one its export records)."""


def _random(checkpoint, num_envs: int, temperature: float, greedy: bool, **options) -> Agent:
    return RandomAgent(num_envs)


def _scripted(checkpoint, num_envs: int, temperature: float, greedy: bool,
              expert_options: dict | None = None, **options) -> Agent:
    from zoo.experts.scripted import ScriptedExpert

    return ScriptedExpert(num_envs, **(expert_options or {}))


def _ppo(checkpoint: str, num_envs: int, temperature: float, greedy: bool, **options) -> Agent:
    from zoo.experts.ppo import PPOExpert

    return PPOExpert.load(checkpoint, num_envs)


def _cvpt(checkpoint: str, num_envs: int, temperature: float, greedy: bool, **options) -> Agent:
    from zoo.agents.cvpt_agent import CVPTAgent

    return CVPTAgent.from_checkpoint(checkpoint, num_envs, temperature=temperature, greedy=greedy)


def _csteve1(checkpoint: str, num_envs: int, temperature: float | None, greedy: bool,
             cclip: str | None = None, prior: str | None = None, cfg_scale: float | None = None,
             **options) -> Agent:
    from zoo.agents.steve_agent import GoalEncoder, SteveAgent, StevePolicy

    policy = StevePolicy.load(checkpoint, cfg_scale=cfg_scale, temperature=temperature,
                              greedy=greedy)
    goals = GoalEncoder.load(cclip, prior) if cclip is not None else None
    return SteveAgent(policy, goals, num_envs)


def imported(target: str) -> Factory:
    """The factory ``"module:function"``, imported when first called (not when registered)."""
    module, _, name = target.partition(":")

    def factory(*args, **kwargs) -> Agent:
        return getattr(importlib.import_module(module), name)(*args, **kwargs)

    return factory


FACTORIES: dict[str, Factory] = {
    "random": _random,
    "scripted": _scripted,
    "ppo": _ppo,
    "cvpt": _cvpt,
    "csteve1": _csteve1,
    "rl": imported("zoo.rl.play:load_rl_agent"),
}
CHECKPOINTS = {
    "ppo": "a PPO expert checkpoint dir",
    "cvpt": "a C-VPT .ckpt or export dir",
    "csteve1": "a C-Steve-1 .ckpt or export dir",
    "rl": "a `zoo rl train` run dir or its checkpoints/update_*.pt",
}
"""What ``--checkpoint`` must be for the agents that need one."""
SAMPLING = ("cvpt", "csteve1", "rl")
"""Agents whose actions are sampled, so ``temperature`` applies."""
AGENT_NAMES = tuple(FACTORIES)


def make_agent(
    name: str,
    num_envs: int,
    checkpoint: str | None = None,
    temperature: float | None = None,
    cclip: str | None = None,
    prior: str | None = None,
    cfg_scale: float | None = None,
    expert_options: dict | None = None,
) -> Agent:
    """Build the named agent for ``num_envs`` envs; ``checkpoint`` is required by trained ones.

    ``temperature`` scales a sampling policy's logits (C-VPT, C-Steve-1, RL); 0 plays the most
    likely action; None is 1, or for C-Steve-1 what its export records. C-Steve-1 reads text
    instructions through ``cclip`` (its C-CLIP checkpoint) and ``prior`` (the CVAE prior's), and
    guides with ``cfg_scale`` (None: the scale its export records, else the paper's 1.5).
    ``expert_options`` overrides the scripted expert's ``ExpertConfig`` fields.
    """
    if name not in FACTORIES:
        raise ValueError(f"unknown agent {name!r}; expected one of {AGENT_NAMES}")
    if expert_options and name != "scripted":
        raise ValueError(f"expert options apply to the scripted expert only, not {name!r}")
    if temperature is not None and temperature < 0:
        raise ValueError(f"temperature must be >= 0, got {temperature}")
    if temperature not in (None, 1.0) and name not in SAMPLING:
        raise ValueError(
            f"temperature applies to the {', '.join(SAMPLING[:-1])} and {SAMPLING[-1]} agents "
            f"only, not {name!r}"
        )
    if name in CHECKPOINTS and checkpoint is None:
        raise ValueError(f"agent {name!r} needs --checkpoint PATH ({CHECKPOINTS[name]})")
    greedy = temperature == 0
    if temperature is None and name != "csteve1":  # only C-Steve-1 exports record one
        temperature = 1.0
    options = {"cclip": cclip, "prior": prior, "cfg_scale": cfg_scale} if name == "csteve1" else {}
    if name == "scripted":
        options["expert_options"] = expert_options
    return FACTORIES[name](checkpoint, num_envs, 1.0 if greedy else temperature, greedy, **options)


def dataset_agent(config, num_envs: int) -> Agent:
    """The agent that plays the episodes of a CrafterPlay dataset
    (``zoo.data.generate.GenerationConfig``): its expert, or with ``dagger`` settings the
    learner/expert mixture (a C-Steve-1 learner reads its instructions through the settings'
    ``cclip`` and ``prior``). What ``zoo data generate`` and ``zoo data dagger`` pass to
    ``zoo.data.generate.generate`` as ``build_agent``."""
    expert = make_agent(config.expert, num_envs, config.checkpoint,
                        expert_options=config.expert_options)
    dagger = config.dagger
    if dagger is None:
        return expert
    from zoo.agents.dagger import DaggerMixture

    # the learner: a C-VPT, or a C-Steve-1 (told the schedule's instructions), .ckpt or export
    kind = checkpoint_kind(dagger.learner)
    if kind == "csteve1":
        learner = make_agent("csteve1", num_envs, dagger.learner, dagger.learner_temperature,
                             dagger.cclip, dagger.prior, dagger.cfg_scale)
    else:
        learner = make_agent("cvpt", num_envs, dagger.learner,
                             temperature=dagger.learner_temperature)
    return DaggerMixture(learner, expert, num_envs, dagger.beta, dagger.mix)


def is_rl_run(path: Path) -> bool:
    """A ``zoo rl train`` run folder (config.yaml + checkpoints/update_*.pt) or one checkpoint."""
    if path.is_dir():
        return (path / "config.yaml").is_file() and any((path / "checkpoints").glob("update_*.pt"))
    return path.is_file() and path.suffix == ".pt" and path.name.startswith("update_")


def checkpoint_kind(path: str | Path) -> str:
    """Which trained agent a checkpoint holds, from its layout alone.

    A PPO run or checkpoint folder has ``meta.json`` files; a ``zoo export`` folder has
    ``model.safetensors`` or ``sha256.txt`` and names its kind in ``config.json`` (C-VPT or
    C-Steve-1 play; C-CLIP and the prior do not); a Lightning ``.ckpt`` file is a C-Steve-1 run
    when its hyper-parameters name a backbone, otherwise a C-VPT run; a ``zoo rl train`` run folder
    (config.yaml, checkpoints/update_*.pt) or one of its ``update_*.pt`` is an RL agent.
    """
    path = Path(path)
    if is_rl_run(path):
        return "rl"
    if path.is_file() and path.suffix == ".ckpt":
        from zoo.agents.steve_agent import is_steve_checkpoint
        from zoo.weights.checkpoint_io import read_torch_file

        return "csteve1" if is_steve_checkpoint(read_torch_file(path)) else "cvpt"
    if path.is_dir():
        if (path / "model.safetensors").is_file() or (path / "sha256.txt").is_file():
            from zoo.weights.export import KINDS, exported_kind

            kind = exported_kind(path)
            if kind not in ("cvpt", "csteve1"):
                raise ValueError(
                    f"{path} is a {KINDS[kind].title} export, not an agent: expected a C-VPT "
                    "or C-Steve-1 export"
                )
            return kind
        if (path / "meta.json").is_file() or any(path.glob("update_*/meta.json")):
            return "ppo"
    raise ValueError(
        f"cannot tell what {path} holds: expected a C-VPT/C-Steve-1 .ckpt, a `zoo export` folder "
        "(model.safetensors), a PPO checkpoint/run folder (meta.json) or a `zoo rl train` run "
        "(config.yaml + checkpoints/update_*.pt); pass --agent"
    )


def load_checkpoint_agent(
    path: str | Path, num_envs: int, temperature: float | None = None, **options
) -> Agent:
    """The trained agent stored at ``path`` (see ``checkpoint_kind``), for ``num_envs`` envs;
    ``options`` are ``make_agent``'s C-Steve-1 arguments (cclip, prior, cfg_scale)."""
    return make_agent(checkpoint_kind(path), num_envs, str(path), temperature, **options)


__all__ = [
    "AGENT_NAMES",
    "Agent",
    "RandomAgent",
    "checkpoint_kind",
    "dataset_agent",
    "load_checkpoint_agent",
    "make_agent",
]
