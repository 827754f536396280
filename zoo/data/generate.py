"""CrafterPlay generation: an expert plays batched envs; episodes become WebDataset shards.

``generate`` writes (or finishes) a dataset: one ``ShardGenerator`` in this process, or
``--workers`` spawned ones (``zoo.data.pool``). Finished shards are verified by sha256 against
the manifest, so a rerun of a killed command skips them and redoes the rest.
"""

from __future__ import annotations

import json
import shutil
from collections.abc import Callable
from dataclasses import asdict
from pathlib import Path

from zoo.data.manifest import check_same_config, load_manifest, new_manifest, save_manifest
from zoo.data.pool import run_pool
from zoo.data.shard_generator import AgentBuilder, GenerationConfig, ShardGenerator
from zoo.files import sha256_file


def _complete_shards(out: Path, manifest: dict) -> list[dict]:
    """Manifest entries whose file exists and matches its sha256."""
    return [
        e for e in manifest["shards"]
        if (out / e["file"]).exists() and sha256_file(out / e["file"]) == e["sha256"]
    ]


def _remove_leftovers(out: Path) -> None:
    """Temp shards and work folders of killed runs (never complete data)."""
    for tmp in out.glob("crafterplay-*.tar.tmp-*"):
        tmp.unlink()
    for work in out.glob(".work-*"):
        shutil.rmtree(work, ignore_errors=True)


def generate(
    config: GenerationConfig,
    out: str | Path,
    workers: int = 1,
    num_envs: int = 8,
    progress: bool = True,
    after_shard: Callable[[dict], None] | None = None,
    generator: ShardGenerator | None = None,
    shards: tuple[int, int] | None = None,
    build_agent: AgentBuilder | None = None,
) -> dict:
    """Write (or finish) the dataset ``config`` in ``out``; returns the final manifest.

    ``after_shard`` is called with each new manifest entry once it is saved. ``generator``
    reuses an already built env and agent (JAX compiles once) for in-process runs. A worker
    process that raises or dies ends the run with a WorkerError naming its shard.
    ``shards`` (start, stop) writes only shard indices in [start, stop): one task of a job
    array, its folder joined with the others' by ``merge_datasets``. ``build_agent`` makes the
    agent of each process (``zoo.agents.dataset_agent``); not needed with ``generator``.
    """
    if generator is not None and generator.config != config:
        raise ValueError("generator was built for another GenerationConfig")
    if generator is None and build_agent is None:
        raise ValueError("pass build_agent (e.g. zoo.agents.dataset_agent) or a generator")
    from tqdm import tqdm

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    stored = json.loads(json.dumps(asdict(config)))  # as the manifest holds it (lists, not tuples)
    manifest = load_manifest(out)
    if manifest is None:
        manifest = new_manifest(stored)
    check_same_config(manifest, stored, out)
    manifest["shards"] = _complete_shards(out, manifest)
    _remove_leftovers(out)
    save_manifest(out, manifest)
    done = {e["index"] for e in manifest["shards"]}
    start, stop = shards or (0, config.num_shards)
    wanted = range(start, min(stop, config.num_shards))
    if not wanted:
        raise ValueError(
            f"--shards {start}:{stop} holds none of the dataset's shards 0:{config.num_shards}"
        )
    todo = [i for i in wanted if i not in done]

    bar = tqdm(
        total=sum(len(config.shard_episodes(i)) for i in wanted),
        initial=sum(e["episodes"] for e in manifest["shards"] if e["index"] in wanted),
        unit="ep", desc=f"crafterplay {out.name}", disable=not progress, dynamic_ncols=True,
    )
    frames_done = 0

    def advance(episodes: int, frames: int) -> None:
        nonlocal frames_done
        frames_done += frames
        bar.update(episodes)
        elapsed = bar.format_dict["elapsed"] or 1e-9
        bar.set_postfix(frames=frames_done, fps=f"{frames_done / elapsed:.0f}", refresh=False)

    def record(entry: dict) -> None:
        manifest["shards"].append(entry)
        save_manifest(out, manifest)
        if after_shard:
            after_shard(entry)

    try:
        if workers <= 1 or len(todo) <= 1:
            if generator is None and todo:
                generator = ShardGenerator(config, num_envs, build_agent)
            for index in todo:
                record(generator.run(index, out, advance))
        else:
            run_pool(config, out, todo, workers, num_envs, build_agent, advance, record)
    finally:
        bar.close()
    return manifest
