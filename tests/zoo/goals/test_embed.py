"""`zoo goals embed` on a tiny random-agent CrafterPlay set (3 crafter episodes, 3 shards) and a
tiny C-CLIP: format, equality with encode_video, captions, resume, refusals, damaged shards."""

from __future__ import annotations

import io
import json
import shutil
import tarfile
from pathlib import Path

import numpy as np
import pytest
import torch

import zoo.goals.embed as embed_module
from zoo.captions.rules import EpisodeView, scan_episode
from zoo.captions.vocabulary import load_vocabulary
from zoo.cli import main
from zoo.data.reader import iter_episodes, list_shards
from zoo.goals.embed import (
    CAPTION_PRIORITY,
    EmbeddingMismatchError,
    check_embeddings_match,
    load_embedding_manifest,
    read_embedding_shard,
    step_captions,
)
from zoo.goals.embed_writer import ClipEmbedder
from zoo.models.cclip import build_cclip

SHARD_KEYS = {"index", "file", "source_file", "source_sha256", "episodes", "steps", "sha256"}


def _save_checkpoint(path: Path, seed: int) -> Path:
    """A checkpoint laid out as Lightning writes one for lit_models.cclip.CCLIP."""
    torch.manual_seed(seed)
    model = build_cclip("smoke", vision_layers=1, text_layers=1)
    state = {f"model.{key}": value for key, value in model.state_dict().items()}
    hparams = {"model": "smoke", "vision_layers": 1, "text_layers": 1}
    torch.save({"hyper_parameters": hparams, "state_dict": state}, path)
    return path


@pytest.fixture(scope="module")
def play(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("play")
    argv = ["data", "generate", "--expert", "random", "--env", "crafter", "--episodes", "3",
            "--episodes-per-shard", "1", "--max-steps", "60", "--seed", "0", "--out", str(out),
            "--no-progress"]
    assert main(argv) == 0
    return out


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory) -> Path:
    return _save_checkpoint(tmp_path_factory.mktemp("ckpt") / "cclip.ckpt", seed=0)


