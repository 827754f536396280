"""Job arrays: CrafterPlay folders of shard ranges (``generate --shards A:B``) joined into one."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from zoo.data.manifest import (
    DatasetMismatchError,
    check_same_config,
    config_diff,
    load_manifest,
    new_manifest,
    save_manifest,
)
from zoo.data.shard_generator import GenerationConfig
from zoo.files import sha256_file


def merge_datasets(sources: list[str | Path], out: str | Path) -> dict:
    """Join CrafterPlay folders of one dataset (``generate --shards A:B`` of a job array) into
    ``out``: the same generation arguments, no shard index twice, every shard's sha256
    checked. Shards are hard-linked when ``out`` is on the same filesystem, else copied; the
    sources are left as they were. Returns the merged manifest (``missing`` lists the shard
    indices no source had yet: rerun their job, then merge again)."""
    out = Path(out)
    if not sources:
        raise ValueError("nothing to merge: give the shard-range folders")
    manifests = []
    for src in map(Path, sources):
        manifest = load_manifest(src)
        if manifest is None:
            raise FileNotFoundError(f"{src / 'manifest.json'} not found: not a CrafterPlay folder")
        manifests.append((src, manifest))
    config = manifests[0][1]["config"]
    owner: dict[int, Path] = {}
    first = manifests[0][0]
    for src, manifest in manifests:
        diff = config_diff(config, manifest["config"], f"in {first}", f"in {src}")
        if diff:
            raise DatasetMismatchError(f"cannot merge shards of different datasets: {diff}")
        for entry in manifest["shards"]:
            if entry["index"] in owner:
                raise ValueError(
                    f"shard {entry['index']} is in both {owner[entry['index']]} and {src}: "
                    "overlapping --shards ranges"
                )
            owner[entry["index"]] = src
            if sha256_file(src / entry["file"]) != entry["sha256"]:
                raise ValueError(f"{src / entry['file']}: sha256 differs from its manifest")
    existing = load_manifest(out)
    if existing is not None:
        check_same_config(existing, config, out)
        taken = {e["index"] for e in existing["shards"]} & set(owner)
        if taken:
            raise ValueError(f"{out} already holds shards {sorted(taken)}")
    merged = existing or new_manifest(config)
    out.mkdir(parents=True, exist_ok=True)
    for src, manifest in manifests:
        for entry in manifest["shards"]:
            target = out / entry["file"]
            target.unlink(missing_ok=True)
            try:
                os.link(src / entry["file"], target)
            except OSError:
                shutil.copyfile(src / entry["file"], target)
            merged["shards"].append(entry)
    save_manifest(out, merged)
    have = {e["index"] for e in merged["shards"]}
    total = GenerationConfig(**config).num_shards
    return {**merged, "missing": [i for i in range(total) if i not in have]}
