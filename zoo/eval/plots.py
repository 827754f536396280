"""Pictures of an evaluation: per-achievement bar plot and an episode GIF.

Plots draw on an Agg canvas directly (no pyplot), so writing a report never switches the
matplotlib backend of the process that called it (a notebook, a training loop).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np


def plot_success_rates(rates: dict[str, float], title: str, path: str | Path) -> Path:
    """Horizontal bars of success rates in percent, first achievement at the top."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    names, values = list(rates), np.array(list(rates.values()), np.float64)
    fig = Figure(figsize=(7, 0.28 * len(names) + 1.2), dpi=100)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    y = np.arange(len(names))
    ax.barh(y, values, color="tab:blue")
    for yi, value in zip(y, values):
        inside = value > 88  # no room right of the bar: write on it, in white
        ax.text(
            value - 1 if inside else value + 1, yi, f"{value:.1f}", va="center", fontsize=7,
            ha="right" if inside else "left", color="white" if inside else "black",
        )
    ax.set_yticks(y, [name.replace("_", " ") for name in names], fontsize=8)
    ax.invert_yaxis()
    ax.set_xlim(0, 100)
    ax.set_xlabel("success rate (%)")
    ax.set_title(title, fontsize=10)
    ax.grid(axis="x", alpha=0.3)
    fig.tight_layout()
    fig.savefig(path)
    return Path(path)


def write_gif(frames: np.ndarray, path: str | Path, scale: int = 2, fps: float = 15.0) -> Path:
    """Write uint8 frames (T, H, W, 3) as a looping GIF, upscaled ``scale``x nearest-neighbour."""
    import imageio.v3 as iio

    frames = np.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3 or frames.dtype != np.uint8 or len(frames) == 0:
        raise ValueError(f"frames must be uint8 (T>=1, H, W, 3), got {frames.dtype} {frames.shape}")
    if scale > 1:
        frames = frames.repeat(scale, axis=1).repeat(scale, axis=2)
    iio.imwrite(path, frames, extension=".gif", duration=1000.0 / fps, loop=0)
    return Path(path)
