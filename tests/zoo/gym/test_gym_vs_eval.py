"""The Gymnasium envs against ``zoo eval`` itself: the same seed gives the same episode, and a
task's rewards are exactly the sub-task completions ``zoo eval --task`` reports.

``zoo eval`` plays with a recording agent; its actions are then replayed through the Gymnasium
env reset to the same episode, and frames, rewards, unlocks and ends must agree step by step.
Fast tests touch Craftax-Classic only through programs the session's ``craftax_env`` compiles
(2 envs, pixels, the 10,000-step limit); the single Craftax env and its tasks compile their own
(about a minute on a fresh cache), so those are slow.
"""

from __future__ import annotations

import numpy as np
import pytest

from zoo.agents.base import RandomAgent
from zoo.envs import make_env
from zoo.envs.base import Step
from zoo.envs.tasks import make_task_env
from zoo.eval.rollout import evaluate
from zoo.eval.task_eval import evaluate_task
from zoo.experts.scripted import ScriptedExpert
from zoo.gym.env import CrafterDojoEnv
from zoo.gym.vector import CraftaxVectorEnv

SEED = 7


class Recorder:
    """Wraps an agent and keeps, per episode seed, the frames it saw and the actions it chose."""

    def __init__(self, inner, num_envs: int) -> None:
        self.inner, self.name, self.needs_pixels = inner, inner.name, inner.needs_pixels
        self.slot_seed = np.zeros(num_envs, np.int64)
        self.traces: dict[int, dict[str, list]] = {}

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> None:
        self.inner.reset(seeds, mask)
        for i in range(len(seeds)) if mask is None else np.flatnonzero(mask):
            self.slot_seed[i] = seeds[i]
            self.traces[int(seeds[i])] = {"frames": [], "actions": []}

    def instruct(self, instructions, mask=None) -> None:
        self.inner.instruct(instructions, mask)

    def act(self, step: Step) -> np.ndarray:
        actions = self.inner.act(step)
        for i, seed in enumerate(self.slot_seed):
            trace = self.traces[int(seed)]
            trace["actions"].append(int(actions[i]))
            if step.frames is not None:
                trace["frames"].append(step.frames[i].copy())
        return actions


SLOW_CRAFTAX = pytest.param("craftax", marks=pytest.mark.slow)


@pytest.mark.parametrize("game", ["crafter", SLOW_CRAFTAX])
def test_reset_seed_replays_zoo_eval_episodes(game):
    """``reset(seed=s)`` is episode 0 of ``zoo eval --seed s`` and each ``reset()`` the next,
    frame for frame; ``options={"episode": j}`` jumps to episode j (here played in a 2-env
    batch by zoo eval: the slot it ran in does not matter)."""
    limit, episodes = 12, 3
    agent = Recorder(RandomAgent(2), 2)
    results = evaluate(agent, make_env(game, 2, max_steps=limit), episodes, SEED, progress=False)
    env = CrafterDojoEnv(game, max_steps=limit)
    for result in results:
        trace = agent.traces[result.seed]
        if result.index == 0:
            obs, info = env.reset(seed=SEED)
        elif result.index == 1:
            obs, info = env.reset()
        else:
            obs, info = env.reset(options={"episode": result.index})
        assert info["episode_seed"] == result.seed and info["episode_index"] == result.index
        assert np.array_equal(obs, trace["frames"][0])
        total, unlocked_at = 0.0, np.full(22, -1)
        for t, action in enumerate(trace["actions"][: result.length], 1):
            obs, reward, terminated, truncated, info = env.step(action)
            total += reward
            unlocked_at[(unlocked_at < 0) & info["achievements"]] = t
            if t < result.length:
                assert np.array_equal(obs, trace["frames"][t]), f"episode {result.index} step {t}"
                assert not (terminated or truncated)
        assert terminated or truncated
        assert truncated == (result.death == "survived")
        assert total == pytest.approx(result.episode_return, abs=1e-5)
        assert np.array_equal(unlocked_at, result.unlock_step)


@pytest.mark.parametrize("game", ["crafter", SLOW_CRAFTAX])
def test_task_rewards_are_zoo_eval_subtask_completions(game):
    """T3 played by the goal-directed expert under ``zoo eval --task``: replayed through
    ``CrafterDojo/<Game>-T3-v0``, reward 1 arrives exactly at each sub-task's step, and the
    episode terminates on success."""
    agent = Recorder(ScriptedExpert(2), 2)
    env = make_task_env("T3", game, 2, pixels=False)
    tasks, _ = evaluate_task(agent, env, 3, SEED, follow_subtasks=True, progress=False)
    assert sum(r.success for r in tasks) >= 2, "the expert should solve T3 (else: a broken task)"
    gym_env = CrafterDojoEnv(game, "T3", size=None if game == "craftax" else 72,
                             symbolic=game == "craftax")
    for result in tasks:
        gym_env.reset(seed=SEED, options={"episode": result.index})
        rewarded = []
        for t, action in enumerate(agent.traces[result.seed]["actions"][: result.length], 1):
            _, reward, terminated, truncated, info = gym_env.step(action)
            rewarded += [t] * int(reward)
        done = [s for s in result.subtask_steps if s is not None]
        assert rewarded == done
        assert info["subtasks_done"] == len(done)
        assert terminated or truncated
        assert info["success"] == result.success and (terminated or not result.success)


def test_vector_slots_start_with_zoo_eval_episodes(craftax_env):
    """Slot i of the native Craftax vector env seeded s plays episode i of ``zoo eval --seed s``
    (frames, rewards, end), then autoresets into episode i + n."""
    agent = Recorder(RandomAgent(2), 2)
    results = evaluate(agent, craftax_env, 2, SEED, record_gif_episode=None, progress=False)
    env = CraftaxVectorEnv(2)
    obs, info = env.reset(seed=SEED)
    assert info["episode_index"].tolist() == [0, 1]
    traces = [agent.traces[r.seed] for r in results]
    lengths = [r.length for r in results]
    returns, ended_at = np.zeros(2), np.zeros(2, int)
    for t in range(1, max(lengths) + 2):
        actions = [trace["actions"][min(t, length) - 1] for trace, length in zip(traces, lengths)]
        obs, reward, terminated, truncated, info = env.step(np.array(actions))
        for i in range(2):
            if t <= lengths[i]:
                returns[i] += reward[i]
                if t < lengths[i]:
                    assert np.array_equal(obs[i], traces[i]["frames"][t]), (i, t)
                if terminated[i] or truncated[i]:
                    ended_at[i] = t
            elif t == lengths[i] + 1:  # next-step autoreset: the slot's next episode begins
                assert info["episode_index"][i] == i + 2 and reward[i] == 0
    assert ended_at.tolist() == lengths
    assert returns == pytest.approx([r.episode_return for r in results], abs=1e-5)
