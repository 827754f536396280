"""`zoo scale` and bench/bench_gpu.py: the counting, the memory model and both commands end to end.

The hand values pin the measurement conventions: a linear layer's forward and backward cost
3 x 2 x in x out FLOPs per sample, attention 3 x its two matmuls over every key (TrXL memory
included) on either CPU kernel, autograd's saved tensors are the activations (parameters apart,
a storage counted once), a C-VPT's FLOPs are per frame of its TBPTT window, AdamW costs 12 bytes
per trainable parameter beside the weights, and memory and GPU-hours are the stated arithmetic.
"""

from __future__ import annotations

import json
import runpy
from pathlib import Path

import pytest
import torch
import yaml
from torch import nn

from torch.utils.flop_counter import FlopCounterMode

from lit_models.scale import measure, project
from lit_models.scale.measure import Measurement, count
from lit_models.scale.ppo import jaxpr_flops
from lit_models.scale.stages import load_stage
from zoo.cli import main
from zoo.models.trxl import TransformerXL

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


@pytest.mark.parametrize("bias_trains", [True, False], ids=["math-kernel", "flash-kernel"])
def test_trxl_attention_flops_count_the_memory_keys(bias_trains: bool) -> None:
    """One TrXL layer, d_model 16, d_ff 32, 2 heads, a window of T = 8 steps over a memory of
    M = 8: its keys are the S = M + T = 16 rows of [memory, window]. Forward FLOPs, 2 x rows x
    in x out per linear layer, 2 x T x S x d per attention matmul (summed over the heads):
    query 2*8*16*16 = 4,096; key_value 2*16*16*32 = 16,384 (over all S rows); QK^T and AV
    2 * 2*8*16*16 = 8,192; out 4,096; feed-forward 2 * 2*8*16*32 = 16,384; total 49,152.
    Backward is twice that (the input's and the weight's gradient; for attention the scores', V's,
    Q's and K's): 3 x 49,152 = 147,456. With the relative bias trained the mask needs a gradient
    and SDPA takes its math path (bmm, which torch counts); frozen (C-Steve-1's base) it takes the
    CPU flash kernel, which torch's counter alone misses (3 x 8,192 short): the count must not
    depend on the kernel."""
    torch.manual_seed(0)
    trxl = TransformerXL(d_model=16, d_ff=32, n_heads=2, n_layers=1, memory_len=8)
    trxl.layers[0].attn.relative_bias.requires_grad_(bias_trains)
    x = torch.randn(1, 8, 16, requires_grad=True)  # the encoder's output: it needs a gradient

    def run() -> torch.Tensor:
        return trxl(x, torch.zeros(1, 8, dtype=torch.bool), trxl.initial_state(1))[0].sum()

    flops, _ = count(run, trxl.parameters(), mixed=False, flops=True)
    assert flops == 3 * (4096 + 16384 + 8192 + 4096 + 16384) == 147456
    with FlopCounterMode(display=False) as torch_alone:
        run().backward()
    assert torch_alone.get_total_flops() == (147456 if bias_trains else 147456 - 3 * 8192)


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


def test_memory_parts_by_hand() -> None:
    """1,000 trainable and 500 frozen parameters at batch 4: weights 4 B x 1,500 = 6,000 (fp32,
    bf16-mixed's master copy is the parameter itself), gradients and AdamW's two moments 12 B x
    1,000 = 12,000 (frozen ones have neither); activations on the line through (1, 3,000) and
    (2, 5,000): 9,000; inputs 100 B x 4 = 400; fixed buffers 600. Sum 28,000 B, x 1.2 margin
    = 33,600 B, plus 1 GiB of CUDA context."""
    m = _measurement(params_trainable=1000, params_frozen=500,
                     activation_bytes={1: 3000.0, 2: 5000.0}, extra_bytes_per_sample=100.0,
                     extra_bytes_fixed=600.0)  # fmt: skip
    parts = project.memory(m, 4)
    gib = project.GIB
    assert parts["weights_grads_adamw"] * gib == pytest.approx(6000 + 12000)
    assert parts["activations"] * gib == pytest.approx(9000)
    assert parts["inputs"] * gib == pytest.approx(400)
    assert parts["fixed_buffers"] * gib == pytest.approx(600)
    assert parts["total_gib"] == pytest.approx(33600 / gib + 1)


def test_adamw_state_is_12_bytes_per_trainable_parameter() -> None:
    """What AdamW really allocates, against the 4 B per parameter + 12 B per trainable one the
    estimate counts: Linear(4, 8) frozen (40 parameters), Linear(8, 2) trained (18). After a
    step: fp32 weights 4 x 58 = 232 B, fp32 gradients 4 x 18 = 72 B, exp_avg and exp_avg_sq
    2 x 4 x 18 = 144 B: 448 = 4 x 58 + 12 x 18. The 12 are gradient + two moments; there is no
    separate master copy (bf16-mixed autocasts fp32 parameters; its bf16 copies are measured
    with the activations). AdamW's per-tensor ``step`` counter (a scalar) is left out."""
    net = nn.Sequential(nn.Linear(4, 8), nn.Linear(8, 2))
    net[0].requires_grad_(False)
    optimizer = measure.trainable_optimizer(net)
    net(torch.randn(3, 4)).sum().backward()
    optimizer.step()
    tensors = [*net.parameters(), *(p.grad for p in net.parameters() if p.grad is not None)]
    tensors += [v for state in optimizer.state.values() for k, v in state.items() if k != "step"]
    allocated = sum(t.numel() * t.element_size() for t in tensors)
    assert allocated == 4 * 58 + 12 * 18 == 448
    m = _measurement(params_trainable=18, params_frozen=40)
    assert project.memory(m, 1)["weights_grads_adamw"] * project.GIB == pytest.approx(allocated)


