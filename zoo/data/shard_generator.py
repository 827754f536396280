"""One process's generation: an agent plays batched envs and its episodes become one shard.

Shard i holds episodes [i*E, (i+1)*E) and episode j is seeded from (seed, j) alone, so a
shard's bytes depend only on (seed, i) and the generation arguments: never on --workers or
--num-envs. The agent comes from ``build_agent(config, num_envs)``, which the caller passes
(``zoo.agents.dataset_agent``): agents sit above this package and are not imported here.
"""

from __future__ import annotations

import os
import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from zoo.data.codec import PLANES_SHAPE, FrameCodec
from zoo.data.manifest import package_versions
from zoo.data.noop import noop_counts, noop_runs
from zoo.data.play_modes import DaggerLabels, Instructions, NoInstructions, PlayedActions
from zoo.data.rerender import renderer_version
from zoo.data.shards import (
    SHARD_PATTERN,
    STATE_ROW_BYTES,
    BufferPool,
    ChunkEncoder,
    EpisodeRecorder,
    FragmentSink,
    state_views,
)
from zoo.data.tar_writer import ShardAssembler
from zoo.envs.base import Step, episode_seed
from zoo.envs.constants import ACHIEVEMENT_NAMES
from zoo.envs.schema import FRAME_SHAPE
from zoo.envs.tasks.starts import START_STATES, TaskStartEnv
from zoo.experts.scripted.schedule import InstructionSchedule

ProgressFn = Callable[[int, int], None]  # (episodes finished, frames recorded) since last call
AgentBuilder = Callable[["GenerationConfig", int], object]
"""``build_agent(config, num_envs)``: the agent that plays a dataset's episodes (a module-level
function, so spawned workers can receive it; ``zoo.agents.dataset_agent``)."""


@dataclass(frozen=True)
class DaggerSettings:
    """A DAgger dataset's rollouts (``zoo data dagger``): the learner plays, the expert labels
    every state it reaches. Stored nested in the manifest's ``config`` as ``dagger``.

    Args:
        learner: the learner as ``zoo.agents.AgentSpec.record`` writes it: a C-VPT or C-Steve-1
            (kind), its checkpoint and, for a C-Steve-1, its goal models, each with its sha256
            (so other weights at the same path make another dataset), its temperature and
            guidance.
        beta: probability that the expert acts instead of the learner.
        mix: "episode" or "step", what one beta draw decides.
        round: the round number, for the record.
    """

    learner: dict = field(hash=False)  # a dict: keep hash() working
    beta: float
    mix: str
    round: int | None = None

    def __post_init__(self) -> None:
        # the values' ranges are checked by the agents that play them (``DaggerMixture``)
        if not isinstance(self.learner, dict) or not {"kind", "checkpoint",
                                                      "checkpoint_sha256"} <= self.learner.keys():
            raise ValueError("a DAgger dataset's learner is an AgentSpec record with kind, "
                             f"checkpoint and checkpoint_sha256, got {self.learner!r}")


