"""Task variants of both games: the paper's single-step and long-horizon (T1-T4) suites.

A ``TaskSpec`` says what the agent starts with, whether the world is peaceful, the step limit
and the ordered sub-tasks, each an achievement plus the caption that instructs it. ``TaskEnv``
wraps any ``GameEnv`` (Craftax-Classic's EnvState pytree or crafter's Python objects) and
re-exports the state after each edit, so ``Step.state`` (and the frames) show the edited game.

Starting inventories of the single-step tasks. The paper pre-equips the agent "with the
necessary items" without listing them; the sets here are the least that lets the task be
done by the instruction alone, with no tech-tree step before it:
- ``collect_sapling`` and ``collect_drink`` need nothing (grass and water are everywhere).
- ``make_wood_*``: 3 wood = a table (2 wood in both games as installed) + the tool (1 wood).
  The table is not given because the inventory cannot hold one; placing it is part of the
  crafting skill the captions "craft ..." were learned from.
- ``make_stone_*``: 3 wood, 1 stone and a wood pickaxe. Wood and stone pay for the table and
  the tool; the pickaxe is not consumed but puts the agent where stone tools are made in play
  data (a wood pickaxe always precedes stone), and lets it mine more stone if it spends it.

Sub-task detection. Success needs the sub-tasks to finish in order; each is an *event* seen
between two consecutive states, not a first unlock, because Craftax-Classic's achievements
are booleans (T4's second wood pickaxe, made after the coal, never flips one). An event of
achievement A at step t is: A's flag flipping, or A's repeatable trace (``achievement_events``):
an inventory increment for collect/make, the drink level rising for drink, a sapling spent
for place_plant, one more table/furnace tile for place_table/furnace, and a ripe plant tile
turning back into a young plant (both games reset an eaten plant) for eat_plant. Both games
cap items and vitals at 9 and still count the act, so at the cap the trace is what else it
changed: the mined tile (tree to grass, stone/coal/iron/diamond to path), the materials a tool
cost, the thirst counter restarting for drink. A sapling collected at the cap leaves nothing
(the grass stays grass), nor does a tool made when it and its sibling (pickaxe/sword of the
same materials) are both at the cap.

Sub-task k completes at the first step after sub-task k-1 completed where its event occurs;
events before that (out of order) are ignored, and at most one sub-task completes per step.

T1 (collect sapling, place plant, eat plant) is peaceful as in the paper: after reset and
every step all zombies, skeletons, arrows and cows are removed (both games spawn them each
step; cows and zombies also trample plants in crafter) and food, drink and energy are set to
9, so health never decays. Plants ripen after 300 steps in crafter, 600 in Craftax-Classic,
so T1's 1,000 steps leave 400 (Craftax) for collecting and placing the sapling.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import cache

import numpy as np

from zoo.envs.base import GameEnv, Step
from zoo.envs.constants import ITEM_NAMES, Achievement, Block, Item
from zoo.envs.schema import State

VITAL_MAX = 9
ITEM_MAX = 9  # inventory cap of every item in both games
DRINK = 2  # column of ``player_vitals``
THIRST = 2  # column of ``player_counters``


@dataclass(frozen=True)
class SubTask:
    """One step of a task: the achievement whose event completes it and the caption that asks
    for it (a caption text of zoo/captions/captions.yaml, as instruction-following agents read)."""

    achievement: Achievement
    instruction: str


@dataclass(frozen=True)
class TaskSpec:
    """A task variant of the game.

    Args:
        name: registry key (``zoo eval --task NAME``).
        subtasks: completed in this order for success.
        inventory: items the agent holds after reset (all other items 0).
        peaceful: no mobs and no vitals decay (food, drink, energy kept at 9).
        max_steps: episode step limit.
        description: one line for reports and ``--help``.
    """

    name: str
    subtasks: tuple[SubTask, ...]
    inventory: dict[Item, int] = field(default_factory=dict)
    peaceful: bool = False
    max_steps: int = 1000
    description: str = ""

    def __post_init__(self) -> None:
        if not self.subtasks:
            raise ValueError(f"task {self.name!r} has no sub-tasks")
        if self.max_steps < 1:
            raise ValueError(f"task {self.name!r}: max_steps must be >= 1, got {self.max_steps}")
        bad = {k: v for k, v in self.inventory.items() if not 0 <= v <= ITEM_MAX}
        if bad:
            raise ValueError(f"task {self.name!r}: item counts must lie in [0, 9], got {bad}")

    @property
    def instructions(self) -> tuple[str, ...]:
        return tuple(s.instruction for s in self.subtasks)

    def inventory_vector(self) -> np.ndarray:
        """The starting inventory in schema order (``zoo.envs.Item``)."""
        vec = np.zeros(len(Item), np.int16)
        for item, count in self.inventory.items():
            vec[Item(item)] = count
        return vec


def _sub(achievement: Achievement, instruction: str) -> SubTask:
    return SubTask(achievement, instruction)


SAPLING = _sub(Achievement.COLLECT_SAPLING, "obtain sapling")
DRINK_SUB = _sub(Achievement.COLLECT_DRINK, "obtain drink")
PLANT = _sub(Achievement.PLACE_PLANT, "place plant on grass")
TABLE = _sub(Achievement.PLACE_TABLE, "place table on grass")
EAT_PLANT = _sub(Achievement.EAT_PLANT, "obtain ripe plant")
WOOD_PICKAXE = _sub(Achievement.MAKE_WOOD_PICKAXE, "craft wood pickaxe")
COAL = _sub(Achievement.COLLECT_COAL, "obtain coal")
STONE = _sub(Achievement.COLLECT_STONE, "obtain stone")

SINGLE_STEP_LIMIT = 500  # the paper gives none; ~50x the goal-directed expert's slowest median
_WOOD_TOOL = {Item.WOOD: 3}
_STONE_TOOL = {Item.WOOD: 3, Item.STONE: 1, Item.WOOD_PICKAXE: 1}

def _single_step(
    name: str, sub: SubTask, inventory: dict[Item, int], description: str
) -> TaskSpec:
    return TaskSpec(name, (sub,), inventory, max_steps=SINGLE_STEP_LIMIT, description=description)


TASKS: dict[str, TaskSpec] = {
    t.name: t
    for t in (
        _single_step("collect_sapling", SAPLING, {}, "collect a sapling"),
        _single_step("collect_drink", DRINK_SUB, {}, "drink water"),
        _single_step("make_wood_pickaxe", WOOD_PICKAXE, _WOOD_TOOL, "craft a wood pickaxe"),
        _single_step(
            "make_wood_sword", _sub(Achievement.MAKE_WOOD_SWORD, "craft wood sword"), _WOOD_TOOL,
            "craft a wood sword",
        ),
        _single_step(
            "make_stone_pickaxe", _sub(Achievement.MAKE_STONE_PICKAXE, "craft stone pickaxe"),
            _STONE_TOOL, "craft a stone pickaxe",
        ),
        _single_step(
            "make_stone_sword", _sub(Achievement.MAKE_STONE_SWORD, "craft stone sword"),
            _STONE_TOOL, "craft a stone sword",
        ),
        TaskSpec(
            "T1", (SAPLING, PLANT, EAT_PLANT), peaceful=True,
            description="collect sapling, place plant, eat the ripe plant (no mobs, no decay)",
        ),
        TaskSpec("T2", (PLANT, TABLE), description="place plant, then place table"),
        TaskSpec("T3", (WOOD_PICKAXE, SAPLING), description="make wood pickaxe, then sapling"),
        TaskSpec(
            "T4", (COAL, WOOD_PICKAXE, STONE),
            description="collect coal, then make a wood pickaxe, then collect stone",
        ),
    )
}
SINGLE_STEP_TASKS = tuple(n for n, t in TASKS.items() if len(t.subtasks) == 1)
LONG_HORIZON_TASKS = ("T1", "T2", "T3", "T4")


def get_task(name: str) -> TaskSpec:
    try:
        return TASKS[name]
    except KeyError:
        raise ValueError(f"unknown task {name!r}; expected one of {sorted(TASKS)}") from None


# --- events ---------------------------------------------------------------------------------
_ITEM_EVENTS = {
    Achievement.COLLECT_WOOD: Item.WOOD,
    Achievement.COLLECT_STONE: Item.STONE,
    Achievement.COLLECT_COAL: Item.COAL,
    Achievement.COLLECT_IRON: Item.IRON,
    Achievement.COLLECT_DIAMOND: Item.DIAMOND,
    Achievement.COLLECT_SAPLING: Item.SAPLING,
    Achievement.MAKE_WOOD_PICKAXE: Item.WOOD_PICKAXE,
    Achievement.MAKE_STONE_PICKAXE: Item.STONE_PICKAXE,
    Achievement.MAKE_IRON_PICKAXE: Item.IRON_PICKAXE,
    Achievement.MAKE_WOOD_SWORD: Item.WOOD_SWORD,
    Achievement.MAKE_STONE_SWORD: Item.STONE_SWORD,
    Achievement.MAKE_IRON_SWORD: Item.IRON_SWORD,
}
_BLOCK_EVENTS = {Achievement.PLACE_TABLE: Block.TABLE, Achievement.PLACE_FURNACE: Block.FURNACE}
# What collecting leaves on the tile in both games as installed: the trace at the item cap.
_MINED = {
    Achievement.COLLECT_WOOD: (Block.TREE, Block.GRASS),
    Achievement.COLLECT_STONE: (Block.STONE, Block.PATH),
    Achievement.COLLECT_COAL: (Block.COAL, Block.PATH),
    Achievement.COLLECT_IRON: (Block.IRON, Block.PATH),
    Achievement.COLLECT_DIAMOND: (Block.DIAMOND, Block.PATH),
}
# Tool pairs and the materials making either spends (item -> amounts allowed): the trace of a
# tool made at the cap. Iron tools cost stone in Craftax-Classic only.
_RECIPES: tuple[tuple[tuple[Item, Item], dict[Item, tuple[int, ...]]], ...] = (
    (
        (Item.WOOD_PICKAXE, Item.WOOD_SWORD),
        {Item.WOOD: (1,), Item.STONE: (0,), Item.COAL: (0,), Item.IRON: (0,)},
    ),
    (
        (Item.STONE_PICKAXE, Item.STONE_SWORD),
        {Item.WOOD: (1,), Item.STONE: (1,), Item.COAL: (0,), Item.IRON: (0,)},
    ),
    (
        (Item.IRON_PICKAXE, Item.IRON_SWORD),
        {Item.WOOD: (1,), Item.STONE: (0, 1), Item.COAL: (1,), Item.IRON: (1,)},
    ),
)
_MADE = {item: ach for ach, item in _ITEM_EVENTS.items()}


def achievement_events(prev: State, cur: State) -> np.ndarray:
    """(N, 22) bool: which achievements happened between two consecutive batched states.

    A flag flip always counts; the achievements in the module docstring also count when they
    happen again, at the item cap too. Others (eat cow, defeat mobs, place stone, wake up)
    count on the flip only.
    """
    events = cur["achievements"].astype(bool) & ~prev["achievements"].astype(bool)
    before, after = prev["inventory"].astype(np.int32), cur["inventory"].astype(np.int32)
    inv_up = after > before
    for ach, item in _ITEM_EVENTS.items():
        events[:, ach] |= inv_up[:, item]
    for ach, (block, left) in _MINED.items():
        events[:, ach] |= ((prev["map"] == block) & (cur["map"] == left)).any(axis=(1, 2))
    spent = before - after
    for pair, costs in _RECIPES:
        paid = np.all([np.isin(spent[:, item], amounts) for item, amounts in costs.items()], 0)
        made_at_cap = paid & ~inv_up[:, list(pair)].any(axis=1)
        for tool, sibling in (pair, pair[::-1]):
            only_tool_full = (before[:, tool] >= ITEM_MAX) & (before[:, sibling] < ITEM_MAX)
            events[:, _MADE[tool]] |= made_at_cap & only_tool_full
    thirst, was = cur["player_counters"][:, THIRST], prev["player_counters"][:, THIRST]
    events[:, Achievement.COLLECT_DRINK] |= (
        cur["player_vitals"][:, DRINK].astype(np.int32) > prev["player_vitals"][:, DRINK]
    ) | ((thirst > 0) & (thirst < was))  # drinking restarts it at 0 (+1 this step)
    events[:, Achievement.PLACE_PLANT] |= after[:, Item.SAPLING] < before[:, Item.SAPLING]
    for ach, block in _BLOCK_EVENTS.items():
        tiles_before, tiles_after = ((s["map"] == block).sum(axis=(1, 2)) for s in (prev, cur))
        events[:, ach] |= tiles_after > tiles_before
    eaten = (prev["map"] == Block.RIPE_PLANT) & (cur["map"] == Block.PLANT)
    events[:, Achievement.EAT_PLANT] |= eaten.any(axis=(1, 2))
    return events


class TaskProgress:
    """Ordered sub-task completion of N envs playing one task, fed one state per step.

    ``done_at[i, k]`` is the step (1-based, steps since reset) at which env i completed
    sub-task k, -1 if not yet; ``next[i]`` is the index of its current sub-task.
    """

    def __init__(self, task: TaskSpec, num_envs: int) -> None:
        self.task = task
        self.num_envs = num_envs
        self.done_at = np.full((num_envs, len(task.subtasks)), -1, np.int64)
        self.next = np.zeros(num_envs, np.int64)
        self.steps = np.zeros(num_envs, np.int64)
        self._targets = np.array([int(s.achievement) for s in task.subtasks])
        self._prev: State | None = None

    def reset(self, state: State, mask: np.ndarray | None = None) -> None:
        """Start over in envs where ``mask`` (all if None) from their reset ``state``."""
        mask = np.ones(self.num_envs, bool) if mask is None else np.asarray(mask, bool)
        self.done_at[mask] = -1
        self.next[mask] = 0
        self.steps[mask] = 0
        if self._prev is None:
            self._prev = {k: v.copy() for k, v in state.items()}
        else:
            for k, v in state.items():
                self._prev[k][mask] = v[mask]

    def update(self, state: State) -> np.ndarray:
        """Read the state after one step of every env; returns (N,) bool: sub-task completed."""
        if self._prev is None:
            raise RuntimeError("TaskProgress.update called before reset")
        self.steps += 1
        events = achievement_events(self._prev, state)
        completed = np.zeros(self.num_envs, bool)
        active = np.flatnonzero(self.next < len(self._targets))
        hit = events[active, self._targets[self.next[active]]]
        for i in active[hit]:
            self.done_at[i, self.next[i]] = self.steps[i]
            self.next[i] += 1
            completed[i] = True
        self._prev = {k: v.copy() for k, v in state.items()}
        return completed

    @property
    def success(self) -> np.ndarray:
        """(N,) bool: every sub-task done, in order."""
        return self.next >= len(self._targets)

    def current_instructions(self) -> list[str | None]:
        """Each env's current sub-task caption (None once the task is done)."""
        subs = self.task.subtasks
        return [subs[k].instruction if k < len(subs) else None for k in self.next]


