"""write_report: files a user opens, and numbers that agree with crafter's own analysis."""

from __future__ import annotations

import json

import imageio.v3 as iio
import numpy as np
import pytest

from zoo.envs import ACHIEVEMENT_NAMES
from zoo.eval.report import format_table, write_report
from zoo.eval.rollout import EpisodeResult

META = {"env": "crafter", "agent": "random", "seed": 3}


def make_results(n=10, frames=True):
    rng = np.random.default_rng(0)
    results = []
    for j in range(n):
        unlocked = rng.random(22) < 0.1 * (j % 4)
        unlock_step = np.where(unlocked, rng.integers(1, 100, 22), -1)
        results.append(EpisodeResult(
            index=j, seed=100 + j, length=100 + 7 * j,
            episode_return=float(unlocked.sum()) - 0.1 * (j % 3),
            unlocked=unlocked, unlock_step=unlock_step, death=("zombie", "needs")[j % 2],
            frames=(
                rng.integers(0, 255, (5, 144, 144, 3), dtype=np.uint8)
                if frames and j == 0 else None
            ),
        ))
    return results[::-1]  # finish order: write_report sorts by index


def crafters_own_score(stats_path):
    """crafter's analysis code: success = count >= 1, then exp(nanmean(log(1 + percents))) - 1."""
    runs = [json.loads(line) for line in stats_path.read_text().splitlines()]
    tasks = sorted(key for key in runs[0] if key.startswith("achievement_"))
    percents = np.array([100 * (np.array([r[t] for r in runs]) >= 1).mean() for t in tasks])
    return np.exp(np.nanmean(np.log(1 + percents))) - 1, dict(zip(tasks, percents)), runs


def test_report_files_and_keys(tmp_path):
    report = write_report(make_results(), tmp_path / "out", META)
    out = tmp_path / "out"
    for name in ("report.json", "stats.jsonl", "achievements.png", "episode.gif"):
        assert (out / name).is_file(), name
    saved = json.loads((out / "report.json").read_text())
    assert saved == report
    for key in ("crafter_score", "normalized_return", "return", "episode_length", "success_rates",
                "median_unlock_step", "episodes", "chunks", "zoo_version", "written_at", "files"):
        assert key in saved, key
    assert {k: saved[k] for k in META} == META
    assert saved["episodes"] == 10 and saved["chunks"] == 5
    assert saved["crafter_score"]["chunk_sizes"] == [2] * 5
    assert list(saved["success_rates"]) == list(ACHIEVEMENT_NAMES)
    assert saved["episode_length"]["min"] == 100 and saved["episode_length"]["max"] == 163
    assert saved["episode_end_percent"]["zombie"] == 50.0 and saved["episode_end_percent"]["needs"] == 50.0
    assert "zombie 50%, needs 50%" in format_table(saved)


def test_report_agrees_with_crafters_analysis_of_stats_jsonl(tmp_path):
    report = write_report(make_results(), tmp_path, META)
    score, percents, runs = crafters_own_score(tmp_path / "stats.jsonl")
    assert report["crafter_score"]["pooled"] == pytest.approx(score)
    for name, rate in report["success_rates"].items():
        assert rate == pytest.approx(percents[f"achievement_{name}"])
    chunk_scores = []
    for c in range(5):
        chunk = tmp_path / f"chunk{c}.jsonl"
        chunk.write_text("".join(json.dumps(r) + "\n" for r in runs[2 * c: 2 * c + 2]))
        chunk_scores.append(crafters_own_score(chunk)[0])
    assert report["crafter_score"]["per_chunk"] == pytest.approx(chunk_scores)
    assert report["crafter_score"]["mean"] == pytest.approx(np.mean(chunk_scores))
    assert report["crafter_score"]["std"] == pytest.approx(np.std(chunk_scores))
    rewards = np.array([r["reward"] for r in runs])
    assert report["normalized_return"]["pooled"] == pytest.approx(rewards.mean() / 22 * 100)


def test_gif_and_plot_are_readable(tmp_path):
    results = make_results()
    write_report(results, tmp_path, META)
    gif = iio.imread(tmp_path / "episode.gif", index=None)
    assert gif.shape[:3] == (5, 288, 288)
    png = iio.imread(tmp_path / "achievements.png")
    assert png.ndim == 3 and png.shape[0] > 300


def test_no_frames_no_gif(tmp_path):
    report = write_report(make_results(frames=False), tmp_path, META)
    assert not (tmp_path / "episode.gif").exists() and "episode.gif" not in report["files"]


def test_few_episodes_use_one_chunk_each(tmp_path):
    report = write_report(make_results(n=3), tmp_path, META)
    assert report["chunks"] == 3 and report["crafter_score"]["chunk_sizes"] == [1, 1, 1]


def test_meta_may_not_overwrite_metrics(tmp_path):
    with pytest.raises(ValueError, match=r"\['crafter_score'\] clash"):
        write_report(make_results(), tmp_path, {"crafter_score": 99})


def test_table_lists_scores_and_every_achievement(tmp_path):
    report = write_report(make_results(), tmp_path, META)
    table = format_table(report)
    first = table.splitlines()[0].split()
    assert first[:2] == ["Crafter", "Score"]
    assert float(first[2]) == pytest.approx(report["crafter_score"]["mean"], abs=0.005)
    assert float(first[4]) == pytest.approx(report["crafter_score"]["std"], abs=0.005)
    assert all(name in table for name in ACHIEVEMENT_NAMES)


def test_every_report_key_is_documented(tmp_path):
    """docs/report_json.md is the schema scripts rely on: a key the code writes must be in it."""
    import re
    from pathlib import Path

    doc = (Path(__file__).resolve().parents[3] / "docs" / "report_json.md").read_text()
    documented = set(re.findall(r"^\| `([a-z_]+)`(?:, `([a-z_]+)`)?", doc, re.M))
    documented = {key for pair in documented for key in pair if key}
    meta = {
        "env": "crafter", "agent": "random", "checkpoint": None, "temperature": 1.0, "seed": 0,
        "num_envs": 2, "max_steps": 100, "started_at": "t", "finished_at": "t",
        "wall_seconds": 1.0,
    }
    report = write_report(make_results(), tmp_path, meta)
    assert set(report) - documented == set()


def test_side_by_side_holds_the_shorter_episodes_last_frame() -> None:
    import numpy as np

    from zoo.eval.play import side_by_side

    a = np.zeros((3, 2, 2, 3), np.uint8)
    b = np.stack([np.full((2, 2, 3), v, np.uint8) for v in (10, 20)])
    movie = side_by_side([a, b], gap=1)
    assert movie.shape == (3, 2, 5, 3)
    assert (movie[:, :, 2] == 255).all()  # the gap
    assert (movie[2, :, 3:] == 20).all() and (movie[0, :, 3:] == 10).all()
