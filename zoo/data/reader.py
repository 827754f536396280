"""Reading CrafterPlay: the contract every consumer (datamodules, captions, eval) builds on.

A sample decodes to a *chunk* of one episode (see docs/data.md). ``iter_chunks`` also checks
that every shard holds whole episodes in order, so a truncated shard is caught even when it
was cut exactly between tar members; the error names the shard file. Both frame modes read
alike: a rendered chunk (RESIDUAL member in place of FRAMES) re-renders its states and adds
the residual (``zoo.data.rerender``), so its chunk equals the stored mode's.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from zoo.data.codec import decode_arrays, decode_frames
from zoo.data.manifest import require_manifest
from zoo.data.noop import filter_noops
from zoo.data.rerender import decode_rendered
from zoo.data.shards import FRAMES, META, RENDER, RESIDUAL, STATE, STEPS
from zoo.data.storage import join, tar_samples
from zoo.envs.schema import validate_state

STEP_ARRAYS = {"actions": np.int64, "rewards": np.float32, "noop": np.bool_, "noop_run": np.int32}
OPTIONAL_STEP_ARRAYS = {"instruction": np.int16}
"""Step arrays only some shards hold, read as ``NO_INSTRUCTION`` where a shard has none, so
every chunk has them: ``instruction``, the caption id the expert was commanded (``zoo data
generate --instructions``)."""
NO_INSTRUCTION = -1
META_FIELDS = ("episode", "seed", "offset", "length", "episode_length", "last", "env", "expert")
RENDERED_META_FIELDS = ("renderer", "frames_crc32")


class CorruptShardError(RuntimeError):
    """A shard cannot be read to its end or holds malformed samples."""


@dataclass
class ReadStats:
    """What a read skipped (``skip_corrupt=True``): the shard files and why."""

    skipped_shards: list[str] = field(default_factory=list)
    reasons: list[str] = field(default_factory=list)

    @property
    def num_skipped(self) -> int:
        return len(self.skipped_shards)


def list_shards(root: str | Path) -> list[str]:
    """Shard paths of a CrafterPlay folder, in index order, from its manifest."""
    return [join(root, entry["file"]) for entry in require_manifest(root)["shards"]]


def _where(sample: dict) -> str:
    return f"{sample.get('__url__', '?')}: sample {sample.get('__key__', '?')}"


def decode_sample(sample: dict) -> dict:
    """Raw WebDataset sample (bytes per member) -> chunk dict; errors name shard and key."""
    where = _where(sample)
    rendered = RESIDUAL in sample
    expected = [RESIDUAL, RENDER] if rendered else [FRAMES]
    expected += [STATE, STEPS, META]
    missing = [name for name in expected if name not in sample]
    if missing:
        raise ValueError(f"{where}: missing fields {missing}; expected {expected}")
    try:
        meta = json.loads(sample[META])
        required = META_FIELDS + (RENDERED_META_FIELDS if rendered else ())
        lacking = [k for k in required if k not in meta]
        if lacking:
            raise ValueError(f"meta lacks {lacking}")
        n = int(meta["length"])
        steps = decode_arrays(sample[STEPS], "steps")
        state = decode_arrays(sample[STATE], "state")
        for name, dtype in OPTIONAL_STEP_ARRAYS.items():
            steps.setdefault(name, np.full(n, NO_INSTRUCTION, dtype))
        for name, dtype in {**STEP_ARRAYS, **OPTIONAL_STEP_ARRAYS}.items():
            if name not in steps:
                raise ValueError(f"steps lacks {name!r}")
            if steps[name].shape != (n,) or steps[name].dtype != dtype:
                raise ValueError(
                    f"{name!r} has {steps[name].dtype} {steps[name].shape}, "
                    f"expected {np.dtype(dtype)} ({n},)"
                )
        validate_state(state, n)
        if rendered:  # JAX is imported when the first rendered chunk is met
            frames = decode_rendered(
                sample[RESIDUAL], sample[RENDER], state, n, int(meta["frames_crc32"]),
                meta["renderer"],
            )
        else:
            frames = decode_frames(sample[FRAMES], n)
    except ValueError as err:
        raise ValueError(f"{where}: {err}") from err
    arrays = {k: steps[k] for k in (*STEP_ARRAYS, *OPTIONAL_STEP_ARRAYS)}
    return {**arrays, "frames": frames, "state": state, "meta": meta}


def _check_order(chunk: dict, expected: dict | None, url: str) -> dict | None:
    """Next expected (episode, offset) after ``chunk``; raises when chunks are out of order."""
    meta = chunk["meta"]
    here = (meta["episode"], meta["offset"])
    if expected is not None and here != (expected["episode"], expected["offset"]):
        raise CorruptShardError(
            f"{url}: chunk of episode {meta['episode']} at step {meta['offset']} follows an "
            f"unfinished episode {expected['episode']} (expected its step {expected['offset']})"
        )
    if expected is None and meta["offset"] != 0:
        raise CorruptShardError(
            f"{url}: episode {meta['episode']} starts at step {meta['offset']}, not 0"
        )
    if meta["last"]:
        return None
    return {"episode": meta["episode"], "offset": meta["offset"] + meta["length"]}


def _shard_chunks(url: str) -> Iterator[dict]:
    """Chunks of one shard; any read/decode failure becomes CorruptShardError naming it."""
    # One named shard, read whole: no node/worker splitting here (the caller splits shards).
    samples = tar_samples([{"url": url}])
    expected = None
    while True:
        try:
            sample = next(samples, None)
            if sample is None:
                break
            chunk = decode_sample(sample)
        except Exception as err:  # open, tarfile, zstd and decode errors alike
            raise CorruptShardError(f"{url}: corrupt or truncated shard ({err})") from err
        expected = _check_order(chunk, expected, url)
        yield chunk
    if expected is not None:
        raise CorruptShardError(
            f"{url}: truncated shard: episode {expected['episode']} ends at step "
            f"{expected['offset']} without its last chunk"
        )


def iter_chunks(
    urls: str | Iterable[str], skip_corrupt: bool = False, stats: ReadStats | None = None
) -> Iterator[dict]:
    """Chunks of the given shards in file order (an episode's chunks consecutive, in order).

    With ``skip_corrupt`` a broken shard is abandoned at the point of failure (chunks before
    it were already yielded) and recorded in ``stats``; otherwise CorruptShardError is raised.
    """
    urls = [urls] if isinstance(urls, str) else list(urls)
    for url in urls:
        try:
            yield from _shard_chunks(url)
        except CorruptShardError as err:
            if not skip_corrupt:
                raise
            if stats is not None:
                stats.skipped_shards.append(url)
                stats.reasons.append(str(err))


def join_chunks(chunks: list[dict]) -> dict:
    """Concatenate consecutive chunks of one episode; meta describes the whole episode."""
    keys = (*STEP_ARRAYS, *OPTIONAL_STEP_ARRAYS, "frames")
    out = {k: np.concatenate([c[k] for c in chunks]) for k in keys}
    out["state"] = {k: np.concatenate([c["state"][k] for c in chunks]) for k in chunks[0]["state"]}
    out["meta"] = {**chunks[0]["meta"], "length": len(out["actions"]), "last": True}
    return out


def iter_episodes(
    urls: str | Iterable[str], skip_corrupt: bool = False, stats: ReadStats | None = None
) -> Iterator[dict]:
    """Whole episodes (chunks joined); an episode of a skipped shard is never half-yielded."""
    pending: list[dict] = []
    for chunk in iter_chunks(urls, skip_corrupt, stats):
        if pending and chunk["meta"]["episode"] != pending[0]["meta"]["episode"]:
            pending = []  # the rest of a corrupt shard was skipped
        pending.append(chunk)
        if chunk["meta"]["last"]:
            yield join_chunks(pending)
            pending = []


__all__ = [
    "NO_INSTRUCTION", "OPTIONAL_STEP_ARRAYS", "CorruptShardError", "ReadStats", "decode_sample",
    "filter_noops", "iter_chunks", "iter_episodes", "join_chunks", "list_shards",
]