@dataclass(frozen=True)
class GenerationConfig:
    """Everything that decides a dataset's content (stored in the manifest as ``config``).

    Args:
        expert: agent kind of ``zoo.agents.AgentSpec`` ("scripted", "ppo", "random").
        checkpoint: the expert's checkpoint (PPO), None otherwise.
        episodes: episodes in the dataset.
        seed: dataset seed; episode j is seeded from (seed, j).
        env: "craftax" or "crafter".
        episodes_per_shard: episodes per tar shard.
        chunk_length: steps per WebDataset sample.
        max_steps: episode step limit.
        min_noop_run: filter threshold used for the noop statistics in the manifest.
        zstd_level: zstd level for frames and arrays.
        zstd_window_log: zstd window (log2 bytes).
        frames: "stored": frames coded as images; "rendered" (Craftax only): each frame as
            its residual against a re-render from the stored state, ~1/100 of the bytes for a
            re-render at decoding (``zoo.data.rerender``).
        expert_options: overrides of the scripted expert's ``ExpertConfig`` fields (e.g.
            ``{"plants_first": True}``); empty: its defaults.
        dagger: DAgger rollouts, the expert labelling a learner's play; None: the expert plays.
            A dict (as read back from a manifest) becomes ``DaggerSettings``.
        instructions: the schedule of captions the scripted expert is told one after another
            (``zoo.experts.scripted.schedule``), each step recording the one it pursued; None:
            normal play. With ``dagger`` a C-Steve-1 learner is told the same instructions. A dict (as read back from a manifest) becomes ``InstructionSchedule``.
        start_states: "default": the game's own start; "tasks": each episode starts
            with one of the task suites' starting inventories (``zoo.envs.tasks.starts``).
    """

    expert: str
    episodes: int
    seed: int
    env: str = "craftax"
    checkpoint: str | None = None
    episodes_per_shard: int = 16
    chunk_length: int = 256
    max_steps: int = 10_000
    min_noop_run: int = 20
    zstd_level: int = 2
    zstd_window_log: int = 25
    frames: str = "stored"
    expert_options: dict = field(default_factory=dict, hash=False)  # a dict: keep hash() working
    dagger: DaggerSettings | None = None
    instructions: InstructionSchedule | None = None
    start_states: str = "default"

    def __post_init__(self) -> None:
        if self.expert_options and self.expert != "scripted":
            raise ValueError(
                f"expert_options apply to the scripted expert only, got expert={self.expert!r}"
            )
        if self.frames not in ("stored", "rendered"):
            raise ValueError(f"frames must be 'stored' or 'rendered', got {self.frames!r}")
        if self.frames == "rendered" and self.env != "craftax":
            raise ValueError(
                f"frames='rendered' needs env='craftax' (its frames are a function of the "
                f"stored state), got env={self.env!r}; use frames='stored'"
            )
        if isinstance(self.dagger, dict):
            object.__setattr__(self, "dagger", DaggerSettings(**self.dagger))
        if isinstance(self.instructions, dict):
            object.__setattr__(self, "instructions", InstructionSchedule(**self.instructions))
        if self.instructions is not None and self.expert != "scripted":
            raise ValueError(
                "an instruction schedule is followed by the scripted expert (alone, or labelling"
                f" a learner told the same instructions), got expert={self.expert!r}"
            )
        if self.start_states not in START_STATES:
            raise ValueError(
                f"start_states must be one of {START_STATES}, got {self.start_states!r}"
            )

    @property
    def num_shards(self) -> int:
        return -(-self.episodes // self.episodes_per_shard)

    def shard_episodes(self, index: int) -> range:
        start = index * self.episodes_per_shard
        return range(start, min(start + self.episodes_per_shard, self.episodes))

    @property
    def codec(self) -> FrameCodec:
        return FrameCodec(self.zstd_level, self.zstd_window_log)


class ShardGenerator:
    """Holds one env batch and one agent (built once per process) and writes shards.

    Args:
        config: the dataset's generation arguments.
        num_envs: episodes played at once (does not change the data).
        build_agent: makes the agent for ``config`` (``zoo.agents.dataset_agent``).
    """

    def __init__(self, config: GenerationConfig, num_envs: int, build_agent: AgentBuilder) -> None:
        from zoo.envs import make_env

        self.config = config
        self.num_envs = max(1, min(num_envs, config.episodes_per_shard, config.episodes))
        self.agent = build_agent(config, self.num_envs)
        self.pixels = _env_draws_frames(config, self.agent)
        self.env = make_env(
            config.env, self.num_envs, pixels=self.pixels, max_steps=config.max_steps)
        if config.start_states == "tasks":
            self.env = TaskStartEnv(self.env)
        n = self.num_envs
        self.labelling = DaggerLabels(self.agent, n) if config.dagger else PlayedActions()
        self.instructions = (NoInstructions(n) if config.instructions is None
                             else Instructions(config.instructions, self.agent, n))
        self.versions = package_versions()
        self.renderer = renderer_version() if config.frames == "rendered" else None
        self.buffers = BufferPool()  # recorders' buffers, reused from shard to shard
        self._rows = np.empty((self.num_envs, STATE_ROW_BYTES), np.uint8)
        self._row_fields = state_views(self._rows)  # a step's states, packed once for all envs
        self._meta = {"env": config.env, "expert": config.expert}  # in every sample's meta.json
        if config.dagger is not None:
            self._meta["source"] = "dagger"
        if self.renderer is not None:
            self._meta["renderer"] = self.renderer

    def run(self, index: int, out: Path, progress: ProgressFn | None = None) -> dict:
        """Play shard ``index``'s episodes, write the shard, return its manifest entry."""
        cfg, n = self.config, self.num_envs
        workdir = Path(out) / f".work-{index:06d}-{os.getpid()}"
        shutil.rmtree(workdir, ignore_errors=True)
        workdir.mkdir(parents=True)
        episodes = iter(cfg.shard_episodes(index))
        summaries: dict[int, dict] = {}
        recorders: list[EpisodeRecorder | None] = [None] * n
        seeds = np.zeros(n, np.int64)
        path = Path(out) / SHARD_PATTERN.format(index=index)
        with (ShardAssembler(path, cfg.shard_episodes(index)) as assembler,
              ChunkEncoder(max_pending=n + 1, pool=self.buffers) as encoder):
            self._prefill(encoder)

            def start(slot: int) -> bool:
                episode = next(episodes, None)
                recorders[slot] = None if episode is None else self._recorder(
                    episode, seeds, slot, workdir, encoder)
                return episode is not None

            for slot in range(n):
                start(slot)
            step = self._reset(seeds, None, recorders)
            frames = 0
            while any(rec is not None for rec in recorders):
                actions = np.asarray(self.agent.act(step))
                commanded = self.instructions.commanded()
                after = self.env.step(actions)
                self.instructions.update(step.state, after.state)
                labels, noop = self.labelling.labels(actions, step, after)
                restart = np.zeros(n, bool)
                rngs, rows = self._state_rngs(after), self._pack(after.state)
                # python scalars once per step: indexing numpy arrays env by env costs more
                rewards, dones = np.asarray(after.reward).tolist(), np.asarray(after.done).tolist()
                per_env = zip(labels.tolist(), rewards, noop.tolist(), commanded.tolist(), strict=True)
                for slot, (rec, (label, reward, flag, instruction)) in enumerate(
                    zip(recorders, per_env, strict=True)
                ):
                    if rec is None:
                        continue
                    rec.act(label, reward, flag, instruction)
                    rec.observe(_frame(after, slot), None, rngs[slot], rows[slot])
                    frames += 1
                    if dones[slot]:  # its fragment goes into the shard on the encoder, in turn
                        summaries[rec.episode] = self._summary(rec, slot, assembler.add_blocks)
                        if progress:
                            progress(1, frames)
                            frames = 0
                        restart[slot] = start(slot)
                step = after
                if restart.any():
                    fresh = self._reset(seeds, restart, recorders)
                    step = Step(fresh.frames, fresh.state, after.reward, after.done & ~restart,
                                fresh.raw)
                if progress and frames >= 1024:
                    progress(0, frames)
                    frames = 0
            if progress and frames:
                progress(0, frames)
            order = sorted(summaries)
            for e in order:
                summaries[e].pop("written").result()  # raises if writing a fragment failed
            sha = encoder.submit(assembler.close).result()
        shutil.rmtree(workdir, ignore_errors=True)
        return self._entry(index, path, sha, [summaries[e] for e in order])

    def _prefill(self, encoder: ChunkEncoder) -> None:
        """Pool the buffers the frame mode needs, as many as can be in use at once: a chunk
        filling per env, and the queued and coding ones."""
        chunk, in_use = self.config.chunk_length, 2 * self.num_envs + 2
        if self.pixels:  # drawn frames are copied into pooled buffers
            encoder.submit(self.buffers.prefill, (chunk, *FRAME_SHAPE), in_use)
        elif self.renderer is None:  # or drawn into one on the encoder
            encoder.submit(self.buffers.prefill, (chunk, *FRAME_SHAPE), 1)
        if self.renderer is None:  # and laid out for the codec in one more
            encoder.submit(self.buffers.prefill, (3, chunk, *PLANES_SHAPE[1:]), 1)
        encoder.submit(self.buffers.prefill, (chunk, STATE_ROW_BYTES), in_use)

    def _recorder(
        self, episode: int, seeds: np.ndarray, slot: int, workdir: Path, encoder: ChunkEncoder
    ) -> EpisodeRecorder:
        """Env ``slot`` starts ``episode``: its seed goes into ``seeds``; its recorder."""
        cfg = self.config
        seeds[slot] = episode_seed(cfg.seed, episode)
        self.labelling.start(slot)
        return EpisodeRecorder(
            episode, int(seeds[slot]), workdir, cfg.chunk_length, self._meta, encoder, cfg.codec,
            rendered=self.renderer is not None, instructed=cfg.instructions is not None,
            drawn=self.pixels,
        )

    def _reset(self, seeds: np.ndarray, mask: np.ndarray | None, recorders: list) -> Step:
        """New episodes where ``mask`` (None: everywhere): env, agent and schedule reset, and
        the first frames recorded."""
        step = self.env.reset(seeds, mask=mask)
        self.agent.reset(seeds, mask=mask)
        self.instructions.reset(seeds, mask)
        self._observe(step, recorders, np.ones(self.num_envs, bool) if mask is None else mask)
        return step

    def _state_rngs(self, step: Step) -> np.ndarray | list[None]:
        """Per env, Craftax's ``state_rng`` (rendered frames, and frames the env did not draw,
        need it), else None. Read now: the env's next call donates the buffers of ``step.raw``."""
        if self.renderer is None and self.pixels:
            return [None] * self.num_envs
        return np.asarray(step.raw.state_rng)

    def _pack(self, state: dict) -> np.ndarray:
        """The envs' states packed in rows (``zoo.data.shards.state_views``); reused buffer."""
        for k, column in self._row_fields.items():
            column[...] = state[k]
        return self._rows

    def _observe(self, step: Step, recorders: list, mask: np.ndarray) -> None:
        rngs = self._state_rngs(step)
        rows = self._pack(step.state)
        for slot in np.flatnonzero(mask):
            if recorders[slot] is not None:
                recorders[slot].observe(_frame(step, slot), None, rngs[slot], rows[slot])

    def _summary(self, rec: EpisodeRecorder, slot: int, sink: FragmentSink) -> dict:
        """Finish the episode (its fragment to ``sink``), keep what the manifest reports."""
        segments = self.instructions.finish(slot)
        written = rec.finish(None if segments is None else {"instructions": segments}, sink)
        noop = np.asarray(rec.noop, bool)
        actions = np.asarray(rec.actions)
        counts = noop_counts(
            noop, noop_runs(noop), actions, self.config.min_noop_run, np.asarray(rec.sleeping)
        )
        return {
            "episode": rec.episode, "seed": rec.seed, "length": len(rec.actions), "noop": counts,
            "written": written,
            "achievements": rec.final_state["achievements"].astype(bool),
            "return": float(np.sum(rec.rewards)),
            "instructions": segments,
            **self.labelling.finish(slot),
        }

    def _entry(self, index: int, path: Path, sha: str, episodes: list[dict]) -> dict:
        cfg = self.config
        noop = {k: sum(e["noop"][k] for e in episodes) for k in episodes[0]["noop"]}
        noop["ratio_before"] = noop["noop_steps"] / max(noop["steps"], 1)
        noop["ratio_after"] = noop["kept_noop_steps"] / max(noop["kept_steps"], 1)
        noop["min_run"] = cfg.min_noop_run
        unlocks = np.sum([e["achievements"] for e in episodes], axis=0)
        extra = {}
        if self.renderer is not None:
            extra["renderer"] = self.renderer
        extra |= self.instructions.entry(episodes) | self.labelling.entry(episodes)
        return {
            **extra,
            "file": path.name,
            "index": index,
            "sha256": sha,
            "bytes": path.stat().st_size,
            "episodes": len(episodes),
            "first_episode": episodes[0]["episode"],
            "episode_seeds": [e["seed"] for e in episodes],
            "episode_lengths": [e["length"] for e in episodes],
            "episode_returns": [e["return"] for e in episodes],
            "steps": sum(e["length"] for e in episodes),
            "seed": cfg.seed,
            "expert": cfg.expert,
            "env": cfg.env,
            "chunk_length": cfg.chunk_length,
            "versions": self.versions,
            "noop": noop,
            "achievement_unlocks": dict(zip(ACHIEVEMENT_NAMES, map(int, unlocks))),
        }


def _env_draws_frames(config: GenerationConfig, agent) -> bool:
    """Whether the env draws the frames. Craftax frames of a state-only expert are drawn on
    the encoder thread from the states instead, so the playing thread never renders: always in
    the rendered mode (the re-render that codes a chunk is its frames), and in the stored mode
    where the env would draw them with the numba renderer. JAX's renderer (on a GPU, or
    ZOO_RENDERER=jax) draws inside the env's jitted step for less than a JAX re-render costs
    the encoder (stored generation at 0.93x raw play there, 0.73x re-rendered on 2 cores)."""
    if config.env != "craftax" or getattr(agent, "needs_pixels", True):
        return True
    if config.frames == "rendered":
        return False
    from zoo.envs.craftax_env import env_renderer

    return env_renderer() != "numba"


def _frame(step: Step, slot: int) -> np.ndarray | None:
    """Env ``slot``'s frame, or None when the env draws none (Craftax, state-only expert)."""
    return None if step.frames is None else step.frames[slot]
