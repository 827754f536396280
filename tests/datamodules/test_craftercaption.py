"""CrafterCaption datamodule on tiny shards written with zoo.captions.dataset's own encoder."""

import json

import numpy as np
import pytest
import torch
import zstandard

from datamodules.craftercaption import CrafterCaptionDataModule
from datamodules.seeded_shuffle import SeededShuffle
from zoo.captions.dataset import EpisodeInfo, _encode_sample, _write_tar
from zoo.captions.vocabulary import load_vocabulary


def write_fake_craftercaption(root, shard_sizes: dict[str, list[int]]) -> None:
    """Shards in CrafterCaption's layout: clip n's pixels all equal n % 256, its caption n % 61."""
    vocabulary = load_vocabulary()
    compressor = zstandard.ZstdCompressor(level=3)
    root.mkdir(parents=True, exist_ok=True)
    splits, number = {}, 0
    for split, sizes in shard_sizes.items():
        shards = []
        for index, size in enumerate(sizes):
            samples = []
            for _ in range(size):
                clip = np.full((6, 144, 144, 3), number % 256, np.uint8)
                info = EpisodeInfo(number // 10, seed=7, length=100, env="crafter", expert="x")
                caption = vocabulary.captions[number % len(vocabulary)]
                samples.append(_encode_sample(clip, info, number % 10 + 4, caption, compressor))
                number += 1
            name = f"{split}-{index:06d}.tar"
            _write_tar(root / name, samples)
            shards.append({"name": name, "samples": size})
        splits[split] = {"shards": shards, "samples": sum(sizes)}
    captions = [{"id": c.id, "caption": c.text} for c in vocabulary.captions]
    (root / "manifest.json").write_text(json.dumps({"captions": captions, "splits": splits}))


@pytest.fixture(scope="module")
def caption_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("craftercaption")
    write_fake_craftercaption(root, {"train": [10, 10, 10], "test": [7]})
    return root


def clip_numbers(batches) -> list[int]:
    return [int(frames[0, 0, 0, 0]) for batch in batches for frames in batch["frames"]]


def test_batches_have_the_documented_fields(caption_root):
    module = CrafterCaptionDataModule(str(caption_root), batch_size=4, num_workers=0)
    batch = next(iter(module.train_dataloader()))
    assert batch["frames"].shape == (4, 6, 144, 144, 3) and batch["frames"].dtype == torch.uint8
    assert batch["caption_id"].dtype == torch.int64 and batch["caption_id"].shape == (4,)
    vocabulary = load_vocabulary()
    for caption_id, caption, rule in zip(batch["caption_id"], batch["caption"], batch["rule"]):
        assert vocabulary.captions[int(caption_id)].text == caption
        assert vocabulary.captions[int(caption_id)].rule == rule
    numbers = clip_numbers([batch])
    assert batch["caption_id"].tolist() == [n % 61 for n in numbers]
    assert batch["episode"].tolist() == [n // 10 for n in numbers]


def test_validation_reads_every_held_out_clip_once_in_order(caption_root):
    module = CrafterCaptionDataModule(str(caption_root), eval_batch_size=3, num_workers=0)
    batches = list(module.test_dataloader())
    assert [len(b["caption_id"]) for b in batches] == [3, 3, 1]  # partial last batch kept
    assert clip_numbers(batches) == list(range(30, 37))


def test_training_pass_is_shuffled_complete_and_reproducible(caption_root):
    def epochs(seed: int, first_epoch: int = 0, count: int = 1) -> list[list[int]]:
        module = CrafterCaptionDataModule(
            str(caption_root), batch_size=5, num_workers=0, shuffle_buffer=8, seed=seed
        )
        stream = module.dataset("train", train=True, first_epoch=first_epoch)
        return [clip_numbers(stream) for _ in range(count)]

    first, second = epochs(0, count=2)
    assert sorted(first) == sorted(second) == list(range(30))
    assert first != list(range(30)) and first != second  # shuffled, anew each epoch
    assert epochs(0, count=2) == [first, second]
    assert epochs(1)[0] != first
    assert epochs(0, first_epoch=1) == [second]  # a run resumed at epoch 1


def test_with_epoch_repeats_the_stream_to_the_requested_number_of_batches(caption_root):
    module = CrafterCaptionDataModule(
        str(caption_root), batch_size=4, num_workers=0, train_batches_per_epoch=12
    )
    torch.manual_seed(0)
    batches = list(module.train_dataloader())
    assert len(batches) == 12  # 48 clips from a 30-clip stream
    numbers = clip_numbers(batches)
    assert set(numbers) == set(range(30))


def test_workers_split_the_shards(caption_root):
    module = CrafterCaptionDataModule(str(caption_root), batch_size=2, num_workers=2)
    torch.manual_seed(0)
    numbers = clip_numbers(module.train_dataloader())
    assert sorted(numbers) == list(range(30))  # 3 shards over 2 workers, none read twice


def test_seeded_shuffle_keeps_every_item_and_changes_order_per_pass():
    shuffle = SeededShuffle(bufsize=4, salt=0)
    shuffle.start_epoch(seed=3, epoch=0)
    first, second = list(shuffle(iter(range(20)))), list(shuffle(iter(range(20))))
    assert sorted(first) == sorted(second) == list(range(20))
    assert first != second
    shuffle.start_epoch(seed=3, epoch=0)  # the same seed and epoch replay the same passes
    assert [list(shuffle(iter(range(20)))) for _ in range(2)] == [first, second]


def test_manifest_with_other_captions_is_rejected(tmp_path):
    root = tmp_path / "other"
    write_fake_craftercaption(root, {"train": [1], "test": [1]})
    manifest = json.loads((root / "manifest.json").read_text())
    manifest["captions"][3]["caption"] = "juggle cows"
    (root / "manifest.json").write_text(json.dumps(manifest))
    module = CrafterCaptionDataModule(str(root), num_workers=0)
    with pytest.raises(ValueError, match="differ from zoo/captions/captions.yaml"):
        module.train_dataloader()
    with pytest.raises(FileNotFoundError, match="manifest.json"):
        CrafterCaptionDataModule(str(tmp_path / "nowhere"), num_workers=0).train_dataloader()


def test_validation_reads_the_val_split_when_there_is_one(caption_root, tmp_path):
    with_val = tmp_path / "with_val"
    write_fake_craftercaption(with_val, {"train": [4], "val": [3], "test": [5]})
    module = CrafterCaptionDataModule(str(with_val), eval_batch_size=8, num_workers=0)
    assert module.val_split == "val"
    assert len(clip_numbers(module.val_dataloader())) == 3
    without = CrafterCaptionDataModule(str(caption_root), num_workers=0)
    with pytest.raises(ValueError, match=r"no 'val' split.*--val-episodes.*val_split=test"):
        without.val_dataloader()
    on_test = CrafterCaptionDataModule(str(caption_root), num_workers=0, val_split="test")
    with pytest.warns(UserWarning, match="val_split='test' is the test split"):
        assert on_test.val_split == "test"
