"""The scripted expert's tunables, in one typed place (``ScriptedExpert(n, **overrides)``)."""

from __future__ import annotations

from dataclasses import dataclass

from zoo.experts.scripted.navigation import MAX_COST


@dataclass(frozen=True)
class ExpertConfig:
    """Thresholds and distances (path costs: 1 per step, more to mine or bridge) of the goals."""

    drink_low: int = 4
    """Go to water when drink is at or below this."""
    food_low: int = 4
    """Hunt a cow (or eat a ripe plant) when food is at or below this."""
    energy_low: int = 3
    """Seal a pocket and sleep when energy is at or below this."""
    food_full: int = 8
    """A food refill (cows, ripe plants) goes on until food reaches this."""
    dusk_light: float = 0.7
    """Below this light (dusk and dawn) drink and food are topped up first."""
    dusk_drink: int = 7
    dusk_food: int = 6
    critical: int = 1
    """Drink/food at or below which the player leaves shelter for water or a cow."""
    night_light: float = 0.45
    """Light level below which it counts as night: zombies swarm, so shelter in a pocket."""
    dawn_light: float = 0.8
    """Night lasts until the light is back above this."""
    rest_until_day: bool = True
    """Stay in a sealed pocket after waking while it is still night."""
    early_stone: int = 3
    """Stones to fetch right after the wood pickaxe (material for the first pocket)."""
    rest_health: int = 4
    """At or below this health, hide in a pocket (sleeping if possible) to heal..."""
    rested_health: int = 8
    """...until health is back to this."""
    fight_health: int = 5
    """Seek out zombies/skeletons only with at least this much health."""
    flee_dist: int = 4
    """Without a sword, walk away from zombies this close (Manhattan)."""
    zombie_engage: int = 3
    """Turn to fight a zombie this close (Manhattan) instead of walking on."""
    skeleton_health: int = 7
    """Chase skeletons (and walk into their tunnels) only with at least this much health."""
    near: int = 10
    """Path cost within which cheap side goals (cow, water, sapling) are taken on the way."""
    hunt_dist: int = 16
    """Path cost within which a zombie or skeleton is chased for its achievement."""
    station_dist: int = 24
    """Walk back to a table/furnace within this cost; farther away, build new ones."""
    shelter_dist: int = 40
    """Largest path cost to a pocket worth walking to for sleep."""
    table_wood: int = 2
    """Wood a table takes (both games as installed)."""
    furnace_stone: int = 4
    """Stone to hold before placing a furnace (crafter takes 4, Craftax-Classic fewer)."""
    wood_target: int = 9
    """Wood to hold before leaving the trees (tools and spare tables need it)."""
    stone_target: int = 9
    """Stone to hold once the wood pickaxe exists (tools, furnace, pockets, bridges)."""
    coal_target: int = 2
    iron_target: int = 2
    plants_wanted: int = 2
    """Saplings to plant early (crafter's mobs trample some)."""
    plants_first: bool = False
    """Collect a sapling and plant it before the first tools (normally a side goal after the
    stone tools). For imitation data: a learner that dies in its first night still sees it."""
    tunnel_density: int = 20
    """Path tiles in the 9x9 box that make a cell count as tunnels (where skeletons spawn)."""
    tunnel_bias: float = 0.7
    """Share of steps spent walking to the tunnels while a skeleton is still wanted."""
    late_wood: int = 5
    """Once the tree is done, keep this much wood (spare tables) when trees are near."""
    drink_in_view: bool = False
    """Told "obtain drink", head for water only once it is in the player's 7 x 9 view, and
    explore until then. A pixel learner cannot imitate a beeline to water it cannot see; the
    default keeps the privileged beeline."""
    explore_dist: int = 12
    """Minimum path cost of a random exploration target."""
    explore_steps: int = 40
    """Steps before an exploration target is replaced."""
    mine_cost: int = 3
    """Path cost of tunnelling through a minable tile (mine + step, plus a small detour bias)."""
    bridge_cost: int = 6
    """Path cost of bridging water (place stone, mine it, step)."""
    near_zombie_cost: int = 4
    """Extra path cost of cells next to a zombie (walking up to one gives it the first hit)."""

    def __post_init__(self) -> None:
        # checked here, not in the first planner step deep inside a generation job
        if min(self.mine_cost, self.bridge_cost) < 1 or self.near_zombie_cost < 0:
            raise ValueError(
                f"mine_cost and bridge_cost must be >= 1 and near_zombie_cost >= 0, got "
                f"{self.mine_cost}, {self.bridge_cost} and {self.near_zombie_cost}"
            )
        worst = max(self.mine_cost, self.bridge_cost) + self.near_zombie_cost
        if worst > MAX_COST:
            raise ValueError(
                f"max(mine_cost, bridge_cost) + near_zombie_cost is {worst}: the planner's step "
                f"costs must stay <= {MAX_COST}"
            )