# --- the env wrapper ------------------------------------------------------------------------
class TaskEnv:
    """``env`` playing ``task``: the starting inventory after each reset, and (peaceful
    tasks) no mobs and full vitals after every step. Same interface as ``GameEnv``.

    ``progress`` tracks each env's ordered sub-tasks; with ``end_on_success`` an env reports
    ``done`` on the step its last sub-task completes (the episode has nothing left to score).
    ``seeds[i]`` is the seed env i was last reset with, so results can be matched to slots.
    ``completed[i]`` says whether env i's last step completed its current sub-task (the
    sparse, ordered task reward of the RL agents).
    The step limit is the wrapped env's own; ``make_task_env`` builds one with the task's.
    """

    def __init__(self, env: GameEnv, task: TaskSpec, end_on_success: bool = True) -> None:
        if env.name == "craftax":
            self._editor: _Editor = _CraftaxEditor(env, task)
        elif env.name == "crafter":
            self._editor = _CrafterEditor(env, task)
        else:
            raise ValueError(f"no task support for env {env.name!r}; expected craftax or crafter")
        self.env, self.task = env, task
        self.num_envs, self.name = env.num_envs, env.name
        self.end_on_success = end_on_success
        self.progress = TaskProgress(task, env.num_envs)
        self.seeds = np.zeros(env.num_envs, np.int64)
        self.completed = np.zeros(env.num_envs, bool)
        self._last: Step | None = None

    @property
    def raw_state(self):
        return getattr(self.env, "raw_state", None)

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> Step:
        mask = np.ones(self.num_envs, bool) if mask is None else np.asarray(mask, bool)
        step = _writable(self.env.reset(seeds, mask))
        if self._last is None:  # the env may hold other edits: export what its games hold
            self._editor.edit(step, ~mask, inventory=False)
        else:  # rows not reset keep what this wrapper last showed
            for k, v in step.state.items():
                v[~mask] = self._last.state[k][~mask]
            if step.frames is not None and self._last.frames is not None:
                step.frames[~mask] = self._last.frames[~mask]
        self._editor.edit(step, mask, inventory=True)
        self.seeds[mask] = np.asarray(seeds)[mask]
        self.progress.reset(step.state, mask)
        self._last = step
        return step

    def step(self, actions: np.ndarray) -> Step:
        step = _writable(self.env.step(actions))
        if self.task.peaceful:
            self._editor.edit(step, np.ones(self.num_envs, bool), inventory=False)
        self.completed = self.progress.update(step.state)
        if self.end_on_success:
            step.done = step.done | self.progress.success
        self._last = step
        return step


