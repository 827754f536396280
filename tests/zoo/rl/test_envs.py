"""What PPO steps: the ordered sparse task reward, resets, and PPO-Steve's caption options."""

from __future__ import annotations

import numpy as np
import torch

from zoo.agents.csteve1_agent import CSteve1Policy
from zoo.envs.base import Step, episode_seed
from zoo.envs.constants import NUM_ACTIONS, Achievement, Block, Item
from zoo.envs.schema import empty_state
from zoo.envs.tasks import TASKS, TaskProgress
from zoo.models.cvpt import CVPTConfig, CVPTModel
from zoo.models.csteve1 import CSteve1Config, CSteve1Model
from zoo.rl.envs import PlannerEnv, TaskVecEnv, Transition


def _t4_states():
    """One env's states: stone (out of order), coal, stone (still out of order: the pickaxe is
    next), wood pickaxe, stone. T4 = coal -> wood pickaxe -> stone."""
    base = empty_state(1)
    base["map"][0] = Block.GRASS
    states = [{k: v.copy() for k, v in base.items()} for _ in range(6)]
    for t, item, count, ach in [
        (1, Item.STONE, 1, Achievement.COLLECT_STONE),
        (2, Item.COAL, 1, Achievement.COLLECT_COAL),
        (3, Item.STONE, 2, None),
        (4, Item.WOOD_PICKAXE, 1, Achievement.MAKE_WOOD_PICKAXE),
        (5, Item.STONE, 3, None),
    ]:
        for s in states[t:]:
            s["inventory"][0, item] = count
            if ach is not None:
                s["achievements"][0, ach] = True
    return states


class ReplayTaskEnv:
    """A task env replaying hand-built states (the contract TaskVecEnv reads: ``reset``,
    ``step``, ``progress`` and ``completed``, as ``zoo.envs.tasks.TaskEnv`` keeps them)."""

    num_envs = 1

    def __init__(self, states):
        self.states, self.t = states, 0
        self.progress = TaskProgress(TASKS["T4"], 1)
        self.completed = np.zeros(1, bool)
        self.reset_seeds: list[int] = []

    def _step(self, done: bool) -> Step:
        frames = np.full((1, 144, 144, 3), self.t, np.uint8)
        return Step(frames, self.states[self.t], np.zeros(1, np.float32), np.array([done]))

    def reset(self, seeds, mask=None) -> Step:
        self.t = 0
        self.reset_seeds.append(int(seeds[0]))
        self.progress.reset(self.states[0])
        return self._step(False)

    def step(self, actions) -> Step:
        self.t += 1
        self.completed = self.progress.update(self.states[self.t])
        return self._step(bool(self.progress.success[0]))


def test_the_task_reward_comes_only_for_sub_tasks_in_order():
    env = ReplayTaskEnv(_t4_states())
    vec = TaskVecEnv(env, seed=7)
    first = vec.reset()
    assert first.first.tolist() == [True] and env.reset_seeds == [episode_seed(7, 0)]
    rewards, dones = [], []
    for _ in range(5):
        t = vec.step(np.zeros(1, np.int64))
        rewards.append(float(t.reward[0]))
        dones.append(bool(t.done[0]))
    # stone before coal: nothing; coal: +1; stone before the pickaxe: nothing; pickaxe: +1;
    # stone: +1 and the task is done
    assert rewards == [0.0, 1.0, 0.0, 1.0, 1.0]
    assert dones == [False, False, False, False, True]
    assert t.first.tolist() == [True]  # reset at once: the next observation starts episode 1
    assert env.reset_seeds == [episode_seed(7, 0), episode_seed(7, 1)]
    (stats,) = t.finished
    assert (stats.success, stats.subtasks_done, stats.length, stats.episode) == (True, 3, 5, 0)
    assert vec.next_episode == 2


class ScriptedTasks:
    """A vectorised task env for PlannerEnv: env 1 ends its episode at its 3rd step."""

    def __init__(self, num_envs: int = 2):
        self.num_envs, self.next_episode = num_envs, 0
        self.actions: list[np.ndarray] = []

    def _transition(self, reward, done) -> Transition:
        frames = np.zeros((self.num_envs, 144, 144, 3), np.uint8)
        n = self.num_envs
        return Transition(frames, reward, done, done.copy(), n, [])

    def reset(self) -> Transition:
        t = self._transition(np.zeros(self.num_envs, np.float32), np.zeros(self.num_envs, bool))
        t.first[:] = True
        return t

    def step(self, actions) -> Transition:
        self.actions.append(np.asarray(actions).copy())
        k = len(self.actions)
        reward = np.ones(self.num_envs, np.float32)  # +1 every step, to see what is summed
        done = np.array([False, k == 3])
        return self._transition(reward, done)


def _steve(goal_dim: int = 8) -> CSteve1Policy:
    torch.manual_seed(0)
    backbone = CVPTModel(CVPTConfig.from_name(
        "tiny", NUM_ACTIONS, d_model=16, d_ff=32, n_heads=2, n_layers=1, impala_channels=(2, 4, 4),
        encoder_hidden=16, memory_len=4, input_downsample=4,
    ))
    return CSteve1Policy(CSteve1Model(backbone, CSteve1Config(goal_dim=goal_dim, lora_rank=0)))


def test_a_planner_action_is_a_caption_whose_goal_steers_c_steve_1_for_an_option():
    steve = _steve()
    goals = torch.randn(5, 8, generator=torch.Generator().manual_seed(1))
    seen = []
    original = steve.model.guided_head

    def spy(hidden, goal, scale):
        seen.append(goal[:, 0].clone())
        return original(hidden, goal, scale)

    steve.model.guided_head = spy
    tasks = ScriptedTasks()
    env = PlannerEnv(tasks, steve, goals, option_steps=4, seed=0)
    assert env.obs_dim == 16 + 5 and env.num_actions == 5
    obs = env.reset().obs
    assert obs.shape == (2, 21) and obs[:, 16:].sum() == 0  # no caption chosen yet
    t = env.step(np.array([3, 1]))
    assert len(tasks.actions) == 4 and t.env_steps == 8  # 4 steps of both envs
    for goal in seen:  # every step of the option follows caption 3 in env 0, 1 in env 1
        torch.testing.assert_close(goal, goals[[3, 1]])
    # env 1's episode ended at step 3: it waits with noop for step 4, its reward stops there
    assert tasks.actions[3][1] == 0
    assert t.reward.tolist() == [4.0, 3.0]
    assert t.done.tolist() == [False, True] and t.first.tolist() == [False, True]
    # the next observation carries the caption each env's planner chose (none after a reset)
    assert t.obs[0, 16 + 3] == 1 and t.obs[0, 16:].sum() == 1 and t.obs[1, 16:].sum() == 0
