"""`zoo scale` and bench/bench_gpu.py: the counting, the memory model and both commands end to end.

The hand values pin the measurement conventions: a linear layer's forward and backward cost
3 x 2 x in x out FLOPs per sample, autograd's saved tensors are the activations (parameters
apart, a storage counted once), and the memory estimate is a straight line in the batch.
"""

from __future__ import annotations

import json
import runpy
from pathlib import Path

import pytest
import torch
import yaml
from torch import nn

from lit_models.scale import project
from lit_models.scale.measure import Measurement, count
from lit_models.scale.ppo import jaxpr_flops
from zoo.cli import main

ROOT = Path(__file__).resolve().parents[2]


def test_linear_forward_backward_flops_are_three_matmuls() -> None:
    batch, width_in, width_out = 5, 32, 16
    layer = nn.Linear(width_in, width_out)
    x = torch.randn(batch, width_in, requires_grad=True)  # a hidden layer: input grad too
    flops, _ = count(lambda: layer(x).sum(), layer.parameters(), mixed=False, flops=True)
    assert flops == 3 * 2 * width_in * width_out * batch


def test_saved_activation_bytes_of_a_tiny_module() -> None:
    batch = 3
    net = nn.Sequential(nn.Linear(4, 8), nn.ReLU(), nn.Linear(8, 2))
    x = torch.randn(batch, 4)
    _, saved = count(lambda: net(x).sum(), net.parameters(), mixed=False, flops=False)
    # the input (for the first weight's gradient) and the ReLU output, which ReLU's backward
    # and the second linear layer both save: one storage, counted once; weights excluded
    assert saved == batch * (4 + 8) * 4


def test_jaxpr_flops_unrolls_a_scan() -> None:
    import jax
    import jax.numpy as jnp

    def run(w, xs):
        return jax.lax.scan(lambda h, x: (jnp.tanh(h @ w + x), None), xs[0], xs)[0]

    jaxpr = jax.make_jaxpr(run)(jnp.zeros((8, 8)), jnp.zeros((5, 3, 8))).jaxpr
    assert jaxpr_flops(jaxpr) == 5 * 2 * 3 * 8 * 8


def _measurement(**overrides) -> Measurement:
    values = {
        "params_trainable": 1000, "params_frozen": 500, "flops_per_unit": 1e9, "flops_batch": 1,
        "activation_bytes": {1: 3e8, 2: 5e8}, "memory_batch": 32, "extra_bytes_per_sample": 1e7,
        "extra_bytes_fixed": 0.0, "cpu_step_s": 1.0, "cpu_step_batch": 1, "cpu_step_flops": 1e10,
        "cpu_peak_flops": 1e11,
    }  # fmt: skip
    return Measurement(**{**values, **overrides})


def test_memory_is_linear_in_the_batch() -> None:
    m = _measurement()
    totals = [project.memory(m, b)["total_gib"] for b in (1, 2, 3, 32, 64)]
    step = totals[1] - totals[0]
    for b, total in zip((1, 2, 3, 32, 64), totals, strict=True):
        assert total == pytest.approx(totals[0] + step * (b - 1))
    assert project.extrapolate({1: 3e8, 2: 5e8}, 32) == pytest.approx(3e8 + 2e8 * 31)


def test_a_batch_that_does_not_fit_gets_a_micro_batch_that_does() -> None:
    m = _measurement(activation_bytes={1: 1e9, 2: 2e9})  # ~1 GB per sample: 32 need ~40 GiB
    fit = project.fit(m, project.GPUS["rtx4090"])
    assert not fit["fits"] and fit["micro_batch"] >= 1
    assert project.memory(m, fit["micro_batch"])["total_gib"] <= 24
    assert project.memory(m, fit["micro_batch"] + 1)["total_gib"] > 24
    assert fit["accumulation_steps"] * fit["micro_batch"] >= 32
    assert project.fit(m, project.GPUS["h100"])["fits"]


def test_zoo_scale_quick_writes_the_report(tmp_path: Path) -> None:
    out = tmp_path / "scale"
    argv = ["scale", "--quick", "--stages", "prior", "cvpt_tiny", "--out", str(out),
            "--configs", str(ROOT / "configs"), "--bench", str(ROOT / "bench" / "results")]
    assert main(argv) == 0
    result = json.loads((out / "scale.json").read_text())
    assert set(result) >= {"meta", "assumptions", "measured", "stages", "disk"}
    tiny = result["stages"]["cvpt_tiny"]
    assert tiny["measured"]["params_trainable"] == pytest.approx(3.2e6, rel=0.05)  # paper table
    assert tiny["measured"]["flops_per_unit"] > 0
    projected = tiny["projected"]
    assert set(projected["fit"]) == set(project.GPUS)
    assert projected["paper"]["paper_hours"] == 7.0
    config = yaml.safe_load((ROOT / "configs" / "cvpt_tiny.yaml").read_text())
    trainer, window = config["trainer"], config["model"]["init_args"]["tbptt_len"]
    per_step = config["data"]["init_args"]["batch_size"] * trainer["devices"] * window
    assert projected["total_units"] == trainer["max_steps"] * per_step  # one step per window
    assert set(projected["loading"]["workers_per_gpu"]) == {"stored", "rendered"}
    assert result["disk"]["rendered"]["total_gb"] < result["disk"]["stored"]["total_gb"]
    text = (out / "scale.md").read_text()
    for heading in ("## Summary", "## Assumed", "## Measured on this CPU", "## Memory per device",
                    "## Time (projected)", "## Data loading", "## Disk"):  # fmt: skip
        assert heading in text


def _bench_gpu(argv: list[str]) -> dict:
    return runpy.run_path(str(ROOT / "bench" / "bench_gpu.py"))["main"](argv)


def test_bench_gpu_tiny_runs(tmp_path: Path) -> None:
    out = tmp_path / "gpu.json"
    results = _bench_gpu(["--tiny", "--configs", str(ROOT / "configs"), "--out", str(out)])
    assert results["mode"] == "cpu-tiny" and json.loads(out.read_text()) == results
    for row in results["stages"]:
        assert row["synthetic"]["units_per_s"] > 0
        assert row["projection"]["memory_estimate_gib"] > 0


@pytest.mark.slow
def test_bench_gpu_tiny_times_a_real_loader(steve_play: Path, tmp_path: Path) -> None:
    results = _bench_gpu(["--tiny", "--stages", "cvpt_tiny", "--data", str(steve_play),
                          "--configs", str(ROOT / "configs"), "--out", str(tmp_path / "g.json")])
    data = results["stages"][0]["data"]
    assert data["frames"] > 0 and 0 <= data["data_wait_share"] <= 1
