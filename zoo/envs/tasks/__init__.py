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

from zoo.envs.tasks.env import TaskEnv, make_task_env
from zoo.envs.tasks.events import achievement_events
from zoo.envs.tasks.progress import TaskProgress
from zoo.envs.tasks.specs import (
    LONG_HORIZON_TASKS,
    SINGLE_STEP_TASKS,
    TASKS,
    SubTask,
    TaskSpec,
    get_task,
)

__all__ = [
    "LONG_HORIZON_TASKS",
    "SINGLE_STEP_TASKS",
    "TASKS",
    "SubTask",
    "TaskEnv",
    "TaskProgress",
    "TaskSpec",
    "achievement_events",
    "get_task",
    "make_task_env",
]
