"""CrafterDojo for any RL library: both games and every task as registered Gymnasium envs.

``import zoo.gym`` registers, for game ``Craftax`` (Craftax-Classic) and ``Crafter`` (original):

- ``CrafterDojo/Craftax-v0``, ``CrafterDojo/Crafter-v0``: the game, crafter's reward;
- ``CrafterDojo/<Game>-<task>-v0`` for every task of ``zoo eval --task`` (``TASK_NAMES``): the
  task played by the same ``TaskEnv``, reward 1 per sub-task completed in order, terminated on
  success.

``gymnasium.make(id, size=72, symbolic=True, ...)`` takes ``CrafterDojoEnv``'s arguments;
``gymnasium.make_vec(id, num_envs=n)`` gives the native vector env (``zoo.gym.vector``). The
foundation models are wrappers in ``zoo.gym.wrappers`` (imported on their own: they load
torch). Seeding, end signals and info: ``zoo.gym.batch``; docs/gym.md has the quickstart.
"""

from __future__ import annotations

import gymnasium

from zoo.envs.tasks import TASKS

NAMESPACE = "CrafterDojo"
GAME_NAMES = {"craftax": "Craftax", "crafter": "Crafter"}
TASK_NAMES = tuple(TASKS)


def env_id(game: str, task: str | None = None) -> str:
    """The registered id of ``game`` ("craftax" or "crafter"), playing ``task`` if given."""
    if game not in GAME_NAMES:
        raise ValueError(f"unknown game {game!r}; expected one of {sorted(GAME_NAMES)}")
    middle = f"-{task}" if task is not None else ""
    return f"{NAMESPACE}/{GAME_NAMES[game]}{middle}-v0"


ENV_IDS = tuple(env_id(game, task) for game in GAME_NAMES for task in (None, *TASK_NAMES))


def _register() -> None:
    for game in GAME_NAMES:
        for task in (None, *TASK_NAMES):
            if env_id(game, task) not in gymnasium.registry:
                gymnasium.register(
                    env_id(game, task),
                    entry_point="zoo.gym.env:CrafterDojoEnv",
                    vector_entry_point="zoo.gym.vector:make_vector_env",
                    kwargs={"game": game, "task": task},
                )


_register()

__all__ = ["ENV_IDS", "GAME_NAMES", "NAMESPACE", "TASK_NAMES", "env_id"]
