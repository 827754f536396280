"""Play an agent for a fixed set of episodes in batched envs, reproducibly.

Episode j always gets the seed ``episode_seed(seed, j)`` for both the env and the agent, and
the results are exactly episodes 0..episodes-1, so they do not depend on how many envs run in
parallel or which slot an episode landed in: changing ``--num-envs`` changes speed only.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from tqdm.auto import tqdm

from zoo.agents.base import Agent
from zoo.envs.base import GameEnv, episode_seed
from zoo.envs.constants import NUM_ACHIEVEMENTS
from zoo.eval.death import death_cause


@dataclass
class EpisodeResult:
    """What one episode achieved.

    ``unlock_step[i]`` is the number of steps taken when achievement i was first unlocked
    (1..length), -1 if never. ``death`` is why it ended (``zoo.eval.death.DEATH_CAUSES``).
    ``frames`` (uint8 (T, H, W, 3)) is kept for the GIF episode only,
    subsampled evenly over the whole episode (see ``FrameSampler``); None for the others.
    """

    index: int
    seed: int
    length: int
    episode_return: float
    unlocked: np.ndarray  # (22,) bool, zoo achievement order
    unlock_step: np.ndarray  # (22,) int64
    death: str = "other"
    frames: np.ndarray | None = None


class FrameSampler:
    """Keeps every ``stride``-th frame and doubles the stride when more than ``max_frames`` pile
    up, so memory stays bounded for a 10,000-step episode yet covers it start to end."""

    def __init__(self, max_frames: int) -> None:
        if max_frames < 2:
            raise ValueError(f"max_frames must be >= 2, got {max_frames}")
        self.max_frames = max_frames
        self.stride = 1
        self._steps: list[int] = []
        self._frames: list[np.ndarray] = []

    def add(self, t: int, frame: np.ndarray) -> None:
        if t % self.stride:
            return
        self._steps.append(t)
        self._frames.append(frame.copy())  # a view would pin the whole batch array
        if len(self._frames) > self.max_frames:
            self._steps, self._frames = self._steps[::2], self._frames[::2]
            self.stride *= 2

    def finish(self, t: int, frame: np.ndarray) -> np.ndarray:
        """Stack the kept frames, ending on the final frame (so at most ``max_frames + 1``)."""
        if not self._steps or self._steps[-1] != t:
            self._steps.append(t)
            self._frames.append(frame.copy())
        return np.stack(self._frames)


class _Slot:
    """Book-keeping of the episode running in one env slot."""

    def __init__(self, index: int, seed: int, sampler: FrameSampler | None) -> None:
        self.index, self.seed, self.sampler = index, seed, sampler
        self.length = 0
        self.episode_return = 0.0
        self.unlock_step = np.full(NUM_ACHIEVEMENTS, -1, np.int64)

    def record(self, reward: float, achievements: np.ndarray, frame: np.ndarray | None) -> None:
        self.length += 1
        self.episode_return += reward
        self.unlock_step[(self.unlock_step < 0) & achievements.astype(bool)] = self.length
        if self.sampler is not None and frame is not None:
            self.sampler.add(self.length, frame)

    def result(self, last_frame: np.ndarray | None, death: str) -> EpisodeResult:
        frames = None
        if self.sampler is not None and last_frame is not None:
            frames = self.sampler.finish(self.length, last_frame)
        return EpisodeResult(
            index=self.index,
            seed=self.seed,
            length=self.length,
            episode_return=self.episode_return,
            unlocked=self.unlock_step >= 0,
            unlock_step=self.unlock_step.copy(),
            death=death,
            frames=frames,
        )


def evaluate(
    agent: Agent,
    env: GameEnv,
    episodes: int,
    seed: int,
    on_episode: Callable[[EpisodeResult], None] | None = None,
    record_gif_episode: int | None = 0,
    gif_max_frames: int = 600,
    progress: bool = True,
) -> list[EpisodeResult]:
    """Run ``agent`` in ``env`` (``env.num_envs`` at once) for episodes 0..episodes-1.

    A finished env is reset (masked) with the next episode's seed until every episode has
    started; slots left without an episode keep stepping but are ignored. Achievements are
    read from the state after each step and not after ``done`` (Craftax keeps stepping a done
    env). Episode return is the sum of the env's step rewards (crafter's reward).

    Args:
        agent: plays all ``env.num_envs`` envs; reset per episode with the episode's seed.
        env: batched env, made with ``pixels=True`` if a GIF is wanted.
        episodes: how many episodes to play (>= 1).
        seed: run seed (>= 0); episode j uses ``episode_seed(seed, j)``.
        on_episode: called with each result as it finishes (finish order, not index order).
        record_gif_episode: index of the episode whose frames are kept; None keeps none.
        gif_max_frames: bound on the frames kept for that episode.
        progress: show a tqdm bar (episodes done, env-steps/s).

    Returns:
        One ``EpisodeResult`` per episode, sorted by index.
    """
    if episodes < 1:
        raise ValueError(f"episodes must be >= 1, got {episodes}")
    n = env.num_envs
    slots: list[_Slot | None] = [None] * n
    seeds = np.zeros(n, np.int64)  # slots without an episode reset with seed 0 and are ignored

    def start(i: int, j: int) -> None:
        """Put episode j into slot i (the env and agent are reset by the caller)."""
        sampler = FrameSampler(gif_max_frames) if j == record_gif_episode else None
        slots[i] = _Slot(j, episode_seed(seed, j), sampler)
        seeds[i] = slots[i].seed

    def first_frames(step, mask: np.ndarray) -> None:
        for i in np.flatnonzero(mask):
            if slots[i] is not None and slots[i].sampler is not None and step.frames is not None:
                slots[i].sampler.add(0, step.frames[i])

    for i in range(min(n, episodes)):
        start(i, i)
    next_episode = min(n, episodes)
    step = env.reset(seeds)
    agent.reset(seeds)
    first_frames(step, np.ones(n, bool))

    results: list[EpisodeResult] = []
    # the rate is timed from the end of the first step, which compiles Craftax's step (seconds):
    # counted from the start, a short evaluation would show steps_per_s=0 to its end
    env_steps, started, shown = 0, None, 0.0
    bar = tqdm(total=episodes, unit="ep", desc=f"eval {env.name}", disable=not progress)
    try:
        while len(results) < episodes:
            before = step.state
            step = env.step(agent.act(step))
            reset_mask = np.zeros(n, bool)
            for i, slot in enumerate(slots):
                if slot is None:
                    continue
                frame = None if step.frames is None else step.frames[i]
                slot.record(float(step.reward[i]), step.state["achievements"][i], frame)
                env_steps += 1
                if not step.done[i]:
                    continue
                result = slot.result(frame, death_cause(before, step.state, i))
                results.append(result)
                bar.update(1)
                if on_episode is not None:
                    on_episode(result)
                slots[i] = None
                if next_episode < episodes:
                    start(i, next_episode)
                    reset_mask[i] = True
                    next_episode += 1
            if reset_mask.any():
                step = env.reset(seeds, reset_mask)
                agent.reset(seeds, reset_mask)
                first_frames(step, reset_mask)
            now = time.perf_counter()
            if started is None:
                env_steps, started, shown = 0, now, now
            elif len(results) == episodes or now - shown > 1.0:  # each second, and at the end
                bar.set_postfix(steps_per_s=f"{env_steps / (now - started):.0f}")
                shown = now
    finally:
        bar.close()
    return sorted(results, key=lambda r: r.index)
