"""`zoo fit` makes torch's OpenMP threads wait passively (DataLoader workers share the cores),
unless the user chose a policy."""

from __future__ import annotations

import pytest

import lit_models.cli
from zoo.cli import main


@pytest.mark.parametrize(("given", "expected"), [(None, "PASSIVE"), ("ACTIVE", "ACTIVE")])
def test_fit_sets_a_passive_omp_wait_policy_unless_one_is_set(monkeypatch, given, expected):
    seen = {}
    if given is None:
        monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    else:
        monkeypatch.setenv("OMP_WAIT_POLICY", given)
    monkeypatch.setattr(lit_models.cli, "run_lightning_cli",
                        lambda argv: seen.update(policy=__import__("os").environ["OMP_WAIT_POLICY"]))
    assert main(["fit", "--config", "configs/cvpt_smoke.yaml"]) == 0
    assert seen == {"policy": expected}
