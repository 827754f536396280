"""Every folder in weights/ is a verified `zoo export` with a model card that its loader reads,
and weights/ stays within the size budget (it is committed to git)."""

from __future__ import annotations

from pathlib import Path

import pytest
import torch

from zoo.agents.csteve1_agent import CSteve1Policy
from zoo.weights import inference_settings, load_model
from zoo.weights.export import CHECKSUM_FILE, exported_kind, verify_export

WEIGHTS = Path(__file__).resolve().parents[1] / "weights"
BUDGET_BYTES = 60 * 1024 * 1024
SHIPPED = sorted(p for p in WEIGHTS.iterdir() if p.is_dir())


def test_weights_folder_ships_models_within_budget() -> None:
    assert {p.name for p in SHIPPED} >= {"cclip_cpu", "prior_cpu"}
    total = sum(p.stat().st_size for p in WEIGHTS.rglob("*") if p.is_file())
    assert total <= BUDGET_BYTES, f"weights/ holds {total / 2**20:.1f} MiB, budget 60 MiB"


@pytest.mark.parametrize("folder", SHIPPED, ids=[p.name for p in SHIPPED])
def test_shipped_folder_verifies_and_loads(folder: Path) -> None:
    card = folder / "MODEL_CARD.md"
    assert card.is_file() and card.read_text().startswith("# "), f"{card} missing or untitled"
    verify_export(folder)  # every file in sha256.txt matches
    listed = {line.split()[1] for line in (folder / CHECKSUM_FILE).read_text().splitlines()}
    assert listed == {"model.safetensors", "config.json"}
    model = load_model(folder, exported_kind(folder))  # the loader weights/README.md documents
    assert not model.training
    floats = {v.dtype for v in model.state_dict().values() if v.is_floating_point()}
    assert floats == {torch.float32}  # half-precision files load as float32


def test_shipped_c_steve_1_plays_at_the_scale_its_card_measured() -> None:
    """Its card's tables are at guidance 1 and temperature 1; config.json records both, so
    loading without arguments plays as measured (the paper's 1.5 is for exports without it)."""
    folder = WEIGHTS / "csteve1_cpu"
    assert inference_settings(folder, "csteve1") == {"cfg_scale": 1.0, "temperature": 1.0}
    policy = CSteve1Policy.load(folder)
    assert (policy.cfg_scale, policy.temperature, policy.greedy) == (1.0, 1.0, False)
