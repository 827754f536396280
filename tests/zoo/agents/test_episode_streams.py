"""EpisodeStreams: an episode's draws depend on its seed alone, whatever its env slot."""

import numpy as np

from zoo.agents.base import EpisodeStreams


def test_reset_reseeds_only_masked_envs_and_marks_their_first_step():
    streams = EpisodeStreams(3)
    streams.reset(np.array([10, 11, 12]))
    first_draws = streams.uniforms()
    streams.stepped()
    assert not streams.first.any()

    envs = streams.reset(np.array([0, 7, 0]), np.array([False, True, False]))
    assert envs.tolist() == [1]
    assert streams.first.tolist() == [False, True, False]
    draws = streams.uniforms()
    assert draws[1] == np.random.default_rng(7).random()
    rng10, rng12 = np.random.default_rng(10), np.random.default_rng(12)
    rng10.random(), rng12.random()
    assert draws[0] == rng10.random() and draws[2] == rng12.random()
    assert first_draws[0] == np.random.default_rng(10).random()


def test_uniforms_of_a_subset_advance_only_that_subset():
    streams = EpisodeStreams(2)
    streams.reset(np.array([3, 4]))
    assert streams.uniforms(np.array([1])).tolist() == [np.random.default_rng(4).random()]
    rng4 = np.random.default_rng(4)
    rng4.random()
    assert streams.uniforms().tolist() == [np.random.default_rng(3).random(), rng4.random()]
