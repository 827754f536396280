"""Datamodules on a dataset folder served over HTTP read exactly what they read locally."""

from __future__ import annotations

import functools
import importlib.util
import json
import re
import threading
from collections.abc import Iterator
from http.server import SimpleHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import numpy as np
import pytest
import torch
import zstandard

from datamodules.craftercaption import CrafterCaptionDataModule
from datamodules.crafterplay import CrafterPlayDataModule
from zoo.agents import dataset_agent
from zoo.captions.dataset import EpisodeInfo, _encode_sample, _write_tar
from zoo.captions.vocabulary import load_vocabulary
from zoo.data.generate import GenerationConfig, generate
from zoo.data.reader import CorruptShardError
from zoo.data.storage import open_binary

SPLIT = {"val_fraction": 0.25, "test_fraction": 0.25}


class QuietHandler(SimpleHTTPRequestHandler):
    def log_message(self, *args) -> None:  # one stderr line per request otherwise
        pass


@pytest.fixture(scope="module")
def served(tmp_path_factory) -> Iterator[tuple[Path, str]]:
    """(folder, its http:// URL): a CrafterPlay folder in crafterplay/ (3 shards of 2 episodes)
    and a CrafterCaption folder in captions/, served by a local HTTP server without range
    requests."""
    folder = tmp_path_factory.mktemp("served")
    config = GenerationConfig(
        expert="random", episodes=6, seed=1, env="crafter", episodes_per_shard=2,
        chunk_length=32, max_steps=80,
    )
    generate(config, folder / "crafterplay", progress=False, build_agent=dataset_agent)
    _write_captions(folder / "captions")
    handler = functools.partial(QuietHandler, directory=str(folder))
    server = ThreadingHTTPServer(("127.0.0.1", 0), handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    yield folder, f"http://127.0.0.1:{server.server_port}/"
    server.shutdown()
    server.server_close()


def _write_captions(root: Path) -> None:
    """CrafterCaption shards (train: 2 of 3 clips, test: 1 of 2); clip n's pixels all equal n."""
    vocabulary, compressor = load_vocabulary(), zstandard.ZstdCompressor()
    root.mkdir()
    splits, number = {}, 0
    for split, sizes in {"train": [3, 3], "test": [2]}.items():
        shards = []
        for index, size in enumerate(sizes):
            samples = []
            for _ in range(size):
                clip = np.full((6, 144, 144, 3), number, np.uint8)
                info = EpisodeInfo(number, seed=7, length=100, env="crafter", expert="x")
                caption = vocabulary.captions[number]
                samples.append(_encode_sample(clip, info, 4, caption, compressor))
                number += 1
            _write_tar(root / f"{split}-{index:06d}.tar", samples)
            shards.append({"name": f"{split}-{index:06d}.tar", "samples": size})
        splits[split] = {"shards": shards, "samples": sum(sizes)}
    captions = [{"id": c.id, "caption": c.text} for c in vocabulary.captions]
    (root / "manifest.json").write_text(json.dumps({"captions": captions, "splits": splits}))


def _batches(dataset) -> list[dict]:
    return [
        {key: value for key, value in batch.items() if isinstance(value, torch.Tensor)}
        for batch in dataset
    ]


def _assert_same(local: list[dict], remote: list[dict]) -> None:
    assert local and len(local) == len(remote)
    for a, b in zip(local, remote):
        assert a.keys() == b.keys()
        assert all(torch.equal(a[key], b[key]) for key in a), "batches differ"


def _play(root: str | None = None, **kwargs) -> CrafterPlayDataModule:
    args = dict(seq_len=8, batch_size=2, num_workers=0, seed=0, **SPLIT)
    return CrafterPlayDataModule(root, **{**args, **kwargs})


def test_crafterplay_over_http_equals_the_local_folder(served) -> None:
    folder, url = served
    local, remote = _play(str(folder / "crafterplay")), _play(url + "crafterplay/")
    assert remote.shards.sources[0]["url"] == url + "crafterplay/crafterplay-000000.tar"
    for split in ("train", "val"):
        _assert_same(_batches(local.dataset(split)), _batches(remote.dataset(split)))
    episodes = {e for b in _batches(remote.dataset("train")) for e in b["episode"].flatten()}
    assert len(episodes) > 1  # the batches hold real data


def test_weighted_sources_mix_urls_and_folders(served) -> None:
    folder, url = served
    local = str(folder / "crafterplay")

    def mixed(first: str) -> CrafterPlayDataModule:
        return _play(sources=[{"root": first, "weight": 3}, {"root": local, "weight": 1}])

    remote = mixed(url + "crafterplay")
    _assert_same(_batches(mixed(local).dataset("train")), _batches(remote.dataset("train")))


def test_a_missing_manifest_url_is_a_one_line_error_naming_it(served) -> None:
    _, url = served
    with pytest.raises(FileNotFoundError) as err:
        _ = _play(url + "nowhere/").shards
    assert str(err.value) == (
        f"{url}nowhere/manifest.json not found: not a CrafterPlay folder (make it with"
        " `zoo data generate`)"
    )


def test_unknown_or_uninstalled_protocols_are_named() -> None:
    with pytest.raises(ValueError, match=re.escape("nosuch://x/manifest.json: unknown protocol")):
        _ = _play("nosuch://x").shards
    if importlib.util.find_spec("s3fs") is None:
        with pytest.raises(ImportError, match="s3fs"):
            _ = _play("s3://bucket/crafterplay").shards


def test_craftercaption_over_http_equals_the_local_folder(served) -> None:
    folder, url = served

    def batches(root: str, split: str, train: bool) -> list[dict]:
        module = CrafterCaptionDataModule(root, batch_size=2, num_workers=0, seed=0)
        return _batches(module.dataset(split, train))

    for split, train in (("train", True), ("test", False)):
        _assert_same(batches(str(folder / "captions"), split, train),
                     batches(url + "captions", split, train))
    with pytest.raises(FileNotFoundError, match=re.escape(f"{url}nowhere/manifest.json")):
        CrafterCaptionDataModule(url + "nowhere", num_workers=0).shards("train")


def test_crafterplay_through_a_pipe_command_equals_the_local_folder(served) -> None:
    folder, _ = served
    local = str(folder / "crafterplay")
    piped = _play(f"pipe:cat {local}/{{name}}")
    assert piped.shards.sources[0]["url"] == f"pipe:cat {local}/crafterplay-000000.tar"
    for split in ("train", "val"):
        _assert_same(_batches(_play(local).dataset(split)), _batches(piped.dataset(split)))


def test_a_failing_pipe_command_is_an_error_naming_it_and_its_stderr(served) -> None:
    folder, _ = served
    root = f"pipe:cat {folder}/nowhere/{{name}}"
    with pytest.raises(OSError, match=re.escape(f"pipe:cat {folder}/nowhere/manifest.json: the "
                                                "command exited with status 1 (cat: ")):
        _ = _play(root).shards
    with pytest.raises(ValueError, match=re.escape("needs {name} where the file name goes")):
        _ = _play(f"pipe:cat {folder}/crafterplay/manifest.json").shards


def test_a_pipe_closed_before_its_end_stops_the_command_without_an_error(tmp_path) -> None:
    with open_binary("pipe:yes") as stream:  # never ends on its own
        assert stream.read(4) == b"y\ny\n"
    with open_binary("pipe:head -c 1000000 /dev/zero; exit 3") as stream:
        assert stream.read(2) == b"\0\0"  # stopped long before the end: status not checked
    with pytest.raises(OSError, match="status 3"), open_binary("pipe:printf abc; exit 3") as stream:
        assert stream.read(2) == b"ab"  # a few bytes short of the end: the status counts


def test_a_shard_command_that_fails_at_its_end_is_a_corrupt_shard(served) -> None:
    folder, _ = served
    local = str(folder / "crafterplay")
    # the whole shard arrives, then the command reports failure: an error, not a good shard
    piped = _play(f"pipe:cat {local}/{{name}}; test {{name}} = manifest.json")
    with pytest.raises(CorruptShardError, match=re.escape(
            f"pipe:cat {local}/crafterplay-00000") + ".*exited with status 1"):
        _batches(piped.dataset("train"))