def _writable(step: Step) -> Step:
    """Own copies of the arrays (Craftax hands back read-only views of device buffers)."""
    step.state = {k: np.array(v) for k, v in step.state.items()}
    step.frames = None if step.frames is None else np.array(step.frames)
    return step


def make_task_env(
    task: TaskSpec | str,
    env_name: str,
    num_envs: int = 1,
    pixels: bool = True,
    max_steps: int | None = None,
) -> TaskEnv:
    """``num_envs`` envs of game ``env_name`` playing ``task`` (step limit: the task's)."""
    from zoo.envs import make_env

    task = get_task(task) if isinstance(task, str) else task
    env = make_env(env_name, num_envs, pixels=pixels, max_steps=max_steps or task.max_steps)
    return TaskEnv(env, task)


class _Editor:
    def edit(self, step: Step, mask: np.ndarray, inventory: bool) -> None:
        """Apply the task to envs where ``mask`` and rewrite their rows of ``step`` in place."""
        raise NotImplementedError


class _CrafterEditor(_Editor):
    """Edits crafter's objects: the player's inventory dict and the world's mob objects."""

    def __init__(self, env, task: TaskSpec) -> None:
        from zoo.envs.crafter_env import _material_lookup

        self.env, self.task = env, task
        self.lookup = _material_lookup(env.raw_state[0]._world._mat_names)
        self.inventory = dict(zip(ITEM_NAMES, task.inventory_vector().tolist()))

    def edit(self, step: Step, mask: np.ndarray, inventory: bool) -> None:
        from crafter import objects

        from zoo.envs.crafter_env import export_crafter_state

        mobs = (objects.Zombie, objects.Skeleton, objects.Cow, objects.Arrow)
        for i in np.flatnonzero(mask):
            game = self.env.raw_state[i]
            player = game._player
            if inventory:
                player.inventory.update(self.inventory)
            if self.task.peaceful:
                for obj in [o for o in game._world.objects if isinstance(o, mobs)]:
                    game._world.remove(obj)
                for need in ("food", "drink", "energy"):
                    player.inventory[need] = VITAL_MAX
            export_crafter_state(game, self.lookup, step.state, i)
            if step.frames is not None:
                step.frames[i] = game.render()


