"""Instructions in, actions out: C-Steve-1 with goals from text, captions or clips, and CFG.

- ``GoalEncoder``: a goal embedding from a text instruction (C-CLIP text tower, then the CVAE
  prior, paper §4.3 "Inference"), from a caption id (its caption text, the same way), or from a
  6-frame video clip (C-CLIP video tower, what training used).
- ``CSteve1Policy``: ``initial_state(n)`` and ``act(frames, goals, state)``, one frame per env per
  call with cached TrXL memory, classifier-free guidance with scale ``cfg_scale``; ``load``
  plays at the scale and temperature its export records, else the paper's and 1, and reads
  text through the goal models its export records (``goals``, built when first used).
- ``instruction_note``: for an instruction that is not a caption, the caption C-CLIP finds
  nearest (free text is allowed; the note says what it resembles).
- ``CSteve1Agent``: an ``InstructableAgent`` for ``zoo eval``/``zoo play`` (``instruct`` sets an
  env's instruction; it persists across episodes until changed; None plays without a goal).
"""

from __future__ import annotations

import zlib
from functools import cached_property
from pathlib import Path

import numpy as np
import torch
from torch.nn import functional as F

from zoo.agents.base import EpisodeStreams
from zoo.envs.base import Step
from zoo.models.cclip import CCLIPModel
from zoo.models.csteve1 import CSteve1Model
from zoo.models.prior import CVAEPrior
from zoo.models.sampling import sample_actions
from zoo.models.trxl import TrXLState
from zoo.weights.export import inference_settings, load_model, recorded_goal_models
from zoo.weights.guidance import PAPER_CFG_SCALE


def is_csteve1_checkpoint(checkpoint: dict) -> bool:
    return "backbone_config" in checkpoint.get("hyper_parameters", {})


class GoalEncoder:
    """Goal embeddings for C-Steve-1 from text, caption ids or video clips.

    Text goals go through the prior; ``sample_prior`` draws c ~ N(0, I) (seeded per call),
    otherwise the prior's mean goal (c = 0) is used. The prior's output is scaled to unit norm,
    like the video embeddings C-Steve-1 was trained on (the CPU prior's come out at ~0.88).
    """

    def __init__(
        self, cclip: CCLIPModel, prior: CVAEPrior | None = None, sample_prior: bool = True
    ) -> None:
        self.cclip = cclip.eval()
        self.prior = prior.eval() if prior is not None else None
        self.sample_prior = sample_prior

    @classmethod
    def load(cls, cclip: str | Path, prior: str | Path | None = None, **kwargs) -> GoalEncoder:
        """From a C-CLIP checkpoint and (for text goals) a prior checkpoint."""
        return cls(load_model(cclip, "cclip"), load_model(prior, "prior") if prior else None, **kwargs)

    @property
    def goal_dim(self) -> int:
        return self.cclip.config.embed_dim

    @torch.no_grad()
    def from_text(self, texts: list[str], seed: int = 0) -> torch.Tensor:
        """(N, D) goals for N instructions (C-CLIP text embedding -> prior)."""
        if self.prior is None:
            raise ValueError(
                "text instructions need the CVAE prior: pass a prior checkpoint (--prior)"
            )
        z_t = self.cclip.encode_text(list(texts))
        generator = torch.Generator(device=z_t.device).manual_seed(seed)
        goal = self.prior.sample(z_t, generator=generator, mean=not self.sample_prior)
        return F.normalize(goal, dim=-1)  # training goals are unit-norm C-CLIP video embeddings

    def from_caption_ids(self, caption_ids: list[int], seed: int = 0) -> torch.Tensor:
        """(N, D) goals for CrafterCaption caption ids (0..60), through their caption text."""
        from zoo.captions.vocabulary import load_vocabulary

        texts = load_vocabulary().texts()
        bad = [i for i in caption_ids if not 0 <= i < len(texts)]
        if bad:
            raise ValueError(f"caption ids {bad} out of range: expected 0..{len(texts) - 1}")
        return self.from_text([texts[i] for i in caption_ids], seed)

    @torch.no_grad()
    def from_clips(self, frames: np.ndarray | torch.Tensor) -> torch.Tensor:
        """(N, D) goals for N clips of 6 frames (N, 6, 144, 144, 3) uint8 (no prior needed)."""
        return self.cclip.encode_video(frames)

    @torch.no_grad()
    def nearest_caption(self, text: str) -> tuple[str, float]:
        """The CrafterCaption caption whose C-CLIP text embedding is closest to ``text``'s, and
        their cosine similarity: what a free-text instruction most resembles in training."""
        from zoo.captions.vocabulary import load_vocabulary

        captions = load_vocabulary().texts()
        embeddings = F.normalize(self.cclip.encode_text([text, *captions]), dim=-1)
        similarity = embeddings[1:] @ embeddings[0]
        best = int(similarity.argmax())
        return captions[best], float(similarity[best])


