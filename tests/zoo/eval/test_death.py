"""Episode-end causes: each rule on a constructed final step, and the report's shares."""

from __future__ import annotations

import numpy as np
import pytest

from zoo.envs.constants import Block
from zoo.envs.schema import empty_state
from zoo.eval.death import DEATH_CAUSES, death_cause, death_shares

PLAYER = (30, 30)


def states(health_after: int = 0):
    """(before, after) of one env: player at PLAYER on grass, vitals full, no creatures."""
    pair = []
    for health in (2, health_after):
        s = empty_state(1)
        s["map"][0] = Block.GRASS
        s["player_pos"][0] = PLAYER
        s["player_vitals"][0] = [health, 9, 9, 9]
        pair.append(s)
    return pair


def put(s, kind: str, pos: tuple[int, int]) -> None:
    s[f"{kind}_pos"][0, 0] = pos
    s[f"{kind}_status"][0, 0] = (1, 3, 0)


def test_alive_at_the_step_limit_is_survived():
    before, after = states(health_after=5)
    put(after, "zombies", (30, 31))  # a zombie next to a living player kills nobody
    assert death_cause(before, after, 0) == "survived"


def test_lava_under_the_player_even_with_health_left():
    before, after = states(health_after=9)
    after["map"][0, PLAYER[0], PLAYER[1]] = Block.LAVA
    assert death_cause(before, after, 0) == "lava"


@pytest.mark.parametrize("kind, cause", [("zombies", "zombie"), ("arrows", "arrow")])
def test_creature_next_to_the_player_is_blamed(kind, cause):
    before, after = states()
    put(before, kind, (31, 31))  # diagonal counts: the creature may have moved off
    assert death_cause(before, after, 0) == cause
    before, after = states()
    put(before, kind, (30, 32))  # two tiles away: a near miss, and no need at 0 either
    assert death_cause(before, after, 0) == "other"


def test_dead_creature_slot_is_ignored():
    before, after = states()
    put(before, "zombies", (30, 31))
    before["zombies_status"][0, 0, 0] = 0  # mask off: an empty padded slot
    assert death_cause(before, after, 0) == "other"


def test_a_need_at_zero_without_creatures():
    before, after = states()
    before["player_vitals"][0] = [1, 9, 0, 9]  # thirst
    assert death_cause(before, after, 0) == "needs"
    put(before, "zombies", (29, 30))
    assert death_cause(before, after, 0) == "zombie"  # the hit, not the slow drain


def test_shares_list_every_cause_and_reject_unknown_ones():
    shares = death_shares(["zombie", "zombie", "lava", "survived"])
    assert list(shares) == list(DEATH_CAUSES)
    assert shares["zombie"] == 50.0 and shares["lava"] == 25.0 and shares["arrow"] == 0.0
    assert np.isclose(sum(shares.values()), 100.0)
    with pytest.raises(ValueError, match="drowned"):
        death_shares(["drowned"])