@cache
def _craftax_edit_fn(pixels: bool):
    """The jitted batched edit (+ render and export). What to edit is all arguments (item
    counts, which envs to pacify), so every task and every TaskEnv shares one program."""
    import jax
    import jax.numpy as jnp

    from zoo.envs.craftax_env import BLOCK_PIXELS, export_state

    render = None
    if pixels:
        from craftax.craftax_classic.renderer import make_craftax_pixel_renderer

        render = make_craftax_pixel_renderer(BLOCK_PIXELS)

    def edit_one(state, set_inventory, make_peace, counts):
        inv = state.inventory
        new_inv = {}
        for k, name in enumerate(ITEM_NAMES):
            old = getattr(inv, name)
            new_inv[name] = jnp.where(set_inventory, counts[k].astype(old.dtype), old)
        changes = {"inventory": inv.replace(**new_inv)}
        for key in ("zombies", "skeletons", "cows", "arrows"):
            mobs = getattr(state, key)
            # Zero health too: a DO recomputes every mob's mask as health > 0.
            changes[key] = mobs.replace(
                mask=mobs.mask & ~make_peace,
                health=jnp.where(make_peace, jnp.zeros_like(mobs.health), mobs.health),
            )
        changes["mob_map"] = state.mob_map & ~make_peace
        for key in ("player_food", "player_drink", "player_energy"):
            old = getattr(state, key)
            changes[key] = jnp.where(make_peace, jnp.asarray(VITAL_MAX, old.dtype), old)
        state = state.replace(**changes)
        frame = None
        if render is not None:
            frame = jnp.clip(jnp.round(render(state)), 0, 255).astype(jnp.uint8)
        return state, frame, export_state(state)

    return jax.jit(jax.vmap(edit_one, in_axes=(0, 0, 0, None)))


class _CraftaxEditor(_Editor):
    """Edits the batched EnvState under one jitted call that also re-renders and re-exports."""

    def __init__(self, env, task: TaskSpec) -> None:
        import jax

        self.env = env
        self._jax = jax
        self._counts = task.inventory_vector().astype(np.int32)
        self._peaceful = task.peaceful
        self._edit = _craftax_edit_fn(env.pixels)

    def edit(self, step: Step, mask: np.ndarray, inventory: bool) -> None:
        mask = np.asarray(mask, bool)
        states, frames, exported = self._edit(
            self.env.raw_state, mask & inventory, mask & self._peaceful, self._counts
        )
        # CraftaxEnv has no setter for its states; the edited pytree replaces them.
        self.env._states = states
        frames, exported = self._jax.device_get((frames, exported))
        for k, v in exported.items():
            step.state[k][mask] = v[mask]
        if step.frames is not None:
            step.frames[mask] = frames[mask]
        step.raw = states
