"""Vector envs: Craftax-Classic batched natively (one JAX call per step), crafter in processes.

``CraftaxVectorEnv`` steps its N games with one jitted call of ``CraftaxEnv`` (not N Python
envs) and resets finished ones with one more; ``CrafterVectorEnv`` is Gymnasium's
``AsyncVectorEnv`` over ``CrafterDojoEnv`` (crafter is pure Python: processes give it cores).

Both take one run seed: ``reset(seed=s)`` starts slot i at episode i of ``zoo eval --seed s``
and each later episode of slot i is i + n, i + 2n, ... (fixed per slot, so timing never changes
which episode a slot plays). A list of per-env seeds is refused: it would not name episodes of
one run. Both declare their autoreset mode in ``metadata["autoreset_mode"]`` and support all
three of Gymnasium's (default ``NEXT_STEP``, as Gymnasium's own vector envs):

- ``NEXT_STEP``: the step after an episode ends resets that env (its action is ignored) and
  returns the new episode's first observation with reward 0 and both end signals False.
- ``SAME_STEP``: the ending step resets at once; the ended episode's last observation and info
  are in ``info["final_obs"]`` and ``info["final_info"]``.
- ``DISABLED``: the caller resets ended envs with ``reset(options={"reset_mask": mask})``.

A masked reset's info is Gymnasium's: the ``_key`` masks mark only the envs reset, and the other
envs' rows are zeros.
"""

from __future__ import annotations

from functools import partial
from typing import Any, ClassVar

import numpy as np
from gymnasium.vector import AsyncVectorEnv, AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from zoo.gym.batch import GameBatch, ObsSpec
from zoo.gym.env import CrafterDojoEnv


def _one_seed(seed: Any) -> int | None:
    if seed is not None and not isinstance(seed, int | np.integer):
        raise TypeError(
            f"seed must be one int (the run seed: env i plays its episodes i, i + n, ...) or "
            f"None, got {seed!r}"
        )
    return None if seed is None else int(seed)


def reset_mask(options: dict[str, Any] | None, num_envs: int) -> np.ndarray:
    """The envs a vector ``reset`` restarts: ``options["reset_mask"]``, else all."""
    mask = (options or {}).get("reset_mask")
    if mask is None:
        return np.ones(num_envs, bool)
    mask = np.asarray(mask)
    if mask.shape != (num_envs,) or mask.dtype != np.bool_ or not mask.any():
        raise ValueError(f"reset_mask must be a ({num_envs},) bool array with a True, got {mask!r}")
    return mask


def _rows_mask(mask: np.ndarray, like: np.ndarray) -> np.ndarray:
    return mask.reshape((-1,) + (1,) * (like.ndim - 1))


def masked_info(info: dict[str, np.ndarray], mask: np.ndarray) -> dict[str, np.ndarray]:
    """``info`` of the envs in ``mask`` as Gymnasium's vector envs batch it (``_add_info``):
    each key with its own ``_key`` mask, zeros in the rows of the other envs."""
    out, every = {}, mask.all()
    for key, value in info.items():
        out[key] = value if every else np.where(
            _rows_mask(mask, value), value, np.zeros_like(value)
        )
        out[f"_{key}"] = mask.copy()
    return out


def _rows(obs: Any, i: int) -> Any:
    return {k: v[i] for k, v in obs.items()} if isinstance(obs, dict) else obs[i]


