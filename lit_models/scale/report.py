"""`zoo scale`'s run: measure each stage, project it, write DIR/scale.json and DIR/scale.md.

scale.json holds every number with its kind (``measured`` on this CPU, ``assumptions``,
``projected`` from both); scale.md is the same for reading, summary first.
"""

from __future__ import annotations

import json
import platform
import sys
import time
from collections.abc import Sequence
from pathlib import Path

import torch

from lit_models.scale import project as proj
from lit_models.scale.measure import measure_torch_stage
from lit_models.scale.stages import QUICK_STAGES, STAGES, load_stage


def measure_stage(name: str, configs: Path, rates: dict, quick: bool) -> dict:
    """One stage's entry of scale.json: its config facts, measurement and projection."""
    stage = load_stage(name, configs)
    start = time.perf_counter()
    if stage.kind == "ppo":
        from lit_models.scale.ppo import measure_ppo  # JAX, imported when the stage is asked for

        measured = measure_ppo(stage)
    else:
        measured = measure_torch_stage(stage, warmup=0 if quick else 1)
    return {
        "config": str(stage.path), "unit": stage.unit, "kind": stage.kind,
        "per_device_batch": stage.per_device_batch, "units_per_sample": stage.units_per_sample,
        "devices": stage.devices, "precision": stage.precision, "max_steps": stage.max_steps,
        "measured": measured.to_dict(),
        "projected": proj.project(stage, measured, rates),
        "seconds": time.perf_counter() - start,
    }  # fmt: skip


def scale(out: Path, configs: Path, names: Sequence[str] | None, bench: Path, quick: bool) -> dict:
    """Measure and project ``names`` (None: every stage, or QUICK_STAGES with ``quick``)."""
    start = time.perf_counter()
    names = list(names or (QUICK_STAGES if quick else STAGES))
    rates = proj.load_rates(bench)
    result: dict = {
        "meta": {"command": "zoo scale", "date": time.strftime("%Y-%m-%d %H:%M"),
                 "machine": platform.processor() or platform.machine(),
                 "torch": torch.__version__, "torch_threads": torch.get_num_threads(),
                 "quick": quick},
        "assumptions": proj.assumptions(),
        "measured": {"loader_rates": rates},
        "stages": {},
        "disk": proj.disk(rates),
    }  # fmt: skip
    for name in names:
        print(f"zoo scale: {name} ...", file=sys.stderr, flush=True)
        result["stages"][name] = measure_stage(name, configs, rates, quick)
    result["meta"]["seconds"] = time.perf_counter() - start
    out.mkdir(parents=True, exist_ok=True)
    (out / "scale.json").write_text(json.dumps(result, indent=1) + "\n")
    (out / "scale.md").write_text(markdown(result))
    return result


def _table(header: Sequence[str], rows: list[Sequence[str]]) -> list[str]:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    return lines + ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]


def _m(n: float) -> str:
    return f"{n / 1e6:.1f}M" if n >= 1e5 else f"{n / 1e3:.0f}k" if n else "0"


def _h(hours: float) -> str:
    return f"{hours:.1f}" if hours >= 1 else f"{hours:.2g}"


def _fits(fit: dict) -> str:
    if fit["fits"]:
        return "yes"
    if fit.get("micro_batch"):
        return f"no (micro-batch {fit['micro_batch']} x {fit['accumulation_steps']})"
    return "no"


def summary(result: dict) -> list[str]:
    """One row per stage: size, FLOPs, memory, fit, projected and reported hours."""
    rows = []
    for name, s in result["stages"].items():
        m, p = s["measured"], s["projected"]
        paper = p["paper"]
        if paper:
            hours = paper["projected_hours"]
            on = f"{_h(hours['30%'])} / {_h(hours['15%'])} on {paper['gpus']}"
            if paper["units"] != p["total_units"]:
                on += f" for the paper's {paper['units']:.3g} {s['unit']}s"
            reported = f"{paper['paper_hours']:g} h ({paper['paper_over_projected']:.1f}x)"
        else:
            hours = p["gpu_hours"]["rtx4090"]
            on, reported = f"{_h(hours['30%'])} / {_h(hours['15%'])} on 1x RTX 4090", "—"
        rows.append([
            name, f"{_m(m['params_trainable'])} / {_m(m['params_frozen'])}",
            f"{m['flops_per_unit'] / 1e9:.3g} per {s['unit']}",
            f"{p['total_units']:.3g} {s['unit']}s", f"{s['per_device_batch']}",
            f"{p['memory_at_batch']['total_gib']:.1f}",
            " / ".join(_fits(p["fit"][g]) for g in proj.GPUS), on, reported,
        ])  # fmt: skip
    header = ["stage", "params trainable / frozen", "fwd+bwd GFLOPs", "total work",
              "batch / device", "memory / device (GiB, est.)", "fits 4090 / A6000 / H100",
              "projected h (30% / 15% MFU)", "paper (paper / projected)"]  # fmt: skip
    return _table(header, rows)


