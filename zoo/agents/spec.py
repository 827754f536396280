"""One description of an agent: what plays, from which weights, at which settings.

Every command that plays (``zoo eval`` and its protocols, ``zoo play``, ``zoo data dagger``,
the online evaluation of a training run) describes its agent as an ``AgentSpec``. The spec
checks itself once, when made, with one message per misuse; builds the agent with
``spec.build(num_envs)``; and writes itself, with the sha256 of every file it names, into
reports and manifests (``spec.record()``). A new kind of agent is an entry in ``FACTORIES``
(and in ``CHECKPOINTS`` or ``SAMPLING`` if it has weights or samples its actions).

The agents of ``zoo rl train`` runs live above this package (``zoo/rl/play.py``: they are built
from RL policies) and are imported by name, only when such an agent is asked for
(tests/test_layers.py forbids the import here).
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from zoo.agents.base import Agent, RandomAgent
from zoo.agents.checkpoints import checkpoint_kind
from zoo.weights.guidance import PAPER_CFG_SCALE

Factory = Callable[["AgentSpec", int], Agent]


def _random(spec: AgentSpec, num_envs: int) -> Agent:
    return RandomAgent(num_envs)


def _scripted(spec: AgentSpec, num_envs: int) -> Agent:
    from zoo.experts.scripted import ScriptedExpert

    return ScriptedExpert(num_envs, **dict(spec.expert_options or {}))


def _ppo(spec: AgentSpec, num_envs: int) -> Agent:
    from zoo.experts.ppo import PPOExpert

    return PPOExpert.load(spec.checkpoint, num_envs)


def _cvpt(spec: AgentSpec, num_envs: int) -> Agent:
    from zoo.agents.cvpt_agent import CVPTAgent

    return CVPTAgent.from_checkpoint(spec.checkpoint, num_envs,
                                     temperature=spec.sampling_temperature, greedy=spec.greedy)


def _csteve1(spec: AgentSpec, num_envs: int) -> Agent:
    from zoo.agents.csteve1_agent import CSteve1Agent, CSteve1Policy

    temperature = None if spec.temperature is None else spec.sampling_temperature
    policy = CSteve1Policy.load(spec.checkpoint, cfg_scale=spec.cfg_scale, temperature=temperature,
                              greedy=spec.greedy, cclip=spec.cclip, prior=spec.prior)
    return CSteve1Agent(policy, num_envs)


def _rl(spec: AgentSpec, num_envs: int) -> Agent:
    load = importlib.import_module("zoo.rl.play").load_rl_agent
    return load(spec.checkpoint, num_envs, spec.sampling_temperature, spec.greedy)


FACTORIES: dict[str, Factory] = {
    "random": _random,
    "scripted": _scripted,
    "ppo": _ppo,
    "cvpt": _cvpt,
    "csteve1": _csteve1,
    "rl": _rl,
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
GOAL_MODEL_FLAGS = ("cclip", "prior", "cfg_scale")
"""C-Steve-1's own settings: the models that read its text instructions, its guidance."""


