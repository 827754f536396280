"""CVAE prior: shapes, the KL term against its closed form, overfitting, seeded sampling, reload."""

import math

import pytest
import torch
from torch.distributions import Normal, kl_divergence

from zoo.models.prior import CVAEPrior, PriorConfig, gaussian_kl
from zoo.weights import load_model

CONFIG = PriorConfig(embed_dim=16, hidden=32, latent_dim=4)


def unit_rows(rows: int, dim: int, seed: int) -> torch.Tensor:
    generator = torch.Generator().manual_seed(seed)
    return torch.nn.functional.normalize(torch.randn(rows, dim, generator=generator), dim=-1)


def test_shapes():
    torch.manual_seed(0)
    model = CVAEPrior(CONFIG)
    z_v, z_t = unit_rows(5, 16, 0), unit_rows(5, 16, 1)
    recon, mu, logvar = model(z_v, z_t)
    assert recon.shape == (5, 16) and mu.shape == logvar.shape == (5, 4)
    assert model.sample(z_t).shape == (5, 16)
    assert set(model.loss(z_v, recon, mu, logvar)) == {"loss", "recon", "kl"}


def test_kl_matches_the_closed_form_on_hand_values():
    mu = torch.tensor([[1.0, 0.0]])
    logvar = torch.tensor([[0.0, math.log(2.0)]])
    # 0.5 * (mu^2 + sigma^2 - 1 - log sigma^2) per dimension: 0.5 * 1 + 0.5 * (2 - 1 - log 2)
    expected = 0.5 + 0.5 * (1.0 - math.log(2.0))
    torch.testing.assert_close(gaussian_kl(mu, logvar), torch.tensor([expected]))
    reference = kl_divergence(Normal(mu, (0.5 * logvar).exp()), Normal(0.0, 1.0)).sum(-1)
    torch.testing.assert_close(gaussian_kl(mu, logvar), reference)


def test_loss_is_summed_squared_error_plus_weighted_kl():
    model = CVAEPrior(PriorConfig(embed_dim=2, hidden=4, latent_dim=2, kl_weight=0.5))
    z_v, recon = torch.zeros(2, 2), torch.ones(2, 2)
    mu, logvar = torch.tensor([[1.0, 0.0], [1.0, 0.0]]), torch.zeros(2, 2)
    losses = model.loss(z_v, recon, mu, logvar)
    assert losses["recon"].item() == 2.0 and losses["kl"].item() == 0.5
    assert losses["loss"].item() == 2.0 + 0.5 * 0.5


@pytest.fixture
def one_thread():
    """Tiny matrices: more intra-op threads only add synchronisation (10x slower on a busy
    2-core machine)."""
    before = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(before)


def test_overfits_eight_pairs(one_thread):
    """Random unit targets: predicting their mean leaves a squared error of ~1 - 1/8 per pair,
    so below 0.02 the decoder has memorised each z_t -> z_v (the KL, weight 1, stays on)."""
    torch.manual_seed(0)
    model = CVAEPrior(CONFIG)
    z_v, z_t = unit_rows(8, 16, 0), unit_rows(8, 16, 1)
    optimizer = torch.optim.Adam(model.parameters(), lr=3e-3)
    for _ in range(400):
        losses = model.loss(z_v, *model(z_v, z_t))
        optimizer.zero_grad()
        losses["loss"].backward()
        optimizer.step()
    error = (model.sample(z_t, mean=True) - z_v).pow(2).sum(-1).mean().item()
    assert error < 0.02


def test_sampling_is_a_function_of_the_generator_seed():
    torch.manual_seed(0)
    model = CVAEPrior(CONFIG)
    z_t = unit_rows(3, 16, 2)

    def draw(seed: int) -> torch.Tensor:
        return model.sample(z_t, generator=torch.Generator().manual_seed(seed))

    torch.testing.assert_close(draw(7), draw(7))
    assert not torch.allclose(draw(7), draw(8))
    torch.testing.assert_close(model.sample(z_t, mean=True), model.decode(torch.zeros(3, 4), z_t))


def test_wrong_embedding_width_and_sizes_are_named():
    model = CVAEPrior(CONFIG)
    with pytest.raises(ValueError, match=r"z_t must have shape \(batch, 16\).*got \(2, 8\)"):
        model.sample(torch.zeros(2, 8))
    with pytest.raises(ValueError, match="z_v must have shape"):
        model(torch.zeros(2, 8), torch.zeros(2, 16))
    with pytest.raises(ValueError, match="latent_dim must be >= 1"):
        PriorConfig(latent_dim=0)


def test_checkpoint_reload_gives_identical_outputs(tmp_path):
    torch.manual_seed(0)
    model = CVAEPrior(CONFIG)
    hparams = {"embed_dim": 16, "hidden": 32, "latent_dim": 4, "kl_weight": 1.0, "lr": 1e-3}
    state = {f"model.{key}": value for key, value in model.state_dict().items()}
    torch.save({"hyper_parameters": hparams, "state_dict": state}, tmp_path / "prior.ckpt")
    loaded = load_model(tmp_path / "prior.ckpt", "prior")
    assert loaded.config == CONFIG and not loaded.training
    z_t = unit_rows(4, 16, 3)
    torch.testing.assert_close(loaded.sample(z_t, mean=True), model.sample(z_t, mean=True))
    with pytest.raises(FileNotFoundError, match="nothing.ckpt"):
        load_model(tmp_path / "nothing.ckpt", "prior")
    torch.save({"state_dict": {}}, tmp_path / "other.ckpt")
    with pytest.raises(ValueError, match="hyper_parameters"):
        load_model(tmp_path / "other.ckpt", "prior")


def test_layer_norm_follows_each_hidden_layer_and_old_configs_load_without():
    """Steve-1's prior: Linear -> LayerNorm -> ReLU twice, then Linear; a config saved before
    the option (no layer_norm key) builds the plain MLPs its weights were trained as."""
    model = CVAEPrior(PriorConfig(embed_dim=8, hidden=16, latent_dim=4, layer_norm=True))
    kinds = [type(m).__name__ for m in model.encoder]
    assert kinds == ["Linear", "LayerNorm", "ReLU", "Linear", "LayerNorm", "ReLU", "Linear"]
    plain = CVAEPrior(PriorConfig(**{"embed_dim": 8, "hidden": 16, "latent_dim": 4}))
    assert [type(m).__name__ for m in plain.decoder] == ["Linear", "ReLU", "Linear", "ReLU", "Linear"]
    assert model.num_params() - plain.num_params() == 2 * 2 * (2 * 16)  # 4 norms, weight+bias
