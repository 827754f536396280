"""The flags that choose which episodes are played: the game, the seed of its worlds, how many
episodes, how many at once and how long. Every command that plays (``zoo eval``, its tables,
``zoo play``, ``zoo data generate`` and ``dagger``) declares them here, so a flag has one type,
one set of choices and one meaning everywhere; a command says only its defaults."""

from __future__ import annotations

import argparse

from zoo.argtypes import non_negative_int, positive_int
from zoo.envs import ENV_NAMES

REQUIRED = None  # a default of REQUIRED makes the flag required


def add_game_flag(p: argparse.ArgumentParser, default: str | None = REQUIRED,
                  many: bool = False) -> None:
    """``--env``: one game, or with ``many`` one or more (default: both)."""
    if many:
        p.add_argument("--env", nargs="+", choices=ENV_NAMES, default=list(ENV_NAMES),
                       metavar="GAME", help=f"games: {', '.join(ENV_NAMES)} (default: both)")
        return
    p.add_argument("--env", choices=ENV_NAMES, default=default, required=default is REQUIRED,
                   help="game to play in" + _default(default))


def add_seed_flag(p: argparse.ArgumentParser, default: int | None = 0) -> None:
    """``--seed``: episode j is seeded from (seed, j), as in ``zoo eval``, so the same seed
    plays the same worlds in every command."""
    p.add_argument("--seed", type=non_negative_int, default=default,
                   required=default is REQUIRED,
                   help="episode j is seeded from (seed, j)" + _default(default))


def add_episodes_flag(p: argparse.ArgumentParser, default: int | None = 100,
                      what: str = "episodes") -> None:
    p.add_argument("--episodes", type=positive_int, default=default,
                   required=default is REQUIRED, help=what + _default(default))


def add_num_envs_flag(p: argparse.ArgumentParser, default: int) -> None:
    p.add_argument("--num-envs", type=positive_int, default=default,
                   help=f"episodes played at once (default {default})")


def add_max_steps_flag(p: argparse.ArgumentParser, default: int | None,
                       what: str = "episode step limit") -> None:
    """``--max-steps``; ``what`` says what the limit is (and a None default's meaning)."""
    p.add_argument("--max-steps", type=positive_int, default=default,
                   help=what + ("" if default is None else f" (default {default})"))


def _default(default: object) -> str:
    return "" if default is REQUIRED else f" (default {default})"


__all__ = ["REQUIRED", "add_episodes_flag", "add_game_flag", "add_max_steps_flag",
           "add_num_envs_flag", "add_seed_flag"]
