"""N game slots as Gymnasium sees them: observations, rewards, end signals, info, episode seeds.

The single env and the native vector env both step one ``GameBatch``, so they cannot disagree.
It holds a zoo ``GameEnv`` (or the ``TaskEnv`` that ``zoo eval --task`` plays) and adds what
Gymnasium needs and the zoo's batched interface lacks:

- **Episode seeds.** Slot i plays episodes ``offset_i, offset_i + stride, ...`` of its run seed
  s, episode j seeded ``episode_seed(s, j)``, as ``zoo eval --seed s`` seeds its episode j. A
  single env (offset 0, stride 1) seeded s plays ``zoo eval --seed s``'s episodes 0, 1, 2, ...
  in order; slot i of n plays i, i + n, ..., so n slots seeded s start with its episodes 0..n-1.
- **terminated vs truncated.** Death (health 0, or lava in Craftax) and task success terminate;
  the step limit truncates. The game itself runs with a limit of at least ``GAME_LIMIT`` and the
  limit is enforced here, so every Craftax env shares one compiled program whatever its task
  (a limit is a constant inside the jitted step: 3 limits would cost 3 compiles). The game's
  limit only ends the episode, so enforcing it here gives the same episodes.
- **Observations.** 144-px frames, 72-px frames (the 2x2 mean, what C-VPT's
  ``input_downsample=2`` sees), Craftax-Classic's symbolic vector, or pixels and symbolic as a
  ``Dict``.
- **info** (batched arrays): ``achievements`` (N, 22) bool, those unlocked this step (names:
  ``zoo.envs.ACHIEVEMENT_NAMES``); ``episode_index`` and ``episode_seed``; for tasks
  ``subtasks_done`` and ``success``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from gymnasium import spaces

from zoo.envs import ENV_NAMES, NUM_ACHIEVEMENTS, NUM_ACTIONS, Block, make_env
from zoo.envs.base import GameEnv, Step, episode_seed
from zoo.envs.schema import FRAME_SHAPE
from zoo.envs.tasks import TaskEnv, get_task

GAME_LIMIT = 10_000  # crafter's and the paper's episode limit
SIZES = (FRAME_SHAPE[0], FRAME_SHAPE[0] // 2)
_HEALTH = 0  # column of player_vitals


@dataclass(frozen=True)
class ObsSpec:
    """What an observation holds: frames of ``size`` px (None: none) and/or Craftax's symbolic
    vector; both make a ``Dict`` with keys "pixels" and "symbolic"."""

    size: int | None = FRAME_SHAPE[0]
    symbolic: bool = False

    def check(self, game: str) -> None:
        if self.size is not None and self.size not in SIZES:
            raise ValueError(f"size must be one of {SIZES} (or None for no pixels), got {self.size}")
        if self.symbolic and game != "craftax":
            raise ValueError("the symbolic observation is Craftax-Classic's: use game='craftax'")
        if self.size is None and not self.symbolic:
            raise ValueError("an observation needs pixels (size) or symbolic=True")

    def space(self) -> spaces.Space:
        parts: dict[str, spaces.Space] = {}
        if self.size is not None:
            parts["pixels"] = spaces.Box(0, 255, (self.size, self.size, 3), np.uint8)
        if self.symbolic:
            parts["symbolic"] = spaces.Box(-1.0, 1.0, (symbolic_dim(),), np.float32)
        return spaces.Dict(parts) if len(parts) > 1 else next(iter(parts.values()))


def symbolic_dim() -> int:
    """Length of Craftax-Classic's symbolic observation (1345)."""
    from craftax.craftax_classic.constants import OBS_DIM, BlockType

    return OBS_DIM[0] * OBS_DIM[1] * (len(BlockType) + 4) + 12 + 4 + 4 + 2


def downsample(frames: np.ndarray) -> np.ndarray:
    """(N, 144, 144, 3) -> (N, 72, 72, 3) uint8, the rounded mean of each 2x2 block."""
    f = frames.reshape(len(frames), 72, 2, 72, 2, 3).astype(np.uint16)
    total = f[:, :, 0, :, 0] + f[:, :, 0, :, 1] + f[:, :, 1, :, 0] + f[:, :, 1, :, 1]
    return ((total + 2) >> 2).astype(np.uint8)


def _symbolic_fn():
    import jax
    from craftax.craftax_classic.renderer import render_craftax_symbolic

    return jax.jit(jax.vmap(render_craftax_symbolic))


