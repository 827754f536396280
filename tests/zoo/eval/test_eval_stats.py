"""stats.jsonl must be crafter's Recorder format, both ways."""

from __future__ import annotations

import json

import numpy as np
import pytest

from zoo.envs import ACHIEVEMENT_NAMES
from zoo.eval.stats import load_stats, write_stats


def _episodes(n=5, seed=0):
    rng = np.random.default_rng(seed)
    unlocks = rng.random((n, 22)) < 0.3
    returns = unlocks.sum(1) + rng.integers(-5, 5, n) * 0.1
    lengths = rng.integers(50, 10_000, n)
    return unlocks, returns, lengths


def test_round_trip(tmp_path):
    unlocks, returns, lengths = _episodes()
    path = write_stats(tmp_path / "stats.jsonl", unlocks, returns, lengths)
    got_unlocks, got_returns, got_lengths = load_stats(path)
    np.testing.assert_array_equal(got_unlocks, unlocks)
    np.testing.assert_allclose(got_returns, returns, atol=1e-9)
    np.testing.assert_array_equal(got_lengths, lengths)
    assert got_unlocks.dtype == bool and got_lengths.dtype == np.int64


def test_keys_and_values_are_crafters(tmp_path):
    unlocks = np.zeros((1, 22), bool)
    unlocks[0, ACHIEVEMENT_NAMES.index("collect_coal")] = True
    write_stats(tmp_path / "stats.jsonl", unlocks, np.array([1.30000001]), np.array([42]))
    record = json.loads((tmp_path / "stats.jsonl").read_text().splitlines()[0])
    assert list(record)[:3] == ["length", "reward", "achievement_collect_coal"]
    assert list(record)[-1] == "achievement_wake_up" and len(record) == 24
    assert record["length"] == 42 and record["reward"] == 1.3
    assert record["achievement_collect_coal"] == 1 and record["achievement_wake_up"] == 0


def test_same_format_as_crafters_recorder(tmp_path):
    import crafter

    env = crafter.Recorder(
        crafter.Env(length=15, seed=3), tmp_path / "crafter", save_stats=True,
        save_video=False, save_episode=False,
    )
    env.reset()
    done = False
    while not done:
        _, _, done, _ = env.step(5)  # "do": collects wood when facing a tree
    theirs = json.loads((tmp_path / "crafter" / "stats.jsonl").read_text())
    write_stats(tmp_path / "ours.jsonl", np.zeros((1, 22), bool), np.zeros(1), np.array([15]))
    ours = json.loads((tmp_path / "ours.jsonl").read_text())
    assert list(ours) == list(theirs)
    unlocks, _, lengths = load_stats(tmp_path / "crafter" / "stats.jsonl")
    assert lengths.tolist() == [15] and unlocks.shape == (1, 22)


def test_counts_above_one_mean_unlocked(tmp_path):
    write_stats(tmp_path / "s.jsonl", np.zeros((1, 22), bool), np.zeros(1), np.ones(1))
    record = json.loads((tmp_path / "s.jsonl").read_text())
    record["achievement_collect_wood"] = 7
    (tmp_path / "s.jsonl").write_text(json.dumps(record) + "\n")
    unlocks, _, _ = load_stats(tmp_path / "s.jsonl")
    assert unlocks[0].sum() == 1 and unlocks[0, ACHIEVEMENT_NAMES.index("collect_wood")]


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda line: line[:-3], "not valid JSON"),
        (lambda line: "[1, 2]", "expected a JSON object"),
        (lambda line: line.replace('"length"', '"len"'), r"missing keys \['length'\]"),
        (
            lambda line: line.replace('"reward": 0.0', '"reward": "x"'),
            "'reward' is 'x', expected a number",
        ),
        (lambda line: line.replace("collect_coal", "mine_gold"), "unknown achievements"),
    ],
)
def test_malformed_line_names_file_and_line(tmp_path, edit, message):
    path = write_stats(tmp_path / "stats.jsonl", np.zeros((3, 22), bool), np.zeros(3), np.ones(3))
    lines = path.read_text().splitlines()
    lines[1] = edit(lines[1])
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(ValueError, match=rf"stats\.jsonl:2: {message}"):
        load_stats(path)


def test_empty_file_is_an_error(tmp_path):
    (tmp_path / "stats.jsonl").write_text("\n")
    with pytest.raises(ValueError, match="no episodes"):
        load_stats(tmp_path / "stats.jsonl")
