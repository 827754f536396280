"""`zoo data info`: what a CrafterPlay folder holds, and whether its shards are intact.

Counts and statistics come from the manifest (written from the data as it was generated);
every shard is re-hashed against its recorded sha256 and its tar headers are scanned for
the bytes each kind of member takes, so the check costs one read of the data.
"""

from __future__ import annotations

import tarfile
from dataclasses import dataclass, field
from pathlib import Path

from zoo.data.manifest import MANIFEST, load_manifest
from zoo.data.shards import FRAMES, RENDER, RESIDUAL
from zoo.envs.constants import ACHIEVEMENT_NAMES
from zoo.envs.schema import FRAME_SHAPE
from zoo.experts.scripted.schedule import OUTCOMES, add_tallies
from zoo.files import sha256_file

RAW_FRAME_BYTES = int(FRAME_SHAPE[0] * FRAME_SHAPE[1] * FRAME_SHAPE[2])


@dataclass
class ShardCheck:
    """Result of verifying shards against the manifest."""

    good: list[dict] = field(default_factory=list)
    bad: list[tuple[str, str]] = field(default_factory=list)  # (file, why)


def check_shards(root: Path, manifest: dict) -> ShardCheck:
    """Re-hash every shard listed in the manifest."""
    result = ShardCheck()
    for entry in manifest["shards"]:
        path = root / entry["file"]
        if not path.exists():
            result.bad.append((str(path), "missing"))
        elif (digest := sha256_file(path)) != entry["sha256"]:
            why = f"sha256 {digest[:12]}... != manifest {entry['sha256'][:12]}..."
            result.bad.append((str(path), why))
        else:
            result.good.append(entry)
    return result


FRAME_MEMBERS = tuple("." + name for name in (FRAMES, RESIDUAL, RENDER))


def _frame_bytes(path: Path) -> int:
    """Bytes of the members that code frames, in either mode (from tar headers only)."""
    with tarfile.open(path) as tar:
        return sum(m.size for m in tar.getmembers() if m.name.endswith(FRAME_MEMBERS))


def dataset_info(root: str | Path, skip_corrupt: bool = False) -> dict:
    """Summary of a CrafterPlay folder; ``ok`` is False when a shard fails its checksum
    (unless ``skip_corrupt``, which reports such shards and sums over the others)."""
    root = Path(root)
    manifest = load_manifest(root)
    if manifest is None:
        raise FileNotFoundError(f"{root / MANIFEST} not found: not a CrafterPlay folder")
    check = check_shards(root, manifest)
    shards = check.good if skip_corrupt else manifest["shards"]
    episodes = sum(e["episodes"] for e in shards)
    frames = sum(e["steps"] for e in shards)
    counts = ("steps", "noop_steps", "kept_steps", "kept_noop_steps")
    noop = {k: sum(e["noop"][k] for e in shards) for k in counts}
    unlocks = {k: sum(e["achievement_unlocks"][k] for e in shards) for k in ACHIEVEMENT_NAMES}
    shard_bytes = sum(e["bytes"] for e in shards)
    frame_bytes = sum(_frame_bytes(root / e["file"]) for e in check.good)
    tallies = [e["instructions"] for e in shards if "instructions" in e]
    return {
        "root": str(root),
        "ok": not check.bad or skip_corrupt,
        "config": manifest["config"],
        "frames_mode": manifest["config"]["frames"],
        "renderers": sorted({e["renderer"] for e in shards if "renderer" in e}),
        "shards": len(shards),
        "bad_shards": [{"file": f, "why": why} for f, why in check.bad],
        "skipped_shards": len(check.bad) if skip_corrupt else 0,
        "episodes": episodes,
        "steps": noop["steps"],
        "frames": frames,
        "bytes": shard_bytes,
        "bytes_per_frame": shard_bytes / max(frames, 1),
        "frame_bytes_per_frame": frame_bytes / max(frames, 1),
        "compression_ratio_frames": RAW_FRAME_BYTES * frames / max(frame_bytes, 1),
        "noop_ratio_before": noop["noop_steps"] / max(noop["steps"], 1),
        "noop_ratio_after": noop["kept_noop_steps"] / max(noop["kept_steps"], 1),
        "noop_min_run": manifest["config"].get("min_noop_run"),
        "achievement_unlock_rates": {k: v / max(episodes, 1) for k, v in unlocks.items()},
        "instructions": add_tallies(tallies) if tallies else None,
    }


def _instruction_lines(tally: dict[str, dict], timeout: int) -> list[str]:
    """Per caption of a scheduled dataset: how its instructions ended."""
    outcomes = " / ".join(OUTCOMES)
    lines = [f"instructions (timeout {timeout} actions): {outcomes}, mean actions to complete"]
    for caption, row in tally.items():
        given = sum(row[outcome] for outcome in OUTCOMES)
        shares = " ".join(f"{row[outcome] / max(given, 1):6.1%}" for outcome in OUTCOMES)
        mean = f"{row['completed_actions'] / row['completed']:6.1f}" if row["completed"] else "     -"
        lines.append(f"  {caption:22s} {shares}  {mean}  ({given} given)")
    return lines


def format_info(info: dict) -> str:
    """Human-readable report of ``dataset_info``."""
    cfg = info["config"]
    mode = "".join([info["frames_mode"], *(f"; re-rendered with {r}" for r in info["renderers"])])
    lines = [
        f"CrafterPlay {info['root']}: expert={cfg['expert']} env={cfg['env']} seed={cfg['seed']}",
        f"shards {info['shards']}  episodes {info['episodes']}  steps {info['steps']}  "
        f"frames {info['frames']}  ({mode})",
        f"bytes {info['bytes']:,}  ({info['bytes_per_frame']:.0f} B/frame in all, "
        f"{info['frame_bytes_per_frame']:.0f} B/frame for frames: "
        f"{info['compression_ratio_frames']:.1f}x smaller than raw {RAW_FRAME_BYTES:,} B)",
        f"noop ratio {info['noop_ratio_before']:.1%} before, {info['noop_ratio_after']:.1%} after "
        f"filtering runs < {info['noop_min_run']}",
    ]
    if dagger := cfg.get("dagger"):
        learner = dagger["learner"]
        lines.append(
            f"DAgger round {dagger['round']}: learner {learner['kind']} {learner['checkpoint']} "
            f"(sha256 {learner['checkpoint_sha256'][:12]}..., temperature "
            f"{learner.get('temperature', 1.0)}), expert acts with beta {dagger['beta']} per "
            f"{dagger['mix']}"
        )
    if info["instructions"]:
        lines += _instruction_lines(info["instructions"], cfg["instructions"]["timeout"])
    lines.append("achievement unlock rates:")
    rates = info["achievement_unlock_rates"]
    lines += [f"  {name:20s} {rate:6.1%}" for name, rate in rates.items()]
    for bad in info["bad_shards"]:
        verb = "skipped" if info["skipped_shards"] else "FAILED"
        lines.append(f"{verb}: {bad['file']}: {bad['why']}")
    lines.append("checksums: " + ("ok" if not info["bad_shards"] else
                                  f"{len(info['bad_shards'])} shard(s) bad"))
    return "\n".join(lines)