class GameBatch:
    """``num_envs`` slots of ``game`` (playing ``task`` if given); see the module docstring.

    Args:
        game: "craftax" or "crafter".
        task: a ``zoo eval --task`` name (reward 1 per sub-task completed in order, terminate
            on success), or None for the game (crafter's reward).
        obs: what observations hold.
        max_steps: step limit (default: the task's, else 10,000).
        offsets, stride: slot i plays episodes ``offsets[i] + k * stride`` of its run seed
            (default: i + k * num_envs).
        render: keep 144-px frames for ``render()`` even when observations have none.
    """

    def __init__(
        self,
        game: str,
        num_envs: int,
        task: str | None = None,
        obs: ObsSpec = ObsSpec(),
        max_steps: int | None = None,
        offsets: np.ndarray | None = None,
        stride: int | None = None,
        render: bool = False,
    ) -> None:
        if game not in ENV_NAMES:
            raise ValueError(f"unknown game {game!r}; expected one of {ENV_NAMES}")
        obs.check(game)
        spec = get_task(task) if task is not None else None
        self.max_steps = max_steps or (spec.max_steps if spec else GAME_LIMIT)
        if self.max_steps < 1:
            raise ValueError(f"max_steps must be >= 1, got {self.max_steps}")
        self.game, self.task, self.obs, self.num_envs = game, spec, obs, num_envs
        pixels = obs.size is not None or render
        env: GameEnv = make_env(game, num_envs, pixels, max(self.max_steps, GAME_LIMIT))
        self.env: GameEnv | TaskEnv = TaskEnv(env, spec) if spec else env
        self.observation_space = obs.space()
        self.action_space = spaces.Discrete(NUM_ACTIONS)
        self.offsets = np.arange(num_envs) if offsets is None else np.asarray(offsets, np.int64)
        self.stride = num_envs if stride is None else stride
        self.run_seed = np.full(num_envs, -1, np.int64)  # -1: not seeded yet
        self.episode = np.zeros(num_envs, np.int64)
        self.seeds = np.zeros(num_envs, np.int64)  # each slot's current episode seed
        self._next = self.offsets.copy()
        self._symbolic = _symbolic_fn() if obs.symbolic else None
        self.last: Step | None = None

    def reset(self, mask: np.ndarray, seed: int | None = None, episode: int | None = None):
        """Start the next episode in slots ``mask``: ``seed`` restarts their run (at their
        offset), ``episode`` jumps to that episode index. Returns (obs, info) of every slot."""
        if seed is not None:
            if seed < 0:
                raise ValueError(f"seed must be >= 0, got {seed}")
            self.run_seed[mask] = seed
            self._next[mask] = self.offsets[mask]
        if episode is not None:
            if episode < 0:
                raise ValueError(f"episode must be >= 0, got {episode}")
            self._next[mask] = episode
        if (self.run_seed[mask] < 0).any():
            raise RuntimeError("GameBatch.reset needs a seed for slots never seeded")
        for i in np.flatnonzero(mask):
            self.episode[i] = self._next[i]
            self._next[i] += self.stride
            self.seeds[i] = episode_seed(int(self.run_seed[i]), int(self.episode[i]))
        self.last = self.env.reset(self.seeds, mask)
        none = np.zeros((self.num_envs, NUM_ACHIEVEMENTS), bool)
        return self._obs(self.last), self._info(none)

    def step(self, actions: np.ndarray):
        """Step every slot: (obs, reward, terminated, truncated, info), batched."""
        before = self.last.state["achievements"]
        step = self.env.step(np.asarray(actions))
        state = step.state
        rows = np.arange(self.num_envs)
        row, col = state["player_pos"][:, 0], state["player_pos"][:, 1]
        dead = (state["player_vitals"][:, _HEALTH] <= 0) | (
            state["map"][rows, row, col] == Block.LAVA
        )
        time_up = state["timestep"] >= self.max_steps
        if self.task is not None:
            reward = self.env.completed.astype(np.float32)
            success = self.env.progress.success
        else:
            reward = step.reward.astype(np.float32)
            success = np.zeros(self.num_envs, bool)
        terminated = dead | success | (step.done & ~time_up)
        truncated = time_up & ~terminated
        self.last = step
        info = self._info(state["achievements"] & ~before)
        return self._obs(step), reward, terminated, truncated, info

    def _obs(self, step: Step):
        out = {}
        if self.obs.size is not None:
            out["pixels"] = step.frames if self.obs.size == SIZES[0] else downsample(step.frames)
        if self._symbolic is not None:
            out["symbolic"] = np.asarray(self._symbolic(step.raw), np.float32)
        return out if len(out) > 1 else next(iter(out.values()))

    def _info(self, unlocked: np.ndarray) -> dict[str, np.ndarray]:
        info = {
            "achievements": unlocked,
            "episode_index": self.episode.copy(),
            "episode_seed": self.seeds.copy(),
        }
        if self.task is not None:
            info["subtasks_done"] = self.env.progress.next.copy()
            info["success"] = self.env.progress.success.copy()
        return info

    def frames(self) -> np.ndarray:
        """The last 144-px frames (N, 144, 144, 3), for ``render()``."""
        if self.last is None or self.last.frames is None:
            raise RuntimeError("no frames: reset first, and make the env with pixels or render_mode")
        return self.last.frames
