"""CVAE prior module: a short fit logs the documented metrics, and its checkpoint reloads without
Lightning to the same outputs."""

import lightning as L
import numpy as np
import pytest
import torch
from torch.nn import functional as F

from datamodules.prior_pairs import PriorPairsDataModule
from lit_models.prior import VALIDATION_SEED, CVAEPriorModule
from zoo.weights import load_model

DIM = 8


@pytest.fixture(scope="module")
def pairs(tmp_path_factory):
    """4 captions with a direction each: z_t is the direction, z_v the direction plus noise;
    96 pairs from 12 episodes."""
    rng = np.random.default_rng(0)
    directions = rng.normal(size=(4, DIM))
    caption_id = np.arange(96) % 4
    video = directions[caption_id] + 0.3 * rng.normal(size=(96, DIM))

    def unit(x: np.ndarray) -> np.ndarray:
        return (x / np.linalg.norm(x, axis=1, keepdims=True)).astype(np.float32)

    path = tmp_path_factory.mktemp("pairs") / "pairs.npz"
    np.savez(
        path, video=unit(video), text=unit(directions[caption_id]), caption_id=caption_id,
        variant=np.zeros(96, np.int64), episode=np.arange(96) // 8, step=np.arange(96),
    )
    return path


def trainer(tmp_path, **kwargs) -> L.Trainer:
    return L.Trainer(
        accelerator="cpu", devices=1, max_steps=40, logger=False, enable_progress_bar=False,
        enable_model_summary=False, num_sanity_val_steps=0, default_root_dir=tmp_path, **kwargs
    )


@pytest.fixture
def one_thread():
    """Tiny matrices: more intra-op threads only add synchronisation (10x slower on a busy
    2-core machine)."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def test_fit_logs_losses_and_cosines_and_reloads_without_lightning(pairs, tmp_path, one_thread):
    L.seed_everything(0)
    module = CVAEPriorModule(embed_dim=DIM, hidden=32, latent_dim=4, lr=3e-3)
    data = PriorPairsDataModule(str(pairs), batch_size=16, val_fraction=0.25)
    fit = trainer(tmp_path)
    fit.fit(module, data)
    metrics = fit.callback_metrics
    for stage in ("train", "val"):
        assert {f"{stage}/loss", f"{stage}/recon", f"{stage}/kl"} <= set(metrics)
    # the logged cosines are those lit_models/prior.py defines, over the held-out episodes (one
    # batch) at the trained weights
    module.eval()
    val = data.splits["val"]
    video, text = val["video"], val["text"]
    assert val["has_caption_mean"].all()  # every caption has training pairs
    draws = torch.Generator().manual_seed(VALIDATION_SEED)
    expected = {
        "cos_mean": F.cosine_similarity(module.model.sample(text, mean=True), video),
        "cos_sample": F.cosine_similarity(module.model.sample(text, generator=draws), video),
        "cos_text": F.cosine_similarity(text, video),
        "cos_caption_mean": F.cosine_similarity(val["caption_mean"], video),
    }
    for name, cosines in expected.items():
        assert float(metrics[f"val/{name}"]) == pytest.approx(float(cosines.mean()), abs=1e-5)
    # 40 steps on 4 well-separated captions: the decoded goal points at its caption's clips
    assert float(metrics["val/cos_mean"]) > 0.7

    (path,) = (tmp_path / "checkpoints").glob("*.ckpt")
    loaded = load_model(path, "prior")
    text = torch.from_numpy(np.load(pairs)["text"][:5])
    torch.testing.assert_close(loaded.sample(text, mean=True), module(text))
    torch.testing.assert_close(
        loaded.sample(text, generator=torch.Generator().manual_seed(3)),
        module.model.sample(text, generator=torch.Generator().manual_seed(3)),
    )


def test_pairs_of_another_width_are_refused_before_training(pairs, tmp_path):
    module = CVAEPriorModule(embed_dim=DIM * 2, hidden=8, latent_dim=2)
    data = PriorPairsDataModule(str(pairs), batch_size=16)
    with pytest.raises(ValueError, match=r"embed_dim=16, but the pairs in .*pairs.npz are 8-d"):
        trainer(tmp_path).fit(module, data)
