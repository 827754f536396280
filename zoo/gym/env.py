"""``CrafterDojoEnv``: one Crafter or Craftax-Classic game (or a task of it) as a ``gymnasium.Env``.

It is slot 0 of a one-slot ``GameBatch`` (seeding, end signals and info are defined there).
``reset(seed=s)`` plays episode 0 of ``zoo eval --seed s``, and each later ``reset()`` the next
one; ``reset(options={"episode": j})`` jumps to episode j of the current run seed. An unseeded
first reset draws the run seed from ``np_random`` (entropy from the OS), as Gymnasium does.
"""

from __future__ import annotations

from typing import Any, ClassVar

import gymnasium
import numpy as np

from zoo.gym.batch import GameBatch, ObsSpec

_ONE = np.ones(1, bool)


def unbatch(tree: Any) -> Any:
    """Row 0 of a batched observation or info (arrays, or dicts of them)."""
    if isinstance(tree, dict):
        return {k: unbatch(v) for k, v in tree.items()}
    return tree[0]


class CrafterDojoEnv(gymnasium.Env):
    """One game of ``game`` ("craftax" or "crafter"), playing ``task`` if given.

    Args:
        game: "craftax" (Craftax-Classic, JAX) or "crafter" (the original game).
        task: a task of ``zoo eval --task`` (reward 1 per sub-task completed in order,
            terminated on success), or None for the game itself (crafter's reward).
        size: frame size in pixels, 144 or 72 (the 2x2 mean); None for no pixels.
        symbolic: add Craftax-Classic's symbolic vector (a ``Dict`` when pixels are kept too).
        max_steps: step limit, truncating (default: the task's, else 10,000).
        render_mode: "rgb_array" renders the 144-px frame.
        episode_offset, episode_stride: play episodes ``offset + k * stride`` of the run seed
            (how ``CrafterVectorEnv`` gives slot i of n the episodes i, i + n, ...).
    """

    metadata: ClassVar[dict] = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        game: str = "craftax",
        task: str | None = None,
        size: int | None = 144,
        symbolic: bool = False,
        max_steps: int | None = None,
        render_mode: str | None = None,
        episode_offset: int = 0,
        episode_stride: int = 1,
    ) -> None:
        if render_mode not in (None, *self.metadata["render_modes"]):
            raise ValueError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.render_mode = render_mode
        self.batch = GameBatch(
            game, 1, task, ObsSpec(size, symbolic), max_steps,
            offsets=np.array([episode_offset]), stride=episode_stride,
            render=render_mode is not None,
        )
        self.observation_space = self.batch.observation_space
        self.action_space = self.batch.action_space

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        super().reset(seed=seed)
        if seed is None and self.batch.run_seed[0] < 0:
            seed = int(self.np_random.integers(2**31))
        obs, info = self.batch.reset(_ONE, seed, (options or {}).get("episode"))
        return unbatch(obs), unbatch(info)

    def step(self, action: int) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        obs, reward, terminated, truncated, info = self.batch.step(np.array([action], np.int32))
        return unbatch(obs), float(reward[0]), bool(terminated[0]), bool(truncated[0]), unbatch(info)

    def render(self) -> np.ndarray | None:
        return self.batch.frames()[0] if self.render_mode == "rgb_array" else None