@dataclasses.dataclass(frozen=True)
class AgentSpec:
    """Who plays and how, checked when made.

    Args:
        kind: one of ``AGENT_NAMES``; None: the one ``checkpoint`` holds (``checkpoint_kind``).
        checkpoint: the trained agent's ``.ckpt``, export folder or run (``CHECKPOINTS``).
        temperature: a sampling agent's logit temperature; 0 plays the most likely action;
            None is 1, or for C-Steve-1 what its export records.
        cfg_scale: C-Steve-1's guidance scale (None: what its export records, else the
            paper's).
        cclip, prior: the C-CLIP and CVAE prior that turn C-Steve-1's text instructions into
            goals (None: the ones its export records).
        expert_options: ``ExpertConfig`` fields of the scripted expert.
    """

    kind: str | None = None
    checkpoint: str | None = None
    temperature: float | None = None
    cfg_scale: float | None = None
    cclip: str | None = None
    prior: str | None = None
    expert_options: Mapping[str, Any] | None = dataclasses.field(default=None, hash=False)

    def __post_init__(self) -> None:
        for name in ("checkpoint", "cclip", "prior"):
            path = getattr(self, name)
            if path is not None:
                if not Path(path).exists():
                    raise ValueError(f"--{name} {path} does not exist")
                object.__setattr__(self, name, str(path))
        if self.kind is None:
            if self.checkpoint is None:
                raise ValueError(f"give --agent NAME (one of {', '.join(AGENT_NAMES)}) or "
                                 "--checkpoint PATH")
            object.__setattr__(self, "kind", checkpoint_kind(self.checkpoint))
        if self.expert_options is not None:
            object.__setattr__(self, "expert_options", dict(self.expert_options))
        self._check()

    def _check(self) -> None:
        kind = self.kind
        if kind not in FACTORIES:
            raise ValueError(f"unknown agent {kind!r}; expected one of {AGENT_NAMES}")
        if self.expert_options and kind != "scripted":
            raise ValueError(f"expert options apply to the scripted expert only, not {kind!r}")
        if self.temperature is not None and not (math.isfinite(self.temperature)
                                                 and self.temperature >= 0):
            raise ValueError(f"temperature must be >= 0, got {self.temperature}")
        if self.temperature not in (None, 1.0) and kind not in SAMPLING:
            raise ValueError(f"temperature applies to the {', '.join(SAMPLING[:-1])} and "
                             f"{SAMPLING[-1]} agents only, not {kind!r}")
        if kind in CHECKPOINTS and self.checkpoint is None:
            raise ValueError(f"agent {kind!r} needs --checkpoint PATH ({CHECKPOINTS[kind]})")
        given = [f"--{name.replace('_', '-')}" for name in GOAL_MODEL_FLAGS
                 if getattr(self, name) is not None]
        if given and kind != "csteve1":
            raise ValueError(f"{', '.join(given)} apply to C-Steve-1 only, not {kind!r}")
        if (self.cclip is None) != (self.prior is None):
            raise ValueError("give --cclip and --prior together (or neither: the ones the "
                             "C-Steve-1 export records)")
        if self.cfg_scale is not None and not (math.isfinite(self.cfg_scale)
                                               and self.cfg_scale >= 0):
            raise ValueError(f"cfg_scale must be >= 0, got {self.cfg_scale}")

    @property
    def greedy(self) -> bool:
        """Temperature 0: the most likely action."""
        return self.temperature == 0

    @property
    def sampling_temperature(self) -> float:
        """The temperature logits are divided by (1 when greedy or not given)."""
        return 1.0 if self.temperature in (None, 0) else float(self.temperature)

    def goal_models(self) -> dict[str, str] | None:
        """C-Steve-1's C-CLIP and prior: the ones given, else the ones its export records
        (checked against their sha256), else None."""
        if self.kind != "csteve1":
            return None
        if self.cclip is not None:
            return {"cclip": self.cclip, "prior": self.prior}
        from zoo.weights.export import recorded_goal_models

        recorded = recorded_goal_models(self.checkpoint)
        return None if recorded is None else {k: str(v) for k, v in recorded.items()}

    def require_text(self) -> None:
        """Raise unless this agent can be told instructions as text (C-Steve-1 needs its goal
        models; the other kinds check their instructions when told them)."""
        if self.kind == "csteve1" and self.goal_models() is None:
            raise ValueError(
                f"C-Steve-1 reads instructions as text through C-CLIP and the CVAE prior, and "
                f"{self.checkpoint} records none (a .ckpt, or an export written before exports "
                "recorded them): give --cclip and --prior (e.g. weights/cclip_cpu, "
                "weights/prior_cpu), or re-export it with `zoo export --cclip --prior`"
            )

    def build(self, num_envs: int) -> Agent:
        """The agent for ``num_envs`` envs."""
        return FACTORIES[self.kind](self, num_envs)

    def record(self) -> dict[str, Any]:
        """The spec as JSON for a report or manifest: every path with its sha256, so other
        weights at the same path make another record (an export's sha256 pins the goal models
        it records too); unset fields are left out."""
        from zoo.weights.export import checkpoint_sha256

        out: dict[str, Any] = {"kind": self.kind}
        for name in ("checkpoint", "cclip", "prior"):
            path = getattr(self, name)
            if path is not None:
                out[name] = str(Path(path).resolve())
                out[f"{name}_sha256"] = checkpoint_sha256(path)
        for name in ("temperature", "cfg_scale", "expert_options"):
            if getattr(self, name) is not None:
                out[name] = getattr(self, name)
        return out

    @classmethod
    def from_args(cls, args: argparse.Namespace) -> AgentSpec:
        """The spec of the flags ``add_agent_flags`` declared (``--agent`` where declared)."""
        return cls(getattr(args, "agent", None), args.checkpoint, args.temperature,
                   args.cfg_scale, args.cclip, args.prior)

    @classmethod
    def from_record(cls, record: Mapping[str, Any]) -> AgentSpec:
        """The spec a ``record()`` describes (its sha256s are what a manifest compares)."""
        fields = {f.name for f in dataclasses.fields(cls)}
        return cls(**{k: v for k, v in record.items() if k in fields})


def add_agent_flags(
    parser: argparse.ArgumentParser,
    *,
    agent: str | None = "who plays (default: the agent --checkpoint holds)",
    checkpoint: str = "a trained agent: C-VPT or C-Steve-1 .ckpt or export, PPO expert run, or "
    "a `zoo rl train` run folder (its newest checkpoint) or one of its checkpoints/update_*.pt",
    required: bool = False,
    temperature: float | None = None,
) -> None:
    """Declare the flags of an ``AgentSpec`` (read back by ``AgentSpec.from_args``), once for
    every command that plays an agent; ``agent`` None leaves out ``--agent`` (the checkpoint
    says), ``temperature`` is the default temperature (None: 1, or a C-Steve-1 export's)."""
    group = parser.add_argument_group("agent")
    if agent is not None:
        group.add_argument("--agent", choices=AGENT_NAMES, help=agent)
    group.add_argument("--checkpoint", type=Path, required=required, help=checkpoint)
    default = ("1, or the temperature a C-Steve-1 export records" if temperature is None
               else f"{temperature:g}")
    group.add_argument(
        "--temperature", type=float, default=temperature,
        help=f"C-VPT, C-Steve-1, zoo rl agents: sample from softmax(logits / T) (default "
        f"{default}); 0 plays the most likely action",
    )
    group.add_argument(
        "--cfg-scale", type=float,
        help="C-Steve-1: classifier-free guidance scale (default: the scale its export "
        f"records, else the paper's {PAPER_CFG_SCALE}; 0: conditional only)",
    )
    group.add_argument(
        "--cclip", type=Path, metavar="DIR",
        help="C-Steve-1: the C-CLIP it was trained with, which reads instruction text "
        "(default: the one its export records)",
    )
    group.add_argument(
        "--prior", type=Path, metavar="DIR",
        help="C-Steve-1: the CVAE prior, text embedding -> goal (default: the one its export "
        "records)",
    )