# C-VPT small enough to count by hand: one IMPALA stage of 2 channels on 144 px frames pooled
# 36x to 4 px, one TrXL layer; 10 steps of 3 sequences on 2 devices, 8-frame windows
TINY_CVPT = {
    "trainer": {"devices": 2, "precision": "bf16-mixed", "max_steps": 10},
    "model": {"class_path": "lit_models.cvpt.CVPT", "init_args": {
        "model": "tiny", "d_model": 16, "d_ff": 32, "n_heads": 2, "n_layers": 1,
        "impala_channels": [2], "encoder_hidden": 8, "memory_len": 8, "input_downsample": 36,
        "tbptt_len": 8, "max_grad_norm": 5.0}},
    "data": {"init_args": {"seq_len": 16, "batch_size": 3}},
}  # fmt: skip


@pytest.fixture
def tiny_configs(tmp_path: Path) -> Path:
    """A configs folder whose cvpt_tiny.yaml is TINY_CVPT."""
    (tmp_path / "cvpt_tiny.yaml").write_text(yaml.safe_dump(TINY_CVPT))
    return tmp_path


def test_tiny_cvpt_flops_per_frame_by_hand(tiny_configs: Path, monkeypatch) -> None:
    """Forward FLOPs per frame (2 x out x in per linear, 2 x out pixels x in channels x 9 per
    3x3 conv; a window of T = 8 frames over M = 8 memory steps, d 16):
    IMPALA conv 3->2 at 4x4 px 2*16*2*27 = 1,728, its backward only the weight gradient (frames
    need none): 2 x 1,728 = 3,456; 4 residual convs 2->2 at 2x2 px 2*4*2*18 = 288 each, 3x:
    3,456; dense 8->8 128, 3x: 384; 8->16 256, 3x: 768; TrXL query 512, 3x: 1,536; key_value on
    (M + T) / T = 2 rows per frame 2*2*16*32 = 2,048, 3x: 6,144; attention over 16 keys
    2 * 2*16*16 = 1,024, 3x: 3,072; out 1,536; feed-forward 2,048, 3x: 6,144; policy head 16->17
    544, 3x: 1,632. Total 28,128 per frame, 8 x 28,128 = 225,024 per sequence (one window).
    The timed step ran at the per-device batch of 3: 3 x 225,024 FLOPs. The CPU peak and the
    step's repeats are patched out: timing is not what is checked."""
    monkeypatch.setattr(measure, "cpu_peak_flops", lambda: 1e11)
    monkeypatch.setattr(measure, "MIN_TIMED_S", 0.0)
    m = measure.measure_torch_stage(load_stage("cvpt_tiny", tiny_configs), warmup=0)
    assert m.flops_per_unit == 3456 + 3456 + 384 + 768 + 1536 + 6144 + 3072 + 1536 + 6144 + 1632
    assert m.flops_per_unit == 28128
    assert (m.cpu_step_batch, m.cpu_step_flops) == (3, 3 * 8 * 28128)


def test_gpu_hours_of_a_tiny_stage_by_hand(tiny_configs: Path) -> None:
    """TINY_CVPT's run: 10 steps x 3 sequences x 2 devices x 8-frame windows = 480 frames. At
    165.2e12 x 0.3 x 3,600 x 4 / 480 FLOPs per frame the run is 4 RTX 4090-hours at 30% MFU
    (8 at 15%), 1 wall hour on the paper's 4 for cvpt_tiny, whose 7 h are then 7x the projection
    at an implied MFU of 0.3 / 7; an H100 takes 4 x 165.2 / 989.4 hours at 30%."""
    stage = load_stage("cvpt_tiny", tiny_configs)
    assert stage.total_units == 480
    p = project.project(stage, _measurement(flops_per_unit=165.2e12 * 0.3 * 3600 * 4 / 480), {})
    assert p["total_flops"] == pytest.approx(165.2e12 * 0.3 * 3600 * 4)
    assert p["gpu_hours"]["rtx4090"] == pytest.approx({"30%": 4.0, "15%": 8.0})
    assert p["gpu_hours"]["h100"]["30%"] == pytest.approx(4 * 165.2 / 989.4)
    paper = p["paper"]
    assert paper["projected_hours"] == pytest.approx({"30%": 1.0, "15%": 2.0})
    assert paper["paper_over_projected"] == pytest.approx(7.0)
    assert paper["implied_mfu"] == pytest.approx(0.3 / 7)


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
