"""Watch the policy play while it trains: an online-evaluation callback for C-VPT and C-Steve-1.

Every ``every_n_steps`` optimizer steps (rank 0 only) a copy of the network plays ``episodes``
episodes in ``num_envs`` batched envs (Craftax-Classic by default; episode j seeded from
(seed, j), so every evaluation plays the same worlds and curves compare like with like):
- C-VPT: ``online/crafter_score``, ``online/return_percent``, ``online/episode_length`` and one
  ``online/success/<achievement>`` per achievement;
- C-Steve-1: with ``task`` and ``instruction`` (and the C-CLIP + prior that read it),
  ``online/task_success`` on that task instead.
Scalars go to every logger (CSV and W&B alike); with a W&B logger also an achievement bar
chart and the first episode as a video. The env is built once and kept (Craftax compiles once).
"""

from __future__ import annotations

import copy
import tempfile
from pathlib import Path

import lightning as L
import numpy as np
from lightning.pytorch.callbacks import Callback
from lightning.pytorch.loggers import WandbLogger

from zoo.agents.cvpt_agent import CVPTAgent, CVPTPolicy
from zoo.agents.csteve1_agent import GoalEncoder, CSteve1Agent, CSteve1Policy
from zoo.envs import make_env
from zoo.envs.tasks import make_task_env
from zoo.eval.plots import plot_success_rates, write_gif
from zoo.eval.report import summarize
from zoo.eval.rollout import evaluate
from zoo.eval.task_eval import evaluate_task, summarize_task
from zoo.models.csteve1 import CSteve1Model


class OnlineEvaluation(Callback):
    def __init__(
        self,
        every_n_steps: int = 500,
        episodes: int = 8,
        num_envs: int = 8,
        env: str = "craftax",
        max_steps: int = 1000,
        seed: int = 0,
        task: str | None = None,
        instruction: str | None = None,
        cclip: str | None = None,
        prior: str | None = None,
        cfg_scale: float | None = None,
        video: bool = True,
    ) -> None:
        """
        Args:
            every_n_steps: optimizer steps between evaluations.
            episodes: episodes per evaluation (more: less noise, longer pauses).
            num_envs: envs played at once.
            env: ``craftax`` (batched, fast) or ``crafter``.
            max_steps: episode step limit (the game's is 10,000; shorter keeps pauses short).
            seed: run seed of the evaluation worlds.
            task: C-Steve-1: a task of ``zoo.envs.tasks`` to score instead of the Crafter Score.
            instruction: C-Steve-1: the instruction text given after every reset.
            cclip: C-Steve-1: the C-CLIP checkpoint/export that reads the instruction.
            prior: C-Steve-1: the CVAE prior checkpoint/export (text -> goal).
            cfg_scale: C-Steve-1: classifier-free guidance scale (None: the paper's).
            video: log the first episode as a W&B video.
        """
        super().__init__()
        if every_n_steps < 1 or episodes < 1 or num_envs < 1:
            raise ValueError("every_n_steps, episodes and num_envs must be >= 1")
        steve_args = (task, instruction, cclip, prior)
        if any(a is not None for a in steve_args) and any(a is None for a in steve_args):
            raise ValueError(
                "OnlineEvaluation for C-Steve-1 needs task, instruction, cclip and prior all set"
            )
        self.every_n_steps, self.episodes, self.num_envs = every_n_steps, episodes, num_envs
        self.env_name, self.max_steps, self.seed = env, max_steps, seed
        self.task, self.instruction, self.cfg_scale, self.video = task, instruction, cfg_scale, video
        self.cclip, self.prior = cclip, prior
        self._env = None
        self._goals: GoalEncoder | None = None
        self._last_step = -1

    def on_train_start(self, trainer: L.Trainer, pl_module) -> None:
        self._last_step = trainer.global_step  # a resumed run waits for its next multiple

    def on_train_batch_end(self, trainer: L.Trainer, pl_module, outputs, batch, batch_idx) -> None:
        # A batch may make several optimizer steps (one per TBPTT window): evaluate when the
        # step count crosses a multiple of every_n_steps, not only when it lands on one.
        step = trainer.global_step
        if step // self.every_n_steps <= max(self._last_step, 0) // self.every_n_steps:
            return
        self._last_step = step
        if trainer.is_global_zero:
            metrics, rates, frames = self.evaluate(pl_module.model)
            for logger in trainer.loggers:
                logger.log_metrics(metrics, step=step)
                if isinstance(logger, WandbLogger):
                    self._log_media(logger, rates, frames, step)

    def evaluate(self, model) -> tuple[dict[str, float], dict[str, float], np.ndarray | None]:
        """Play a copy of ``model`` (a CVPTModel or CSteve1Model); returns the scalar metrics,
        the achievement success rates and the first episode's frames (or None)."""
        model = copy.deepcopy(model).float().eval()
        gif = 0 if self.video else None
        if isinstance(model, CSteve1Model):
            if self.task is None:
                raise ValueError("OnlineEvaluation of C-Steve-1 needs task, instruction, cclip, prior")
            if self._goals is None:
                self._goals = GoalEncoder.load(self.cclip, self.prior)
            agent = CSteve1Agent(CSteve1Policy(model, cfg_scale=self.cfg_scale), self.num_envs,
                               self._goals)
            if self._env is None:
                self._env = make_task_env(self.task, self.env_name, self.num_envs,
                                          max_steps=self.max_steps)
            tasks, results = evaluate_task(agent, self._env, self.episodes, self.seed,
                                           instruction=self.instruction,
                                           record_gif_episode=gif, progress=False)
            summary = summarize_task(tasks, list(self._env.task.instructions))
            metrics = {"online/task_success": summary["success_percent"]}
        else:
            if self._env is None:
                self._env = make_env(self.env_name, self.num_envs, pixels=True,
                                     max_steps=self.max_steps)
            agent = CVPTAgent(CVPTPolicy(model), self.num_envs)
            results = evaluate(agent, self._env, self.episodes, self.seed,
                               record_gif_episode=gif, progress=False)
            metrics = {}
        report = summarize(results, chunks=1)
        rates = report["success_rates"]
        metrics |= {
            "online/crafter_score": report["crafter_score"]["mean"],
            "online/return_percent": report["normalized_return"]["mean"],
            "online/episode_length": report["episode_length"]["mean"],
        } | {f"online/success/{name}": rate for name, rate in rates.items()}
        frames = next((r.frames for r in results if r.frames is not None), None)
        return metrics, rates, frames

    def _log_media(self, logger: WandbLogger, rates: dict[str, float], frames, step: int) -> None:
        import wandb

        media = {}
        with tempfile.TemporaryDirectory() as tmp:
            chart = plot_success_rates(rates, f"step {step}", Path(tmp) / "rates.png")
            media["online/achievements"] = wandb.Image(str(chart))
            if frames is not None:  # from a file: raw arrays would need moviepy
                gif = write_gif(frames, Path(tmp) / "rollout.gif", scale=1)
                media["online/rollout"] = wandb.Video(str(gif), format="gif")
            logger.experiment.log(media | {"trainer/global_step": step})
