"""CrafterPlay -> CrafterCaption round trip on a tiny random-agent set (3 crafter episodes)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import webdataset as wds

from zoo.captions.dataset import (
    caption_dataset,
    decode_caption_sample,
    heldout_count,
    list_caption_shards,
    write_caption_dataset,
)
from zoo.captions.vocabulary import load_vocabulary
from zoo.cli import main
from zoo.data.reader import iter_episodes, list_shards


@pytest.fixture(scope="module")
def play(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("play")
    argv = ["data", "generate", "--expert", "random", "--env", "crafter", "--episodes", "3",
            "--max-steps", "60", "--seed", "0", "--out", str(out), "--no-progress"]
    assert main(argv) == 0
    return out


@pytest.fixture(scope="module")
def captioned(play, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("cap")
    argv = ["data", "caption", "--src", str(play), "--out", str(out), "--seed", "0",
            "--per-shard", "3"]
    assert main(argv) == 0
    return out


def read_split(root: Path, split: str) -> list[dict]:
    urls = list_caption_shards(root, split)
    dataset = wds.WebDataset(urls, shardshuffle=False, empty_check=False)
    return list(dataset.map(decode_caption_sample))


def test_samples_are_source_clips_with_their_caption(play, captioned):
    episodes = {e["meta"]["episode"]: e for e in iter_episodes(list_shards(play))}
    vocab = load_vocabulary()
    samples = read_split(captioned, "train") + read_split(captioned, "test")
    assert samples
    for s in samples:
        assert s["frames"].shape == (6, 144, 144, 3) and s["frames"].dtype == np.uint8
        source = episodes[s["episode"]]
        t = s["step"]
        assert np.array_equal(s["frames"], source["frames"][t - 4 : t + 2])
        assert s["seed"] == source["meta"]["seed"]
        caption = vocab.captions[s["caption_id"]]
        assert (caption.text, caption.rule) == (s["caption"], s["rule"])
        assert caption.category == s["category"]


def test_manifest_counts_and_split(captioned):
    manifest = json.loads((captioned / "manifest.json").read_text())
    train, test = manifest["splits"]["train"], manifest["splits"]["test"]
    assert test["samples"] > 0 and train["samples"] > 0
    assert (train["episodes"], test["episodes"]) == (2, 1)  # 1000 requested > 3: 5%, at least one
    assert len(manifest["heldout"]) == 1 and manifest["heldout"][0] in manifest["episodes"]
    assert (manifest["balance"], manifest["balance_unit"], manifest["per_unit"]) == (
        "uniform", "category", None  # the paper balances rule categories
    )
    vocab = load_vocabulary()
    for split in (train, test):
        before, after = split["counts_before"], split["counts_after"]
        kept = [n for n in after["categories"].values() if n]
        assert len(set(kept)) == 1  # every category that fired keeps the rarest one's count
        fired = {c for c, n in before["categories"].items() if n}
        assert {c for c, n in after["categories"].items() if n} == fired
        for category in fired:  # inside a category the rules are spread evenly
            rules = {c.rule for c in vocab.captions if c.category == category}
            most = max(after["rules"][r] for r in rules)
            for r in rules:
                assert after["rules"][r] in (before["rules"][r], most, most - 1)
        for level in ("categories", "rules", "captions"):
            assert sum(after[level].values()) == split["samples"]
        assert sum(s["samples"] for s in split["shards"]) == split["samples"]
        for level in ("categories", "rules"):
            expected = {k: round(n / split["samples"], 4) for k, n in after[level].items()}
            assert split["shares"][level] == expected
    held = set(manifest["heldout"])
    assert all(s["episode"] in held for s in read_split(captioned, "test"))
    assert not any(s["episode"] in held for s in read_split(captioned, "train"))


def test_rule_unit_evens_out_rules_and_prints_both_shares(play, tmp_path, capsys):
    argv = ["data", "caption", "--src", str(play), "--out", str(tmp_path), "--seed", "0",
            "--balance-unit", "rule"]
    assert main(argv) == 0
    out = capsys.readouterr().out
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert manifest["balance_unit"] == "rule"
    for name, split in manifest["splits"].items():
        kept = [n for n in split["counts_after"]["rules"].values() if n]
        assert len(set(kept)) == 1  # every rule that fired keeps the rarest one's count
        fired = {r for r, n in split["counts_before"]["rules"].items() if n}
        assert {r for r, n in split["counts_after"]["rules"].items() if n} == fired
        for level, label in (("categories", "category"), ("rules", "rule")):
            line = next(x for x in out.splitlines() if x.startswith(f"{name} shares by {label}:"))
            for key, share in split["shares"][level].items():
                assert (f"{key} {share:.1%}" in line) == (share > 0)
    assert "(balanced per rule)" in out


def test_per_rule_is_a_quota_per_rule(play, tmp_path):
    argv = ["data", "caption", "--src", str(play), "--out", str(tmp_path), "--seed", "0",
            "--per-rule", "1"]
    assert main(argv) == 0
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert (manifest["balance_unit"], manifest["per_unit"]) == ("rule", 1)
    for split in manifest["splits"].values():
        assert set(split["counts_after"]["rules"].values()) == {0, 1}


def test_per_rule_with_the_category_unit_is_a_usage_error(play, tmp_path, capsys):
    argv = ["data", "caption", "--src", str(play), "--out", str(tmp_path),
            "--balance-unit", "category", "--per-rule", "5"]
    with pytest.raises(SystemExit):
        main(argv)
    assert "use --per-unit with --balance-unit category" in capsys.readouterr().err


def test_unknown_balance_unit_fails_before_the_rule_pass(tmp_path):
    def episodes():
        pytest.fail("the episodes were read before the arguments were checked")

    with pytest.raises(ValueError, match="unit 'caption' not in"):
        write_caption_dataset(episodes, tmp_path, balance_unit="caption")


def _shard_bytes(root: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(root.glob("*.tar"))}


def test_same_input_and_seed_give_identical_shards(play, captioned, tmp_path):
    caption_dataset(play, tmp_path, seed=0, per_shard=3)
    assert _shard_bytes(tmp_path) == _shard_bytes(captioned)


def test_resume_rewrites_only_missing_shards(play, captioned, tmp_path):
    caption_dataset(play, tmp_path, seed=0, per_shard=3)
    first = sorted(tmp_path.glob("*.tar"))[0]
    first.unlink()
    caption_dataset(play, tmp_path, seed=0, per_shard=3)
    assert _shard_bytes(tmp_path) == _shard_bytes(captioned)
    assert not list(tmp_path.glob("*.tmp"))


def test_resuming_a_different_run_is_refused(play, tmp_path):
    caption_dataset(play, tmp_path, seed=0, per_shard=3)
    with pytest.raises(ValueError, match="different caption run.*per_shard"):
        caption_dataset(play, tmp_path, seed=0, per_shard=4)


def test_heldout_count_is_never_empty():
    assert heldout_count(20_000, 1000, 0.05) == 1000
    assert heldout_count(3, 1000, 0.05) == 1
    assert heldout_count(100, 1000, 0.05) == 5
    assert heldout_count(3, 2, 0.05) == 2
    with pytest.raises(ValueError, match="at least 2 episodes"):
        heldout_count(1, 1000, 0.05)
    with pytest.raises(ValueError, match="must be >= 1"):
        heldout_count(10, 0, 0.05)


def test_single_episode_input_is_an_error(play, tmp_path):
    episode = next(iter_episodes(list_shards(play)))
    with pytest.raises(ValueError, match="at least 2 episodes"):
        write_caption_dataset(lambda: [episode], tmp_path)


def test_val_split_holds_other_episodes_and_leaves_the_test_split_as_it_was(play, captioned, tmp_path):
    argv = ["data", "caption", "--src", str(play), "--out", str(tmp_path), "--seed", "0",
            "--per-shard", "3", "--val-episodes", "1"]
    assert main(argv) == 0
    manifest = json.loads((tmp_path / "manifest.json").read_text())
    assert sorted(manifest["splits"]) == ["test", "train", "val"]
    episodes = {split: {s["episode"] for s in read_split(tmp_path, split)} for split in manifest["splits"]}
    assert episodes["val"] == set(manifest["val_episodes"]) and len(manifest["val_episodes"]) == 1
    assert not episodes["val"] & (episodes["train"] | episodes["test"])
    test_shards = sorted(tmp_path.glob("test-*.tar"))
    assert [p.read_bytes() for p in test_shards] == [
        p.read_bytes() for p in sorted(captioned.glob("test-*.tar"))
    ]


def test_val_split_may_not_take_every_training_episode(play, tmp_path):
    with pytest.raises(ValueError, match="leaves no training episode"):
        caption_dataset(play, tmp_path, heldout_episodes=1, val_episodes=2)
