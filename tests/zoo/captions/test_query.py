"""Zero-shot captioning demo: checkpoint loading without Lightning, clip files, top captions."""

import argparse
import io

import numpy as np
import pytest
import torch
import zstandard

from zoo.captions.query import load_clip, run_query, top_captions
from zoo.captions.vocabulary import load_vocabulary
from zoo.models.cclip import build_cclip
from zoo.weights import load_model


@pytest.fixture(scope="module")
def checkpoint(tmp_path_factory):
    """A checkpoint laid out as Lightning writes one for lit_models.cclip.CCLIP."""
    torch.manual_seed(0)
    model = build_cclip("smoke", text_layers=1)
    path = tmp_path_factory.mktemp("ckpt") / "cclip.ckpt"
    state = {f"model.{key}": value for key, value in model.state_dict().items()}
    hparams = {"model": "smoke", "text_layers": 1, "vision_layers": None, "lr": 1e-3}
    torch.save({"hyper_parameters": hparams, "state_dict": state}, path)
    return path, model


def test_checkpoint_rebuilds_the_same_model(checkpoint):
    path, model = checkpoint
    loaded = load_model(path, "cclip")
    assert loaded.config == model.config and not loaded.training
    with torch.no_grad():
        torch.testing.assert_close(
            loaded.encode_text(["go to sleep"]), model.encode_text(["go to sleep"])
        )


def test_top_captions_are_sorted_probabilities_over_the_vocabulary(checkpoint):
    model = load_model(checkpoint[0], "cclip")
    clip = np.random.default_rng(0).integers(0, 256, (6, 144, 144, 3), dtype=np.uint8)
    best = top_captions(model, clip, k=5)
    assert len(best) == 5
    scores = [score for _, score in best]
    assert scores == sorted(scores, reverse=True) and 0 < sum(scores) <= 1
    assert {caption for caption, _ in best} <= set(load_vocabulary().texts())
    assert len(top_captions(model, clip, k=100)) == 61
    with pytest.raises(ValueError, match="one clip"):
        top_captions(model, np.zeros((2, 6, 144, 144, 3), np.uint8))


def test_clip_files_and_query_command(checkpoint, tmp_path, capsys):
    clip = np.random.default_rng(1).integers(0, 256, (6, 144, 144, 3), dtype=np.uint8)
    np.save(tmp_path / "clip.npy", clip)
    buffer = io.BytesIO()
    np.save(buffer, clip)
    (tmp_path / "clip.npy.zst").write_bytes(zstandard.ZstdCompressor().compress(buffer.getvalue()))
    np.testing.assert_array_equal(load_clip(tmp_path / "clip.npy"), clip)
    np.testing.assert_array_equal(load_clip(tmp_path / "clip.npy.zst"), clip)

    args = argparse.Namespace(
        checkpoint=str(checkpoint[0]), clip=str(tmp_path / "clip.npy.zst"), k=3, device="cpu"
    )
    assert run_query(args) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == 3 and all(line.split("\t")[1] in load_vocabulary() for line in lines)


def test_missing_or_foreign_checkpoint_is_named(tmp_path):
    with pytest.raises(FileNotFoundError, match="nothing.ckpt"):
        load_model(tmp_path / "nothing.ckpt", "cclip")
    torch.save({"state_dict": {}}, tmp_path / "other.ckpt")
    with pytest.raises(ValueError, match="hyper_parameters"):
        load_model(tmp_path / "other.ckpt", "cclip")
