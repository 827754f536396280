"""The game layer: one action/achievement convention over Craftax-Classic and crafter."""

from zoo.envs.base import GameEnv, Step
from zoo.envs.constants import (
    ACHIEVEMENT_NAMES,
    ACTION_NAMES,
    NUM_ACHIEVEMENTS,
    NUM_ACTIONS,
    Achievement,
    Action,
    Block,
    Item,
    Mob,
)
from zoo.envs.schema import STATE_FIELDS, State

ENV_NAMES = ("craftax", "crafter")


def make_env(name: str, num_envs: int = 1, pixels: bool = True, max_steps: int = 10_000) -> GameEnv:
    """Build ``num_envs`` envs of the named game ("craftax" or "crafter")."""
    if name == "craftax":
        from zoo.envs.craftax_env import CraftaxEnv

        return CraftaxEnv(num_envs, pixels=pixels, max_steps=max_steps)
    if name == "crafter":
        from zoo.envs.crafter_env import CrafterEnv

        return CrafterEnv(num_envs, pixels=pixels, max_steps=max_steps)
    raise ValueError(f"unknown env {name!r}; expected one of {ENV_NAMES}")


__all__ = [
    "ACHIEVEMENT_NAMES", "ACTION_NAMES", "ENV_NAMES", "NUM_ACHIEVEMENTS", "NUM_ACTIONS",
    "STATE_FIELDS", "Achievement", "Action", "Block", "GameEnv", "Item", "Mob", "State", "Step",
    "make_env",
]
