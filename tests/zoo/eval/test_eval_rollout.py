"""evaluate(): the same episodes whatever the batch size, nothing read after an episode ends."""

from __future__ import annotations

import numpy as np
import pytest

from zoo.agents import RandomAgent
from zoo.envs import ACHIEVEMENT_NAMES, Step, make_env
from zoo.envs.schema import empty_state
from zoo.eval.death import DEATH_CAUSES
from zoo.eval.rollout import FrameSampler, episode_seed, evaluate

WOOD = ACHIEVEMENT_NAMES.index("collect_wood")


def fake_length(seed: int) -> int:
    return 3 + seed % 7


class CountingGame:
    """Stand-in GameEnv with known answers: an episode of seed s lasts ``fake_length(s)`` steps,
    pays action/10 per step and unlocks collect_wood at step 2. Frames hold the step count.
    Like Craftax, a finished env keeps stepping, and then pays 100 and unlocks everything,
    so reading it after ``done`` would show."""

    name = "counting"

    def __init__(self, num_envs: int) -> None:
        self.num_envs = num_envs
        self.t = np.zeros(num_envs, int)
        self.length = np.zeros(num_envs, int)

    def _observe(self, reward: np.ndarray) -> Step:
        achievements = np.zeros((self.num_envs, 22), bool)
        achievements[:, WOOD] = self.t >= 2
        achievements[self.t > self.length] = True
        count = np.minimum(self.t, 255).astype(np.uint8)[:, None, None, None]
        frames = np.broadcast_to(count, (self.num_envs, 144, 144, 3)).copy()
        state = empty_state(self.num_envs)  # the full schema: evaluate reads vitals at the end
        state["achievements"] = achievements
        return Step(frames, state, reward.astype(np.float32), self.t >= self.length)

    def reset(self, seeds: np.ndarray, mask: np.ndarray | None = None) -> Step:
        mask = np.ones(self.num_envs, bool) if mask is None else mask
        self.t[mask] = 0
        self.length[mask] = [fake_length(int(s)) for s in seeds[mask]]
        return self._observe(np.zeros(self.num_envs))

    def step(self, actions: np.ndarray) -> Step:
        self.t += 1
        return self._observe(np.where(self.t > self.length, 100.0, actions / 10))


def summary(results):
    return [
        (r.index, r.seed, r.length, round(r.episode_return, 6), r.unlocked.tolist(),
         r.unlock_step.tolist(), r.death)
        for r in results
    ]


def test_results_match_hand_computed_episodes():
    finished = []
    results = evaluate(
        RandomAgent(3), CountingGame(3), 7, seed=5, on_episode=finished.append, progress=False
    )
    assert [r.index for r in results] == list(range(7))
    assert sorted(r.index for r in finished) == list(range(7))
    for r in results:
        assert r.seed == episode_seed(5, r.index)
        assert r.length == fake_length(r.seed)
        agent = RandomAgent(1)
        agent.reset(np.array([r.seed]))
        actions = [int(agent.act(None)[0]) for _ in range(r.length)]
        assert r.episode_return == pytest.approx(sum(actions) / 10, abs=1e-5)
        assert r.unlocked.tolist() == [i == WOOD for i in range(22)]
        assert r.unlock_step[WOOD] == 2 and (np.delete(r.unlock_step, WOOD) == -1).all()


@pytest.mark.parametrize("num_envs", [1, 2, 5, 9])
def test_batch_size_does_not_change_results(num_envs):
    reference = summary(evaluate(RandomAgent(3), CountingGame(3), 7, seed=11, progress=False))
    got = evaluate(RandomAgent(num_envs), CountingGame(num_envs), 7, seed=11, progress=False)
    assert summary(got) == reference


def test_gif_episode_keeps_every_frame_of_a_short_episode():
    results = evaluate(
        RandomAgent(2), CountingGame(2), 4, seed=0, record_gif_episode=2, progress=False
    )
    assert [r.frames is None for r in results] == [True, True, False, True]
    frames = results[2].frames
    assert frames.shape == (results[2].length + 1, 144, 144, 3) and frames.dtype == np.uint8
    assert frames[:, 0, 0, 0].tolist() == list(range(results[2].length + 1))


def test_frame_sampler_is_bounded_and_spans_the_episode():
    sampler = FrameSampler(max_frames=10)
    for t in range(1001):
        sampler.add(t, np.full((2, 2, 3), t % 256, np.uint8))
    frames = sampler.finish(1000, np.full((2, 2, 3), 1000 % 256, np.uint8))
    steps = sampler._steps
    assert len(frames) <= 11 and steps[0] == 0 and steps[-1] == 1000
    assert len(set(np.diff(steps[:-1]))) == 1  # evenly spaced before the final frame


def test_episodes_must_be_positive():
    with pytest.raises(ValueError, match="episodes must be >= 1"):
        evaluate(RandomAgent(1), CountingGame(1), 0, seed=0, progress=False)


def test_crafter_same_episodes_for_any_num_envs():
    def run(num_envs: int, seed: int, episodes: int = 3):
        env = make_env("crafter", num_envs, max_steps=100)
        return evaluate(RandomAgent(num_envs), env, episodes, seed=seed, progress=False)

    one, three = run(1, seed=2), run(3, seed=2)
    assert summary(one) == summary(three)
    for r in one:  # a random player rarely dies in 100 steps; at the limit it survived
        assert r.death in DEATH_CAUSES and (r.death == "survived") == (r.length == 100)
    assert one[0].frames.shape == (one[0].length + 1, 144, 144, 3)
    other = run(1, seed=3, episodes=1)
    assert other[0].seed != one[0].seed


class FirstSlot:
    """One env seen through slot 0 of a two-env batch (to reuse the compiled Craftax fixture)."""

    name = "craftax"
    num_envs = 1

    def __init__(self, env) -> None:
        self.env = env

    @staticmethod
    def _first(step: Step) -> Step:
        state = {k: v[:1] for k, v in step.state.items()}
        return Step(step.frames[:1], state, step.reward[:1], step.done[:1])

    def reset(self, seeds, mask=None):
        mask = np.ones(1, bool) if mask is None else mask
        return self._first(self.env.reset(np.r_[seeds, 0], np.r_[mask, True]))

    def step(self, actions):
        return self._first(self.env.step(np.r_[actions, 0]))


def test_craftax_same_episodes_for_any_num_envs(craftax_env):
    two = evaluate(RandomAgent(2), craftax_env, 3, seed=4, progress=False)
    one = evaluate(RandomAgent(1), FirstSlot(craftax_env), 3, seed=4, progress=False)
    assert summary(one) == summary(two)
    again = evaluate(RandomAgent(2), craftax_env, 3, seed=4, progress=False)
    assert summary(again) == summary(two)
    assert all(r.length > 0 and r.unlocked.dtype == bool for r in two)
