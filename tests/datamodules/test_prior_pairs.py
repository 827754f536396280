"""Prior pairs: `zoo goals prior-pairs` on a tiny CrafterCaption folder and a tiny C-CLIP, then the
datamodule's episode split and batches."""

import json

import numpy as np
import pytest
import torch
import zstandard

from datamodules.prior_pairs import PriorPairsDataModule, caption_means, split_episodes
from zoo.captions.dataset import EpisodeInfo, _encode_sample, _write_tar
from zoo.captions.vocabulary import load_vocabulary
from zoo.cli import main
from zoo.goals.prior_pairs import read_prior_pairs, write_prior_pairs
from zoo.models.cclip import build_cclip

EMBED_DIM = 64  # the smoke preset's


@pytest.fixture(scope="module")
def caption_root(tmp_path_factory):
    """CrafterCaption layout: 'test' holds 11 clips of episodes 0..3 in two shards (clip n: pixels
    n * 20, caption n % 5, episode n // 3), 'train' one clip."""
    vocabulary = load_vocabulary()
    compressor = zstandard.ZstdCompressor(level=3)
    root = tmp_path_factory.mktemp("craftercaption")
    splits, number = {}, 0
    for split, sizes in {"test": [6, 5], "train": [1]}.items():
        shards = []
        for index, size in enumerate(sizes):
            samples = []
            for _ in range(size):
                clip = np.full((6, 144, 144, 3), number * 20 % 256, np.uint8)
                info = EpisodeInfo(number // 3, seed=1, length=50, env="crafter", expert="x")
                caption = vocabulary.captions[number % 5]
                samples.append(_encode_sample(clip, info, number + 4, caption, compressor))
                number += 1
            name = f"{split}-{index:06d}.tar"
            _write_tar(root / name, samples)
            shards.append({"name": name, "samples": size})
        splits[split] = {"shards": shards, "samples": sum(sizes)}
    captions = [{"id": c.id, "caption": c.text} for c in vocabulary.captions]
    (root / "manifest.json").write_text(json.dumps({"captions": captions, "splits": splits}))
    return root


@pytest.fixture(scope="module")
def cclip_checkpoint(tmp_path_factory):
    """A checkpoint laid out as Lightning writes one for lit_models.cclip.CCLIP."""
    torch.manual_seed(0)
    model = build_cclip("smoke", text_layers=1, vision_layers=1)
    path = tmp_path_factory.mktemp("ckpt") / "cclip.ckpt"
    state = {f"model.{key}": value for key, value in model.state_dict().items()}
    hparams = {"model": "smoke", "text_layers": 1, "vision_layers": 1}
    torch.save({"hyper_parameters": hparams, "state_dict": state}, path)
    return path, model.eval()


@pytest.fixture(scope="module")
def pairs(caption_root, cclip_checkpoint, tmp_path_factory):
    out = tmp_path_factory.mktemp("pairs") / "pairs.npz"
    write_prior_pairs(cclip_checkpoint[0], caption_root, out, paraphrases=True, batch_size=4,
                      progress=False)
    return out


def test_pairs_file_holds_one_row_per_clip_with_its_embeddings(pairs, cclip_checkpoint):
    arrays = read_prior_pairs(pairs, embed_dim=EMBED_DIM)
    assert arrays["video"].shape == arrays["text"].shape == (11, EMBED_DIM)
    assert arrays["video"].dtype == arrays["text"].dtype == np.float32
    np.testing.assert_array_equal(arrays["caption_id"], np.arange(11) % 5)
    np.testing.assert_array_equal(arrays["episode"], np.arange(11) // 3)
    np.testing.assert_array_equal(arrays["step"], np.arange(11) + 4)
    vocabulary, model = load_vocabulary(), cclip_checkpoint[1]
    with torch.no_grad():
        clip = torch.full((1, 6, 144, 144, 3), 7 * 20, dtype=torch.uint8)
        np.testing.assert_allclose(arrays["video"][7], model.encode_video(clip)[0], atol=1e-5)
        caption = vocabulary.captions[arrays["caption_id"][7]].text
        text = vocabulary.variants(caption)[arrays["variant"][7]]
        np.testing.assert_allclose(arrays["text"][7], model.encode_text([text])[0], atol=1e-5)
    np.testing.assert_allclose(np.linalg.norm(arrays["video"], axis=1), 1.0, atol=1e-5)
    info = json.loads(pairs.with_suffix(".json").read_text())
    assert info["pairs"] == 11 and info["episodes"] == 4 and info["embed_dim"] == EMBED_DIM
    assert len(info["checkpoint_sha256"]) == 64 and info["split"] == "test"
    assert not list(pairs.parent.glob(".*tmp"))


def test_capped_paraphrased_pairs_are_seeded_rows_of_the_full_file(
    pairs, caption_root, cclip_checkpoint, tmp_path
):
    def write(name: str) -> dict[str, np.ndarray]:
        write_prior_pairs(cclip_checkpoint[0], caption_root, tmp_path / name, max_pairs=5,
                          paraphrases=True, seed=1, progress=False)
        return read_prior_pairs(tmp_path / name)

    first, again, full = write("a.npz"), write("b.npz"), read_prior_pairs(pairs)
    assert len(first["video"]) == 5
    for name in first:
        np.testing.assert_array_equal(first[name], again[name])
    rows = first["step"] - 4  # the fixture's step is the clip number + 4
    np.testing.assert_allclose(first["video"], full["video"][rows], atol=1e-5)


def test_command_line_and_its_errors(caption_root, cclip_checkpoint, tmp_path, capsys):
    out = tmp_path / "cli.npz"
    args = ["goals", "prior-pairs", "--checkpoint", str(cclip_checkpoint[0]), "--src",
            str(caption_root), "--out", str(out), "--no-progress"]
    assert main(args) == 0
    assert "11 pairs from 4 episodes" in capsys.readouterr().out
    assert main(args[:-1] + ["--split", "val", "--no-progress"]) == 2
    assert "splits ['test', 'train'], not 'val'" in capsys.readouterr().err
    assert main(args[:-3] + ["--out", str(tmp_path / "x.txt")]) == 2
    assert "must end in .npz" in capsys.readouterr().err


def test_reading_a_file_of_another_width_or_layout_is_refused(pairs, tmp_path):
    with pytest.raises(ValueError, match="64-d and text 64-d, expected both 512-d"):
        read_prior_pairs(pairs, embed_dim=512)
    np.savez(tmp_path / "partial.npz", video=np.zeros((2, 4), np.float32))
    with pytest.raises(ValueError, match=r"partial.npz lacks \['caption_id'"):
        read_prior_pairs(tmp_path / "partial.npz")
    with pytest.raises(FileNotFoundError, match="zoo goals prior-pairs"):
        read_prior_pairs(tmp_path / "none.npz")


def test_datamodule_holds_out_whole_episodes_with_caption_means(pairs):
    module = PriorPairsDataModule(str(pairs), batch_size=3, eval_batch_size=100,
                                  val_fraction=0.25, seed=0)
    assert module.embed_dim == EMBED_DIM
    train, val = module.splits["train"], module.splits["val"]
    assert len(train["video"]) + len(val["video"]) == 11
    assert not set(train["episode"].tolist()) & set(val["episode"].tolist())
    assert len(set(val["episode"].tolist())) == 1  # 25% of 4 episodes
    batches = list(module.train_dataloader())
    assert all(b["video"].shape == (3, EMBED_DIM) for b in batches)  # last partial one dropped
    (batch,) = module.val_dataloader()
    assert set(batch) == {"video", "text", "caption_id", "episode", "caption_mean",
                          "has_caption_mean"}
    means, present = caption_means(train["video"], train["caption_id"], 5)
    for row, caption in enumerate(batch["caption_id"].tolist()):
        assert bool(batch["has_caption_mean"][row]) == bool(present[caption])
        torch.testing.assert_close(batch["caption_mean"][row], means[caption])


def test_training_order_follows_seed_and_epoch(pairs):
    def order(seed: int, epoch: int) -> list[int]:
        module = PriorPairsDataModule(str(pairs), batch_size=1, val_fraction=0.25, seed=seed)
        loader = module.train_dataloader()
        loader.sampler.epoch = lambda: epoch
        return [int(b["episode"] * 100 + b["caption_id"]) for b in loader]

    assert order(0, 0) == order(0, 0)
    assert order(0, 0) != order(0, 1) and sorted(order(0, 0)) == sorted(order(0, 1))


def test_episode_split_needs_two_episodes():
    assert split_episodes(np.array([0, 0, 1, 2]), 0.5, seed=0).sum() in (1, 2)
    with pytest.raises(ValueError, match="at least 2"):
        split_episodes(np.array([3, 3]), 0.5, seed=0)