@pytest.fixture(scope="module")
def embedded(play, checkpoint, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("embed")
    argv = ["goals", "embed", "--checkpoint", str(checkpoint), "--src", str(play), "--out",
            str(out), "--batch-size", "20", "--no-progress"]
    assert main(argv) == 0
    return out


@pytest.fixture(scope="module")
def episodes(play) -> list[dict]:
    return list(iter_episodes(list_shards(play)))


def _all_shards(root: Path) -> dict[int, dict[str, np.ndarray]]:
    manifest = load_embedding_manifest(root)
    out = {}
    for entry in manifest["shards"]:
        out.update(read_embedding_shard(root / entry["file"]))
    return out


def test_layout_dtypes_and_manifest(play, embedded, checkpoint, episodes):
    manifest = load_embedding_manifest(embedded)
    play_manifest = json.loads((play / "manifest.json").read_text())
    assert manifest["format"] == "crafter-zoo-goal-embeddings" and manifest["version"] == 1
    assert manifest["embed_dim"] == 64 and manifest["dtype"] == "float16"
    assert manifest["clip"] == {"history": 4, "future": 1}
    assert manifest["caption_priority"] == list(CAPTION_PRIORITY)
    assert manifest["checkpoint"]["path"] == str(checkpoint)
    assert [e["index"] for e in manifest["shards"]] == [0, 1, 2]
    for entry, source in zip(manifest["shards"], play_manifest["shards"]):
        assert set(entry) == SHARD_KEYS
        assert entry["file"] == f"embed-{entry['index']:06d}.tar"
        assert (entry["source_file"], entry["source_sha256"]) == (source["file"], source["sha256"])
        assert (entry["episodes"], entry["steps"]) == (source["episodes"], source["steps"])
        with tarfile.open(embedded / entry["file"]) as tar:
            episode = source["first_episode"]
            names = [f"{episode:09d}.goal.npy", f"{episode:09d}.caption.npy", f"{episode:09d}.json"]
            assert tar.getnames() == names
            meta = json.loads(tar.extractfile(names[2]).read())
        assert meta == {"episode": episode, "length": source["steps"],
                        "seed": source["episode_seeds"][0]}
    rows = _all_shards(embedded)
    assert list(rows) == [e["meta"]["episode"] for e in episodes]
    for episode in episodes:
        got = rows[episode["meta"]["episode"]]
        length = len(episode["frames"])
        assert got["goal"].dtype == np.float16 and got["goal"].shape == (length, 64)
        assert got["caption"].dtype == np.int16 and got["caption"].shape == (length,)
        np.testing.assert_allclose(np.linalg.norm(got["goal"].astype(np.float32), axis=1), 1,
                                   atol=2e-3)
    stats = manifest["stats"]
    assert stats["steps"] == sum(len(e["frames"]) for e in episodes)
    captioned = sum(int((r["caption"] >= 0).sum()) for r in rows.values())
    assert stats["captioned_steps"] == captioned
    assert sum(c["steps"] for c in stats["categories"].values()) == captioned
    check_embeddings_match(embedded, play)


def test_rows_are_encode_video_of_the_clamped_clips(embedded, checkpoint, episodes):
    from zoo.weights import load_model

    model = load_model(checkpoint, "cclip")
    episode = episodes[0]
    frames, length = episode["frames"], len(episode["frames"])
    clips = np.stack([frames[[min(max(s, 0), length - 1) for s in range(t - 4, t + 2)]]
                      for t in range(length)])
    with torch.inference_mode():
        expected = model.encode_video(torch.from_numpy(clips)).numpy()
    goal = _all_shards(embedded)[episode["meta"]["episode"]]["goal"].astype(np.float32)
    np.testing.assert_allclose(goal, expected, atol=2e-3)
    # float32, before the cast: frame sharing (a padded last group of 6 too) is encode_video
    embedder = ClipEmbedder(model, batch_size=25)
    assert embedder.batch_size == 24 and length % 6
    np.testing.assert_allclose(embedder(frames), expected, atol=1e-5)
    np.testing.assert_allclose(embedder.naive(frames[:7]), embedder(frames[:7]), atol=1e-5)


def _expected_captions(episode: dict) -> np.ndarray:
    """What scan_episode fires per step, the highest-priority category then lowest id kept."""
    vocab = load_vocabulary()
    rank = {c: i for i, c in enumerate(("achievement", "construction", "combat", "movement"))}
    out = np.full(len(episode["actions"]), -1)
    fired: dict[int, list] = {}
    for t, _, text in scan_episode(EpisodeView(episode["actions"], episode["state"])):
        fired.setdefault(t, []).append(vocab[text])
    for t, captions in fired.items():
        out[t] = min(captions, key=lambda c: (rank[c.category], c.id)).id
    return out


def test_step_captions_are_scan_episode_with_priority(embedded, episodes, monkeypatch):
    rows = _all_shards(embedded)
    for episode in episodes:
        expected = _expected_captions(episode)
        np.testing.assert_array_equal(rows[episode["meta"]["episode"]]["caption"], expected)
    assert any((r["caption"] >= 0).any() for r in rows.values())

    vocab = load_vocabulary()
    by_category = {}
    for caption in sorted(vocab.captions, key=lambda c: -c.id):
        by_category[caption.category] = caption  # the lowest id of each category
    move, combat, craft = by_category["movement"], by_category["combat"], by_category["achievement"]
    highest_achievement = max((c for c in vocab.captions if c.category == "achievement"),
                              key=lambda c: c.id)
    hits = [(5, "r", move.text), (5, "r", combat.text), (6, "r", move.text),
            (7, "r", highest_achievement.text), (7, "r", move.text), (7, "r", craft.text)]
    monkeypatch.setattr(embed_module, "scan_episode", lambda *args: iter(hits))
    episode = episodes[0]
    got = step_captions(EpisodeView(episode["actions"], episode["state"]), vocab)
    assert got.dtype == np.int16
    assert got[5] == combat.id and got[6] == move.id and got[7] == craft.id
    assert (np.delete(got, [5, 6, 7]) == -1).all()


def test_resume_rewrites_only_the_missing_shard_with_identical_bytes(embedded, play, checkpoint,
                                                                      tmp_path):
    out = tmp_path / "embed"
    shutil.copytree(embedded, out)
    before = {p.name: p.read_bytes() for p in out.glob("embed-*.tar")}
    (out / "embed-000001.tar").unlink()
    kept = {name: (out / name).stat().st_mtime_ns for name in ("embed-000000.tar",
                                                                "embed-000002.tar")}
    (out / "embed-000002.tar.tmp-999").write_bytes(b"half a shard")  # a killed run's leftover
    argv = ["goals", "embed", "--checkpoint", str(checkpoint), "--src", str(play), "--out",
            str(out), "--batch-size", "20", "--no-progress"]
    assert main(argv) == 0
    assert {p.name: p.read_bytes() for p in out.glob("embed-*")} == before
    assert {name: (out / name).stat().st_mtime_ns for name in kept} == kept
    manifest, original = load_embedding_manifest(out), load_embedding_manifest(embedded)
    assert manifest["shards"] == original["shards"]
    assert {k: v for k, v in manifest["stats"].items() if k != "last_run"} == {
        k: v for k, v in original["stats"].items() if k != "last_run"}


def test_other_checkpoint_or_source_is_refused(embedded, play, checkpoint, tmp_path, capsys):
    out = tmp_path / "embed"
    shutil.copytree(embedded, out)
    other = _save_checkpoint(tmp_path / "other.ckpt", seed=1)
    argv = ["goals", "embed", "--checkpoint", str(other), "--src", str(play), "--out", str(out),
            "--no-progress"]
    assert main(argv) == 2
    assert "another checkpoint" in capsys.readouterr().err

    other_play = tmp_path / "play"
    shutil.copytree(play, other_play)
    manifest = json.loads((other_play / "manifest.json").read_text())
    manifest["shards"] = manifest["shards"][:2]
    (other_play / "manifest.json").write_text(json.dumps(manifest))
    with pytest.raises(EmbeddingMismatchError, match="sha256"):
        check_embeddings_match(embedded, other_play)
    argv = ["goals", "embed", "--checkpoint", str(checkpoint), "--src", str(other_play), "--out",
            str(out), "--no-progress"]
    assert main(argv) == 2
    assert "another CrafterPlay manifest" in capsys.readouterr().err

    partial = tmp_path / "partial"
    argv = ["goals", "embed", "--checkpoint", str(checkpoint), "--src", str(play), "--out",
            str(partial), "--shards", "1:2", "--no-progress"]
    assert main(argv) == 0
    assert [e["index"] for e in load_embedding_manifest(partial)["shards"]] == [1]
    with pytest.raises(ValueError, match="lists 1 shards.*lists 3"):
        check_embeddings_match(partial, play)


def test_damaged_shards_and_missing_manifest_are_named(embedded, tmp_path):
    raw = (embedded / "embed-000000.tar").read_bytes()
    with tarfile.open(embedded / "embed-000000.tar") as tar:
        second = tar.getmembers()[1].offset  # a cut exactly between two members
    for name, data in {"half.tar": raw[: len(raw) // 2], "cut.tar": raw[:second],
                       "noise.tar": b"\1" * 4096}.items():
        (tmp_path / name).write_bytes(data)
        with pytest.raises(ValueError, match=f"{name}: corrupt goal-embedding shard"):
            read_embedding_shard(tmp_path / name)
    lacking = tmp_path / "lacking.tar"
    with tarfile.open(lacking, "w", format=tarfile.USTAR_FORMAT) as tar:
        info = tarfile.TarInfo("000000001.json")
        data = json.dumps({"episode": 1, "length": 2, "seed": 0}).encode()
        info.size = len(data)
        tar.addfile(info, io.BytesIO(data))
    with pytest.raises(ValueError, match=r"lacking.tar.*lacks \['goal.npy', 'caption.npy'\]"):
        read_embedding_shard(lacking)
    with pytest.raises(FileNotFoundError, match=str(tmp_path / "manifest.json")):
        load_embedding_manifest(tmp_path)


def test_frame_size_other_than_crafters_is_refused():
    with pytest.raises(ValueError, match="160x160 frames.*144x144"):
        ClipEmbedder(build_cclip("smoke", image_size=160, vision_layers=1, text_layers=1))


@pytest.mark.parametrize("text", ["3", "2:1", "a:b", "-1:2"])
def test_bad_shard_ranges_are_usage_errors(text, tmp_path, capsys):
    argv = ["goals", "embed", "--checkpoint", "x.ckpt", "--src", str(tmp_path), "--out",
            str(tmp_path / "o"), f"--shards={text}"]
    with pytest.raises(SystemExit) as exit_info:
        main(argv)
    assert exit_info.value.code == 2 and "A:B" in capsys.readouterr().err