def instruction_note(goals: GoalEncoder, text: str) -> str | None:
    """One line for a user whose instruction is not one of the captions (None if it is one).

    Free text is allowed (C-CLIP reads any text); the nearest caption says which trained
    behaviour it will most likely get.
    """
    from zoo.captions.vocabulary import load_vocabulary

    vocabulary = load_vocabulary()
    if text in vocabulary:
        return None
    caption, similarity = goals.nearest_caption(text)
    return (f"instruction {text!r} is free text, not one of the {len(vocabulary)} captions; "
            f"nearest caption {caption!r} (C-CLIP cosine similarity {similarity:.2f})")


class CSteve1Policy:
    """Steps N envs one frame at a time towards per-env goals, with classifier-free guidance.

    ``cfg_scale`` None is the paper's. ``goals`` reads text instructions through
    ``goal_models`` (C-CLIP and prior paths), else through the ones the ``export`` folder it
    was loaded from records.
    """

    def __init__(
        self,
        model: CSteve1Model,
        device: str | torch.device = "cpu",
        cfg_scale: float | None = None,
        temperature: float = 1.0,
        greedy: bool = False,
        seed: int = 0,
        goal_models: dict[str, str | Path] | None = None,
        export: str | Path | None = None,
    ) -> None:
        if temperature <= 0:
            raise ValueError(f"temperature must be > 0, got {temperature}")
        cfg_scale = PAPER_CFG_SCALE if cfg_scale is None else cfg_scale
        if cfg_scale < 0:
            raise ValueError(f"cfg_scale must be >= 0, got {cfg_scale}")
        self.device = torch.device(device)
        self.model = model.to(self.device).eval()
        self.cfg_scale = cfg_scale
        self.temperature = temperature
        self.greedy = greedy
        self.goal_models, self.export = goal_models, export
        self._rng = np.random.default_rng(seed)

    def goal_model_paths(self) -> dict[str, str | Path]:
        """The C-CLIP and prior it reads text with: the ones given, else its export's."""
        models = self.goal_models
        if models is None and self.export is not None:
            models = recorded_goal_models(self.export)
        if models is None:
            raise ValueError("this C-Steve-1 has no goal models, so it cannot read text: give "
                             "--cclip and --prior")
        return models

    @cached_property
    def goals(self) -> GoalEncoder:
        """Text -> goal through ``goal_models`` (loaded when first asked for: C-CLIP's text
        tower is slow to import and a policy given video goals never needs it)."""
        models = self.goal_model_paths()
        goals = GoalEncoder.load(models["cclip"], models["prior"])
        if goals.goal_dim != self.goal_dim:
            raise ValueError(
                f"the C-CLIP {models['cclip']} embeds {goals.goal_dim} dimensions but "
                f"C-Steve-1 expects goal_dim={self.goal_dim}: use the C-CLIP it was trained with"
            )
        return goals

    @classmethod
    def load(
        cls,
        path: str | Path,
        device: str | torch.device = "cpu",
        cfg_scale: float | None = None,
        temperature: float | None = None,
        greedy: bool = False,
        seed: int = 0,
        cclip: str | Path | None = None,
        prior: str | Path | None = None,
    ) -> CSteve1Policy:
        """The C-Steve-1 at ``path`` (export folder or ``.ckpt``). ``cfg_scale`` and
        ``temperature`` left None are what its export records (the settings its scores were
        measured at, ``zoo export --cfg-scale``), else the paper's and 1; a temperature of 0
        plays the most likely action. ``cclip`` and ``prior`` left None are the goal models
        its export records (``zoo export --cclip --prior``), read when text first needs them."""
        model = load_model(path, "csteve1")  # checks an export's sums before its config is read
        recorded = inference_settings(path, "csteve1")
        cfg_scale = recorded["cfg_scale"] if cfg_scale is None else cfg_scale
        temperature = recorded["temperature"] if temperature is None else temperature
        greedy = greedy or temperature == 0
        goal_models = None if cclip is None else {"cclip": cclip, "prior": prior}
        return cls(model, device, cfg_scale, 1.0 if greedy else temperature, greedy, seed,
                   goal_models, path)

    @property
    def goal_dim(self) -> int:
        return self.model.config.goal_dim

    def initial_state(self, n: int) -> TrXLState:
        """Empty memory for n envs (both guidance passes)."""
        return self.model.guidance_state(n, self.device)

    # The goal-free feature API (PPO-Steve's planner observes it). With head conditioning (the
    # paper's) the goal enters after the Transformer-XL, so one backbone pass per step gives
    # both the feature and, through ``logits_from_features``, the guided action logits.

    @property
    def conditioning(self) -> str:
        """Where the goal enters: "head" (the paper's), "film" or "trxl_input"."""
        return self.model.config.conditioning

    @property
    def feature_dim(self) -> int:
        """Width of ``features``' output (the Transformer-XL's d_model)."""
        return self.model.backbone.config.d_model

    def feature_state(self, n: int) -> TrXLState:
        """Empty memory of ``features`` for n envs (one backbone pass, no guidance copy)."""
        return self.model.initial_state(n, self.device)

    @torch.no_grad()
    def features(
        self, frames: np.ndarray, first: np.ndarray, state: TrXLState
    ) -> tuple[torch.Tensor, TrXLState]:
        """(N, d_model) goal-free features of one frame per env (``first`` marks episode
        starts) and the new memory; head or FiLM conditioning only."""
        if not self.model.config.goal_after_trxl:
            raise ValueError(
                "goal-free features need head or FiLM conditioning (the goal after the "
                f"Transformer-XL); this C-Steve-1 uses {self.conditioning!r}"
            )
        frames_t = torch.tensor(np.asarray(frames), device=self.device).unsqueeze(1)
        first_t = torch.as_tensor(first, device=self.device).unsqueeze(1)
        hidden, state = self.model.backbone.features(frames_t, first_t, state)
        return hidden[:, 0], state

    @torch.no_grad()
    def logits_from_features(self, hidden: torch.Tensor, goals: torch.Tensor) -> torch.Tensor:
        """Guided action logits (N, A) from ``features``' output towards goals (N, D)."""
        return self.model.guided_head(
            hidden.unsqueeze(1), goals.unsqueeze(1), self.cfg_scale
        )[:, 0].float()

    @torch.no_grad()
    def logits(
        self,
        frames: np.ndarray,
        goals: torch.Tensor,
        state: TrXLState,
        first: np.ndarray | None = None,
    ) -> tuple[torch.Tensor, TrXLState]:
        """Guided logits (N, A) for frames (N, 144, 144, 3) uint8 and goals (N, D)."""
        frames_t = torch.tensor(np.asarray(frames), device=self.device).unsqueeze(1)
        n = frames_t.shape[0]
        if first is None:
            first = np.zeros(n, dtype=bool)
        first_t = torch.as_tensor(np.asarray(first, dtype=bool), device=self.device).unsqueeze(1)
        goals = torch.as_tensor(goals, device=self.device, dtype=torch.float32)
        if goals.shape != (n, self.goal_dim):
            raise ValueError(
                f"goals must have shape ({n}, {self.goal_dim}), got {tuple(goals.shape)}"
            )
        logits, state = self.model.guided_logits(
            frames_t, first_t, goals.unsqueeze(1), state, self.cfg_scale
        )
        return logits[:, 0].float(), state

    def act(
        self,
        frames: np.ndarray,
        goals: torch.Tensor,
        state: TrXLState,
        first: np.ndarray | None = None,
        uniforms: np.ndarray | None = None,
    ) -> tuple[np.ndarray, TrXLState]:
        """One action per env: ``actions, state = act(frames, goals, state)``."""
        logits, state = self.logits(frames, goals, state, first)
        u = self._rng.random(len(logits)) if uniforms is None else np.asarray(uniforms)
        return sample_actions(logits, self.temperature, self.greedy, u), state