def measured_section(result: dict) -> list[str]:
    rows = []
    for name, s in result["stages"].items():
        m, check = s["measured"], s["projected"]["cpu_check"]
        act = " / ".join(f"{v / 1e6:,.1f} @{b}" for b, v in m["activation_bytes"].items())
        rows.append([name, m["flops_batch"], act, f"{m['cpu_step_s']:.3f} @{m['cpu_step_batch']}",
                     f"{check['achieved_flops'] / 1e9:.1f}", f"{m['cpu_peak_flops'] / 1e9:.0f}",
                     f"{check['fraction_of_peak']:.0%}", f"{s['seconds']:.0f}"])  # fmt: skip
    header = ["stage", "FLOPs counted at batch", "activations MB @batch", "CPU step s @batch",
              "step GFLOP/s", "CPU peak GFLOP/s", "step / peak", "measure s"]  # fmt: skip
    return [f"The CPU step is fp32 forward, backward, clip and AdamW "
            f"({result['meta']['torch_threads']} torch threads); the CPU peak is the best fp32 "
            "2048x2048 matmul measured right after it, since the machine may be shared. The "
            "step's share of the peak checks the FLOP model: above 100% would mean FLOPs counted "
            "that were not done, a share near 100% bounds what the counter misses, and a small "
            "share is a step bound by overheads or memory traffic (or elementwise work, which "
            "is not counted).", "", *_table(header, rows)]  # fmt: skip


def memory_section(result: dict) -> list[str]:
    rows = []
    for name, s in result["stages"].items():
        mem, fits = s["projected"]["memory_at_batch"], s["projected"]["fit"]
        advice = []
        for fit in fits.values():
            if fit["fits"]:
                continue
            cut = fit.get("activation_cut_needed")
            micro = (f"micro-batch {fit['micro_batch']} x {fit['accumulation_steps']} accumulation"
                     if fit.get("micro_batch") else "no micro-batch fits")  # fmt: skip
            advice.append(f"{fit['gpu']}: {micro}" + (f", or checkpointing that cuts activations "
                                                       f"{cut:.1f}x" if cut else ""))  # fmt: skip
        rows.append([name, s["measured"]["memory_batch"], f"{mem['weights_grads_adamw']:.2f}",
                     f"{mem['activations']:.2f}", f"{mem['inputs'] + mem['fixed_buffers']:.2f}",
                     f"{mem['total_gib']:.1f}", "; ".join(advice) or "fits all three"])  # fmt: skip
    a = result["assumptions"]
    header = ["stage", "batch / device", "weights+grads+AdamW GiB", "activations GiB",
              "inputs+buffers GiB", "estimate GiB", "when it does not fit"]  # fmt: skip
    return [f"Estimates: (parts) x {a['memory_margin']} margin + {a['cuda_context_gib']} GiB CUDA "
            "context; allocator caching, fragmentation and cuDNN workspaces are not modelled "
            "beyond that margin. Activations are the bytes saved for backward at two measured "
            "batches, extrapolated linearly; weights fp32 (bf16-mixed keeps fp32 master weights), "
            "gradients and AdamW moments fp32 for the trainable ones; inputs are the batch on "
            "the device (a sequence model holds the whole sequence while it steps per window).",
            "", *_table(header, rows)]  # fmt: skip


