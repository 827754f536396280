"""The stages of a DAgger run (``kind: dagger``, docs/dagger.md): per round r, ``dagger-rR``
rolls out the last round's C-VPT with the scripted expert labelling every state, ``fit-rR``
trains from the last round's weights on the expert data plus every round's labels so far, and
``eval-rR-GAME`` scores the new weights.

Round 1's learner is ``initial_learner``; each later round's is the previous round's
``last.ckpt``, the weights at the end of its short cosine (the 8-batch validation loss moves
less between checkpoints than its own noise, so "best" would be a coin toss). A retrained round
is a new checkpoint, so every later round runs again; a new initial learner or expert data
(their fingerprints) reruns the rounds that read them. Layout under ``--out``: ``data/rR``
(rollouts), ``runs/fit-rR``, ``eval/rR-GAME``.
"""

from __future__ import annotations

import json
from pathlib import Path

from zoo.pipeline.checks import crafterplay
from zoo.pipeline.config import DaggerPipelineConfig
from zoo.pipeline.stages import Keys, Stage, fit_stage, score_stage

WEIGHTS = "last.ckpt"


def dagger_plan(config: DaggerPipelineConfig, out: Path) -> list[Stage]:
    """Every stage of every round, in the order they run."""
    stages: list[Stage] = []
    for r, beta in enumerate(config.rounds, 1):
        stages += _round(config, out, r, beta, None if r == 1 else f"fit-r{r - 1}")
    return stages


def _round(config: DaggerPipelineConfig, out: Path, r: int, beta: float,
           learner: str | None) -> list[Stage]:
    """Round ``r``'s rollouts, training and scores; ``learner``: the stage whose checkpoint
    plays and starts the training (None: ``initial_learner``)."""
    initial, expert = Path(config.initial_learner), Path(config.expert_data)
    rollouts, fit, folder = f"dagger-r{r}", f"fit-r{r}", out / "data" / f"r{r}"
    before = () if learner is None else (learner,)
    first = (initial,) if learner is None else ()
    sources = [{"root": str(expert), "weight": config.expert_weight},
               *({"root": str(out / "data" / f"r{k}"), "weight": config.round_weight}
                 for k in range(1, r + 1))]

    def weights(keys: Keys) -> str:
        return str(initial if learner is None else keys[learner])

    def rollouts_argv(keys: Keys) -> list[str]:
        return ["data", "dagger", "--checkpoint", weights(keys), "--round", str(r),
                "--beta", str(beta), "--mix", config.mix, "--episodes", str(config.episodes),
                "--seed", str(config.seed + r), "--max-steps", str(config.max_steps),
                "--env", config.env, "--episodes-per-shard", str(config.episodes_per_shard),
                "--num-envs", str(config.num_envs), "--workers", str(config.workers),
                "--out", str(folder), "--no-progress"]

    def wiring(keys: Keys) -> list[str]:
        # JSON is YAML: jsonargparse reads it whatever the paths hold
        return [f"--model.init_args.init_weights={weights(keys)}",
                f"--data.init_args.sources={json.dumps(sources)}"]

    return [
        Stage(rollouts, before, folder, rollouts_argv, crafterplay, resumable=True,
              reads=first),
        fit_stage(fit, config.fit_config, config.fit_args, out / "runs",
                  (*before, *(f"dagger-r{k}" for k in range(1, r + 1))), wiring,
                  kind="cvpt", weights=WEIGHTS, reads=(*first, expert / "manifest.json")),
        *(score_stage(f"eval-r{r}-{game}", out / "eval" / f"r{r}-{game}", (fit,),
                      lambda keys: ["--checkpoint", str(keys[fit])],
                      ["--env", game, "--episodes", str(config.eval_episodes),
                       "--num-envs", str(config.eval_num_envs), "--no-gif"])
          for game in config.eval_games),
    ]