class CSteve1Agent:
    """``InstructableAgent`` for N envs: C-Steve-1 following each env's current instruction,
    read through ``goals`` (None: the policy's own, ``CSteve1Policy.goals``)."""

    name = "csteve1"
    needs_pixels = True

    def __init__(
        self, policy: CSteve1Policy, num_envs: int, goals: GoalEncoder | None = None
    ) -> None:
        if goals is not None and goals.goal_dim != policy.goal_dim:
            raise ValueError(
                f"the C-CLIP embeds {goals.goal_dim} dimensions but C-Steve-1 expects "
                f"goal_dim={policy.goal_dim}: use the C-CLIP it was trained with"
            )
        self.policy = policy
        self._goals = goals
        self.num_envs = num_envs
        self._state = policy.initial_state(num_envs)
        self._episodes = EpisodeStreams(num_envs)
        self._seeds = np.zeros(num_envs, dtype=np.int64)
        self._goal = torch.zeros(num_envs, policy.goal_dim)
        self.instructions: list[str | None] = [None] * num_envs

    @property
    def goals(self) -> GoalEncoder:
        """What reads its text instructions."""
        return self.policy.goals if self._goals is None else self._goals

    @property
    def inference(self) -> dict[str, float]:
        """The guidance scale and temperature it plays at (0: the most likely action), as
        resolved from its export or given: what a report records."""
        temperature = 0.0 if self.policy.greedy else self.policy.temperature
        return {"cfg_scale": self.policy.cfg_scale, "temperature": temperature}

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> None:
        """New episodes where ``mask``: fresh memory, and the current instruction's goal is
        drawn again from the new episode seed."""
        for i in self._episodes.reset(seeds, mask):
            self._seeds[i] = int(seeds[i])
            self._draw_goal(i)

    def instruct(self, instructions: list[str | None], mask: np.ndarray | None = None) -> None:
        """Give env i ``instructions[i]`` where ``mask[i]`` (all if None); None: no goal.

        The goal is drawn from the prior once per instruction and episode, seeded by the
        episode seed and the text, so an episode's goals depend on its seed alone.
        """
        if len(instructions) != self.num_envs:
            raise ValueError(f"{len(instructions)} instructions for {self.num_envs} envs")
        for i in range(self.num_envs) if mask is None else np.flatnonzero(mask):
            if instructions[i] != self.instructions[i]:
                self.instructions[i] = instructions[i]
                self._draw_goal(i)

    def _draw_goal(self, i: int) -> None:
        text = self.instructions[i]
        if text is None:
            self._goal[i] = 0
            return
        seed = int(self._seeds[i]) ^ zlib.crc32(text.encode())
        self._goal[i] = self.goals.from_text([text], seed=seed)[0]

    def act(self, step: Step) -> np.ndarray:
        if step.frames is None:
            raise ValueError("CSteve1Agent plays from pixels: make the env with pixels=True")
        episodes = self._episodes
        actions, self._state = self.policy.act(
            step.frames, self._goal, self._state, episodes.first, episodes.uniforms()
        )
        episodes.stepped()
        return actions.astype(np.int32)


__all__ = [
    "GoalEncoder",
    "CSteve1Agent",
    "CSteve1Policy",
    "instruction_note",
    "is_csteve1_checkpoint",
]