def time_section(result: dict) -> list[str]:
    gpus = result["assumptions"]["gpus"]
    header = ["stage", "total PFLOPs", *(f"{g['name']} GPU-h" for g in gpus.values())]
    rows, comments = [], []
    for name, s in result["stages"].items():
        p = s["projected"]
        rows.append([name, f"{p['total_flops'] / 1e15:,.3g}",
                     *(f"{_h(h['30%'])} / {_h(h['15%'])}" for h in p["gpu_hours"].values())])
        if p["paper"] and "comment" in p["paper"]:
            comments.append(f"- **{name}**: {p['paper']['comment']}.")
    return ["GPU-hours = total FLOPs / (bf16 dense peak x MFU), at 30% / 15% MFU; divide by the "
            "GPU count for wall hours.", "", *_table(header, rows), "", *comments]  # fmt: skip


def loading_section(result: dict) -> list[str]:
    rows, sources = [], set()
    for name, s in result["stages"].items():
        load = s["projected"]["loading"]
        if load is None:
            continue
        for pace, rate in load["units_per_s_per_gpu"].items():
            workers = [str(load["workers_per_gpu"].get(m, {}).get(pace, "—"))
                       for m in ("stored", "rendered")]  # fmt: skip
            rows.append([name, pace, f"{rate:,.0f} {s['unit']}s/s", *workers])
        sources.update(load.get("sources", {}).values())
    return ["Workers per GPU = units/s x decoded per trained (CrafterPlay's noop filter: "
            f"{result['assumptions']['decoded_per_trained_frame']:.2f}) / measured decode rate "
            "of one loader process on this machine. Sources: " + "; ".join(sorted(sources)) + ".",
            "", *_table(["stage", "pace", "per GPU", "workers stored", "workers rendered"], rows)]


def disk_section(result: dict) -> list[str]:
    frames = result["assumptions"]["paper_frames"]
    rows = [[mode, f"{d['bytes_per_frame']:,.0f}", f"{d['total_gb']:,.0f} GB", d["source"]]
            for mode, d in result["disk"].items()]  # fmt: skip
    return [f"The paper's {frames / 1e6:.0f}M CrafterPlay frames (measured bytes per frame of "
            "whole shards: frames, actions, states).", "",
            *_table(["mode", "B/frame", "disk", "source"], rows)]  # fmt: skip


def markdown(result: dict) -> str:
    meta, a = result["meta"], result["assumptions"]
    peaks = "; ".join(f"{g['name']} {g['bf16_dense_tflops']:g} TFLOP/s, {g['memory_gib']:g} GiB "
                      f"({g['source']})" for g in a["gpus"].values())  # fmt: skip
    notes = [f"- **{name}**: " + "; ".join(s["measured"]["notes"])
             for name, s in result["stages"].items()]  # fmt: skip
    lines = [
        "# What the paper's scale will cost: a projection", "",
        f"`zoo scale` on {meta['machine']}, {meta['date']}, torch {meta['torch']}, "
        f"{meta['seconds']:.0f} s{' (--quick)' if meta['quick'] else ''}. These are "
        "**projections**: FLOPs, activation bytes and CPU step times are measured here; GPU "
        "peaks, MFU and the memory margin are assumed; nothing ran on a GPU "
        "(bench/bench_gpu.py measures that).", "",
        "## Summary", "", *summary(result), "",
        "## Assumed", "",
        f"- GPU peaks (bf16 dense, FP32 accumulate): {peaks}.",
        f"- MFU {' and '.join(f'{x:.0%}' for x in a['mfu'])}; memory margin "
        f"{a['memory_margin']}x + {a['cuda_context_gib']} GiB context.",
        f"- CrafterPlay {a['paper_frames'] / 1e6:.0f}M frames; "
        f"{a['decoded_per_trained_frame']:.2f} frames decoded per frame trained (noop filter).",
        "", "## Measured on this CPU", "", *measured_section(result), "",
        "## Memory per device (estimate)", "", *memory_section(result), "",
        "## Time (projected)", "", *time_section(result), "",
        "## Data loading (projected)", "", *loading_section(result), "",
        "## Disk", "", *disk_section(result), "",
        "## Notes", "", *notes, "",
    ]  # fmt: skip
    return "\n".join(lines)


__all__ = ["markdown", "measure_stage", "scale"]