class CraftaxVectorEnv(VectorEnv):
    """``num_envs`` Craftax-Classic games stepped by JAX in one call (``CrafterDojoEnv``'s
    arguments, plus ``autoreset_mode``)."""

    metadata: ClassVar[dict] = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        num_envs: int,
        task: str | None = None,
        size: int | None = 144,
        symbolic: bool = False,
        max_steps: int | None = None,
        render_mode: str | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
    ) -> None:
        self.batch = GameBatch(
            "craftax", num_envs, task, ObsSpec(size, symbolic), max_steps,
            render=render_mode is not None,
        )
        self.num_envs = num_envs
        self.render_mode = render_mode
        self.metadata = {**self.metadata, "autoreset_mode": AutoresetMode(autoreset_mode)}
        self.single_observation_space = self.batch.observation_space
        self.single_action_space = self.batch.action_space
        self.observation_space = batch_space(self.single_observation_space, num_envs)
        self.action_space = batch_space(self.single_action_space, num_envs)
        self._ended = np.zeros(num_envs, bool)  # ended and not reset yet

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        seed = _one_seed(seed)
        super().reset(seed=seed)
        mask = reset_mask(options, self.num_envs)
        if seed is None and (self.batch.run_seed[mask] < 0).any():
            seed = int(self.np_random.integers(2**31))
        obs, info = self.batch.reset(mask, seed)
        self._ended[mask] = False
        return obs, masked_info(info, mask)

    def step(self, actions: np.ndarray) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict]:
        mode = self.metadata["autoreset_mode"]
        if mode == AutoresetMode.DISABLED and self._ended.any():
            raise ValueError(
                f"envs {np.flatnonzero(self._ended).tolist()} ended: reset them with "
                "reset(options={'reset_mask': mask}) before stepping (autoreset is disabled)"
            )
        obs, reward, terminated, truncated, info = self.batch.step(actions)
        every = np.ones(self.num_envs, bool)
        if mode == AutoresetMode.NEXT_STEP:
            restart = self._ended
            if restart.any():
                obs, reset_info = self.batch.reset(restart)
                reward[restart], terminated[restart], truncated[restart] = 0.0, False, False
                info = _merge(info, reset_info, restart)
            self._ended = terminated | truncated
            return obs, reward, terminated, truncated, masked_info(info, every)
        ended = terminated | truncated
        if mode == AutoresetMode.DISABLED or not ended.any():
            self._ended = ended
            return obs, reward, terminated, truncated, masked_info(info, every)
        final_obs = np.full(self.num_envs, None, object)
        for i in np.flatnonzero(ended):
            final_obs[i] = _rows(obs, i)
        obs, reset_info = self.batch.reset(ended)
        out = masked_info(_merge(info, reset_info, ended), every)
        out.update(final_obs=final_obs, _final_obs=ended, final_info=masked_info(info, ended),
                   _final_info=ended)
        return obs, reward, terminated, truncated, out

    def render(self) -> tuple[np.ndarray, ...] | None:
        if self.render_mode != "rgb_array":
            return None
        return tuple(self.batch.frames())


def _merge(info: dict, reset_info: dict, mask: np.ndarray) -> dict:
    """``reset_info``'s rows where ``mask``, ``info``'s elsewhere."""
    return {k: np.where(_rows_mask(mask, v), reset_info[k], v) for k, v in info.items()}


class CrafterVectorEnv(AsyncVectorEnv):
    """``num_envs`` crafter games in worker processes (``AsyncVectorEnv``), seeded as one run.

    ``context`` is multiprocessing's start method (None: the platform's, fork on Linux). Pass
    "spawn" when this process also runs JAX (a Craftax env): JAX warns that forking its
    threads may deadlock the child. Spawned workers need the script's ``__main__`` guard.
    """

    def __init__(
        self,
        num_envs: int,
        task: str | None = None,
        size: int | None = 144,
        max_steps: int | None = None,
        render_mode: str | None = None,
        autoreset_mode: AutoresetMode | str = AutoresetMode.NEXT_STEP,
        context: str | None = None,
    ) -> None:
        make = [
            partial(CrafterDojoEnv, "crafter", task, size, False, max_steps, render_mode, i, num_envs)
            for i in range(num_envs)
        ]
        super().__init__(make, context=context, autoreset_mode=AutoresetMode(autoreset_mode))

    def reset_async(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> None:
        seed = _one_seed(seed)
        super().reset_async(seed=None if seed is None else [seed] * self.num_envs, options=options)


def make_vector_env(num_envs: int, game: str = "craftax", **kwargs: Any) -> VectorEnv:
    """``gymnasium.make_vec``'s entry point: the vector env of ``game``."""
    if game == "craftax":
        return CraftaxVectorEnv(num_envs, **kwargs)
    if game == "crafter":
        if kwargs.pop("symbolic", False):
            raise ValueError("the symbolic observation is Craftax-Classic's: use game='craftax'")
        return CrafterVectorEnv(num_envs, **kwargs)
    raise ValueError(f"unknown game {game!r}; expected 'craftax' or 'crafter'")
