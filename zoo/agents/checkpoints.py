"""Which trained agent a checkpoint path holds, from its layout alone (no weights are built)."""

from __future__ import annotations

from pathlib import Path


def is_rl_run(path: Path) -> bool:
    """A ``zoo rl train`` run folder (config.yaml + checkpoints/update_*.pt) or one checkpoint."""
    if path.is_dir():
        return (path / "config.yaml").is_file() and any((path / "checkpoints").glob("update_*.pt"))
    return path.is_file() and path.suffix == ".pt" and path.name.startswith("update_")


def checkpoint_kind(path: str | Path) -> str:
    """Which trained agent a checkpoint holds, from its layout alone.

    A PPO run or checkpoint folder has ``meta.json`` files; a ``zoo export`` folder has
    ``model.safetensors`` or ``sha256.txt`` and names its kind in ``config.json`` (C-VPT or
    C-Steve-1 play; C-CLIP and the prior do not); a Lightning ``.ckpt`` file is a C-Steve-1 run
    when its hyper-parameters name a backbone, otherwise a C-VPT run; a ``zoo rl train`` run folder
    (config.yaml, checkpoints/update_*.pt) or one of its ``update_*.pt`` is an RL agent.
    """
    path = Path(path)
    if is_rl_run(path):
        return "rl"
    if path.is_file() and path.suffix == ".ckpt":
        from zoo.agents.csteve1_agent import is_csteve1_checkpoint
        from zoo.weights.checkpoint_io import read_torch_file

        return "csteve1" if is_csteve1_checkpoint(read_torch_file(path)) else "cvpt"
    if path.is_dir():
        if (path / "model.safetensors").is_file() or (path / "sha256.txt").is_file():
            from zoo.weights.export import exported_kind
            from zoo.weights.kinds import KINDS

            kind = exported_kind(path)
            if kind not in ("cvpt", "csteve1"):
                raise ValueError(
                    f"{path} is a {KINDS[kind].title} export, not an agent: expected a C-VPT "
                    "or C-Steve-1 export"
                )
            return kind
        if (path / "meta.json").is_file() or any(path.glob("update_*/meta.json")):
            return "ppo"
    raise ValueError(
        f"cannot tell what {path} holds: expected a C-VPT/C-Steve-1 .ckpt, a `zoo export` folder "
        "(model.safetensors), a PPO checkpoint/run folder (meta.json) or a `zoo rl train` run "
        "(config.yaml + checkpoints/update_*.pt); pass --agent"
    )
