"""C-CLIP LightningModule: lr groups, paraphrase sampling, a short fit, reload, the CLI."""

import json
from pathlib import Path

import lightning as L
import numpy as np
import pytest
import torch
import zstandard

from datamodules.craftercaption import CrafterCaptionDataModule
from lit_models.cclip import CCLIP
from zoo.captions.dataset import EpisodeInfo, _encode_sample, _write_tar
from zoo.captions.vocabulary import load_vocabulary
from zoo.weights import load_model

REPO = Path(__file__).resolve().parents[2]


def write_fake_craftercaption(root: Path, shard_sizes: dict[str, list[int]]) -> None:
    """Shards in CrafterCaption's layout: clip n is one solid colour, caption n % 61."""
    vocabulary = load_vocabulary()
    compressor = zstandard.ZstdCompressor(level=3)
    rng = np.random.default_rng(0)
    root.mkdir(parents=True, exist_ok=True)
    splits, number = {}, 0
    for split, sizes in shard_sizes.items():
        shards = []
        for index, size in enumerate(sizes):
            samples = []
            for _ in range(size):
                colour = rng.integers(0, 256, (6, 1, 1, 3), dtype=np.uint8)
                clip = np.broadcast_to(colour, (6, 144, 144, 3))
                info = EpisodeInfo(number // 10, seed=0, length=100, env="crafter", expert="x")
                caption = vocabulary.captions[number % len(vocabulary)]
                samples.append(_encode_sample(clip, info, 10, caption, compressor))
                number += 1
            name = f"{split}-{index:06d}.tar"
            _write_tar(root / name, samples)
            shards.append({"name": name, "samples": size})
        splits[split] = {"shards": shards, "samples": sum(sizes)}
    captions = [{"id": c.id, "caption": c.text} for c in vocabulary.captions]
    (root / "manifest.json").write_text(json.dumps({"captions": captions, "splits": splits}))


@pytest.fixture(scope="module")
def caption_root(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("craftercaption")
    write_fake_craftercaption(root, {"train": [32, 32], "test": [70]})
    return root


def smoke_module(**kwargs) -> CCLIP:
    torch.manual_seed(0)
    return CCLIP(model="smoke", **kwargs)


def group_lr_of(module: CCLIP, groups: list[dict], name: str) -> tuple[float, float]:
    param = dict(module.named_parameters())[name]
    (group,) = [g for g in groups if any(p is param for p in g["params"])]
    return group["lr"], group["weight_decay"]


def test_layer_wise_lr_groups_without_pretrained_weights():
    module = smoke_module(lr=1e-3, layer_decay=0.5, weight_decay=0.2)
    groups = module.parameter_groups()
    lr_of = lambda name: group_lr_of(module, groups, name)  # noqa: E731
    # smoke towers: 2 blocks -> layer ids 0 (embeddings), 1, 2 (blocks), 3 (final norm/projection).
    assert lr_of("model.clip.visual.conv1.weight") == pytest.approx((1e-3 * 0.5**3, 0.2))
    assert lr_of("model.clip.visual.class_embedding") == pytest.approx((1e-3 * 0.5**3, 0.0))
    assert lr_of("model.clip.visual.transformer.resblocks.0.mlp.c_fc.weight") == pytest.approx(
        (1e-3 * 0.5**2, 0.2)
    )
    assert lr_of("model.clip.transformer.resblocks.1.ln_2.bias") == pytest.approx((1e-3 * 0.5, 0.0))
    assert lr_of("model.clip.text_projection") == pytest.approx((1e-3, 0.2))
    assert lr_of("model.clip.logit_scale") == pytest.approx((1e-3, 0.0))
    assert lr_of("model.temporal.transformer.layers.0.linear1.weight") == pytest.approx((1e-3, 0.2))
    assert lr_of("model.video_adapter.residual_logit") == pytest.approx((1e-3, 0.0))
    grouped = sum(len(g["params"]) for g in groups)
    assert grouped == len(list(module.parameters()))


def test_pretrained_towers_get_the_multiplier_and_new_layers_do_not(tmp_path):
    path = tmp_path / "clip.pt"
    torch.save(smoke_module().model.clip.state_dict(), path)
    module = smoke_module(
        lr=1e-3, layer_decay=0.5, pretrained_lr_mult=0.25, pretrained_path=str(path)
    )
    groups = module.parameter_groups()
    lr_of = lambda name: group_lr_of(module, groups, name)[0]  # noqa: E731
    assert lr_of("model.clip.visual.conv1.weight") == pytest.approx(1e-3 * 0.25 * 0.5**3)
    assert lr_of("model.clip.ln_final.weight") == pytest.approx(1e-3 * 0.25)
    assert lr_of("model.temporal.position_embedding") == pytest.approx(1e-3)
    assert lr_of("model.video_adapter.mlp.0.weight") == pytest.approx(1e-3)


def test_pretrained_weights_load_at_setup_not_at_construction(tmp_path):
    source = smoke_module()
    path = tmp_path / "clip.pt"
    torch.save(source.model.clip.state_dict(), path)
    torch.manual_seed(5)
    module = CCLIP(model="smoke", pretrained_path=str(path))
    weight = lambda m: m.model.clip.visual.conv1.weight  # noqa: E731
    assert not torch.equal(weight(module), weight(source))
    module.setup("fit")
    assert torch.equal(weight(module), weight(source))


def test_paraphrases_are_sampled_uniformly_from_the_caption_and_its_variants():
    module = smoke_module(num_paraphrases=3)
    vocabulary = load_vocabulary()
    caption = vocabulary.captions[5]
    variants = list(vocabulary.variants(caption.text)[:4])
    expected = {tuple(t) for t in module.model.tokenize(variants).tolist()}
    torch.manual_seed(0)
    tokens = module.caption_tokens(torch.full((400,), 5), paraphrase=True)
    drawn = [tuple(t) for t in tokens.tolist()]
    assert set(drawn) == expected
    assert min(drawn.count(t) for t in expected) > 60  # ~100 each of 400
    templates = module.caption_tokens(torch.tensor([5, 0]), paraphrase=False)
    texts = [caption.text, vocabulary.captions[0].text]
    assert torch.equal(templates, module.model.tokenize(texts))
    with pytest.raises(ValueError, match="caption ids must be in 0..60"):
        module.caption_tokens(torch.tensor([61]), paraphrase=False)


def test_fit_validate_and_reload_from_checkpoint(caption_root, tmp_path):
    module = smoke_module(lr=5e-4, warmup_steps=2)
    data = CrafterCaptionDataModule(
        str(caption_root), batch_size=8, eval_batch_size=35, num_workers=0, shuffle_buffer=16,
        train_batches_per_epoch=4, val_split="test",  # the fake set has no val split
    )  # fmt: skip
    settings = dict(
        accelerator="cpu", logger=False, enable_checkpointing=False, enable_progress_bar=False,
        enable_model_summary=False, default_root_dir=tmp_path,
    )  # fmt: skip
    trainer = L.Trainer(max_steps=4, limit_val_batches=0, **settings)
    trainer.fit(module, data)
    assert trainer.global_step == 4
    metrics = L.Trainer(**settings).validate(module, data, verbose=False)[0]
    assert metrics["val/queries"] == 64  # 70 held-out clips -> one full group of 64
    assert 0.0 <= metrics["val/R@1"] <= metrics["val/R@5"] <= metrics["val/R@10"] <= 1.0
    assert 1.0 <= metrics["val/MeanR"] <= 64.0

    path = tmp_path / "cclip.ckpt"
    trainer.save_checkpoint(path)
    reloaded = CCLIP.load_from_checkpoint(path).eval()
    module.eval()
    clips = torch.randint(0, 256, (2, 6, 144, 144, 3), dtype=torch.uint8)
    with torch.no_grad():
        expected = module.model.encode_video(clips)
        torch.testing.assert_close(reloaded.model.encode_video(clips), expected)
        torch.testing.assert_close(
            reloaded.model.encode_text(["kill cow"]), module.model.encode_text(["kill cow"])
        )
    assert reloaded.config == module.config
    plain = load_model(path, "cclip")  # the Lightning-free loader of zoo.captions.query
    with torch.no_grad():
        torch.testing.assert_close(plain.encode_video(clips), module.model.encode_video(clips))


def test_checkpoints_without_retrieval_metric_states_still_load(tmp_path):
    # What CCLIP saved before the retrieval metric existed: the model's weights and nothing else.
    model = smoke_module().model
    path = tmp_path / "old.ckpt"
    torch.save({
        "pytorch-lightning_version": L.__version__, "hyper_parameters": {"model": "smoke"},
        "state_dict": {f"model.{k}": v for k, v in model.state_dict().items()},
    }, path)  # fmt: skip
    module = CCLIP.load_from_checkpoint(path)
    # torchmetrics forgives missing metric keys on load; this keeps new checkpoints like old ones
    assert not [key for key in module.state_dict() if not key.startswith("model.")]
    torch.testing.assert_close(module.model.state_dict(), model.state_dict())


def test_smoke_config_runs_through_the_lightning_cli(caption_root, tmp_path):
    from lit_models.cli import run_lightning_cli

    # W&B is checked once, in tests/test_lightning_cli.py; the fake set has no val split
    cli = run_lightning_cli(
        [
            "fit", "--config", str(REPO / "configs" / "cclip_smoke.yaml"),
            "--trainer.max_steps=2", "--trainer.val_check_interval=2",
            "--trainer.limit_val_batches=1", f"--trainer.default_root_dir={tmp_path}",
            "--trainer.enable_progress_bar=false", "--trainer.logger=false",
            f"--data.init_args.root={caption_root}", "--data.init_args.num_workers=0",
            "--data.init_args.batch_size=4", "--data.init_args.val_split=test",
        ]
    )  # fmt: skip
    assert isinstance(cli.model, CCLIP) and cli.trainer.global_step == 2
    assert "val/R@1" in cli.trainer.callback_metrics
    (run_dir,) = [p for p in tmp_path.iterdir() if (p / "config.yaml").exists()]
    assert list((run_dir / "checkpoints").glob("*.ckpt"))

    # zoo predict: the held-out clips' embeddings, matching the model and the clips' captions
    last = run_dir / "checkpoints" / "last.ckpt"
    predicted = run_lightning_cli(
        [
            "predict", "--config", str(REPO / "configs" / "cclip_smoke.yaml"),
            f"--trainer.default_root_dir={tmp_path / 'predict'}",
            "--trainer.enable_progress_bar=false", f"--data.init_args.root={caption_root}",
            "--data.init_args.num_workers=0", "--data.init_args.eval_batch_size=4",
            f"--ckpt_path={last}",
        ]
    )  # fmt: skip
    files = sorted(Path(predicted.trainer.default_root_dir, "predictions").glob("*.npz"))
    first_batch = next(iter(predicted.datamodule.predict_dataloader()))
    with np.load(files[0], allow_pickle=False) as pred:
        assert pred["video_embedding"].shape == (4, predicted.model.config.embed_dim)
        np.testing.assert_allclose(np.linalg.norm(pred["video_embedding"], axis=-1), 1.0, rtol=1e-5)
        assert np.array_equal(pred["caption_id"], first_batch["caption_id"].numpy())
        with torch.no_grad():
            expected = predicted.model.model.encode_video(first_batch["frames"]).numpy()
        np.testing.assert_allclose(pred["video_embedding"], expected, rtol=1e-4, atol=1e-5)


def test_validation_logs_example_clips_with_their_top_captions_to_wandb(
    caption_root, tmp_path, monkeypatch
):
    from lightning.pytorch.loggers import WandbLogger

    monkeypatch.setenv("WANDB_SILENT", "true")
    module = smoke_module(example_clips=3)
    data = CrafterCaptionDataModule(
        str(caption_root), batch_size=8, eval_batch_size=35, num_workers=0, val_split="test",
    )  # fmt: skip
    logger = WandbLogger(project="crafter-zoo", save_dir=str(tmp_path), offline=True)
    logged = []
    monkeypatch.setattr(type(logger.experiment), "log", lambda self, data, **kw: logged.append(data))
    L.Trainer(accelerator="cpu", logger=logger, enable_progress_bar=False,
              enable_model_summary=False, default_root_dir=tmp_path).validate(module, data)
    (table,) = [d["val/examples"] for d in logged if "val/examples" in d]
    assert table.columns == ["clip", "caption", "top-1", "top-2", "top-3"]
    assert len(table.data) == 3
    texts = load_vocabulary().texts()
    assert all(row[1] in texts and set(row[2:]) <= set(texts) for row in table.data)
    logger.experiment.finish()
