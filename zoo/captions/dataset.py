"""CrafterPlay episodes -> CrafterCaption WebDataset shards (paper §3.2, Appendix C).

Two passes over the episodes: the first runs the rules on the states and keeps only
(episode, step, caption) references; then the held-out split is drawn by episode, each split
is balanced over rule categories (the paper) or rules, and the second pass cuts the kept
6-frame clips o_{t-4..t+1} and writes them. Everything after the input is fixed by the seed,
so a rerun writes identical shards; each shard is written to a temp name and renamed, so a
killed run resumes by skipping the shards already there (plan.json guards against resuming a
different run).

Shard layout: ``{out}/{split}-{i:06d}.tar`` with split in train/test; per sample
``{key}.frames.npy.zst`` (zstd-compressed .npy, uint8 (6, 144, 144, 3)) and ``{key}.json``
(caption, caption_id, rule, category, episode, seed, step, env, expert); ``manifest.json``
lists shards, the balance unit, per-category/rule/caption counts before and after balancing,
and the kept clips' shares per category and per rule.
"""

from __future__ import annotations

import hashlib
import io
import json
import tarfile
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import zstandard
from tqdm import tqdm

from zoo.captions.balance import (
    BALANCE_MODES,
    BALANCE_UNITS,
    DEFAULT_BALANCE_UNIT,
    balance_indices,
    count_by,
    shares,
    unit_levels,
)
from zoo.captions.rules import CATEGORIES, EpisodeView, RuleParams, all_rules, scan_episode
from zoo.captions.vocabulary import Caption, Vocabulary, load_vocabulary
from zoo.data.manifest import MissingDatasetError
from zoo.data.storage import join, read_bytes
from zoo.files import atomic_path, atomic_write_text, sha256_file

SPLITS = ("train", "val", "test")  # "val" only when val_episodes > 0
FORMAT_VERSION = 1
ZSTD_LEVEL = 3


@dataclass(frozen=True)
class EpisodeInfo:
    """Where a sample comes from: the CrafterPlay episode index and its seed."""

    episode: int
    seed: int
    length: int
    env: str
    expert: str


@dataclass
class CaptionRefs:
    """Column arrays of (episode, step, caption, rule) references, one row per fired caption."""

    episode: np.ndarray
    step: np.ndarray
    caption: np.ndarray
    rule: np.ndarray

    def digest(self) -> str:
        """Fingerprint of the rows (which clips, in which order) for resume checks."""
        sha = hashlib.sha1()
        for column in self.columns():
            sha.update(np.ascontiguousarray(column, np.int64).tobytes())
        return sha.hexdigest()

    def columns(self) -> tuple[np.ndarray, ...]:
        return self.episode, self.step, self.caption, self.rule

    def take(self, idx: np.ndarray) -> CaptionRefs:
        return CaptionRefs(self.episode[idx], self.step[idx], self.caption[idx], self.rule[idx])

    def __len__(self) -> int:
        return len(self.episode)


def episode_info(episode: dict) -> EpisodeInfo:
    meta = episode.get("meta", {})
    missing = [k for k in ("episode", "seed") if k not in meta]
    if missing:
        raise ValueError(f"episode meta lacks {missing}; expected zoo.data.reader episodes")
    return EpisodeInfo(
        int(meta["episode"]), int(meta["seed"]), len(episode["actions"]),
        str(meta.get("env", "")), str(meta.get("expert", "")),
    )


def find_captions(
    episodes: Iterable[dict],
    vocab: Vocabulary,
    params: RuleParams,
    progress: bool = False,
    total: int | None = None,
) -> tuple[list[EpisodeInfo], CaptionRefs]:
    """First pass: run every rule on every episode; keep references only (``total``: episode
    count for the progress bar, when known)."""
    rules = all_rules()
    rule_ids = {name: i for i, name in enumerate(vocab.rules())}
    infos, parts, seen = [], [], set()
    for episode in tqdm(
        episodes, total=total, desc="caption rules", unit="episode", disable=not progress
    ):
        info = episode_info(episode)
        if info.episode in seen:
            raise ValueError(f"episode {info.episode} appears twice in the input")
        seen.add(info.episode)
        infos.append(info)
        view = EpisodeView(episode["actions"], episode["state"])
        hits = [(t, vocab[c].id, rule_ids[r]) for t, r, c in scan_episode(view, rules, params)]
        table = np.array(hits, np.int32).reshape(-1, 3)
        parts.append(CaptionRefs(np.full(len(table), info.episode, np.int64), *table.T.copy()))
    empty = np.zeros(0, np.int32)
    parts = parts or [CaptionRefs(np.zeros(0, np.int64), empty, empty, empty)]
    return infos, CaptionRefs(*(np.concatenate(col) for col in zip(*(p.columns() for p in parts))))


def heldout_count(num_episodes: int, requested: int, fraction: float) -> int:
    """How many episodes to hold out: ``requested`` when that leaves training episodes,
    else ``fraction`` of them (at least one). Raises when no split can be made."""
    if requested < 1:
        raise ValueError(
            f"--heldout-episodes must be >= 1 (the test split may not be empty), got {requested}"
        )
    if num_episodes < 2:
        raise ValueError(
            f"need at least 2 episodes to hold some out for the test split, got {num_episodes}"
        )
    if requested < num_episodes:
        return requested
    return min(num_episodes - 1, max(1, int(num_episodes * fraction)))


def _shard_name(split: str, index: int) -> str:
    return f"{split}-{index:06d}.tar"


def _sample_key(episode: int, step: int, caption: int) -> str:
    return f"{episode:08d}-{step:06d}-{caption:02d}"


def _write_tar(path: Path, samples: list[tuple[str, dict[str, bytes]]]) -> str:
    """Write samples into a tar with fixed metadata (byte-identical reruns); temp + rename."""
    with atomic_path(path) as tmp, tarfile.open(tmp, "w", format=tarfile.USTAR_FORMAT) as tar:
        for key, files in samples:
            for ext, data in files.items():
                info = tarfile.TarInfo(f"{key}.{ext}")
                info.size, info.mtime, info.mode = len(data), 0, 0o644
                tar.addfile(info, io.BytesIO(data))
    return sha256_file(path)


def _encode_clip(frames: np.ndarray, compressor: zstandard.ZstdCompressor) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, np.ascontiguousarray(frames, np.uint8), allow_pickle=False)
    return compressor.compress(buffer.getvalue())


def decode_caption_sample(sample: dict) -> dict:
    """A CrafterCaption sample as read by webdataset -> {"frames": uint8 (6,144,144,3), **json}."""
    try:
        raw, meta = sample["frames.npy.zst"], sample["json"]
    except KeyError as err:
        key = sample.get("__key__")
        raise ValueError(f"CrafterCaption sample {key!r} lacks {err.args[0]!r}") from None
    frames = np.load(io.BytesIO(zstandard.ZstdDecompressor().decompress(raw)), allow_pickle=False)
    out = json.loads(meta)
    out["frames"] = frames
    return out


def load_caption_manifest(root: str | Path) -> dict:
    """root/manifest.json of a CrafterCaption folder or folder URL (``zoo.data.storage``)."""
    path = join(root, "manifest.json")
    try:
        return json.loads(read_bytes(path))
    except FileNotFoundError:
        raise MissingDatasetError(
            f"{path} does not exist; write the data with `zoo data caption`"
        ) from None


def list_caption_shards(root: str | Path, split: str) -> list[str]:
    """Shard paths (or URLs) of one split, from root/manifest.json."""
    manifest = load_caption_manifest(root)
    if split not in manifest["splits"]:
        splits = sorted(manifest["splits"])
        raise ValueError(f"{join(root, 'manifest.json')} has splits {splits}, not {split!r}")
    return [join(root, s["name"]) for s in manifest["splits"][split]["shards"]]


def write_caption_dataset(
    episodes: Callable[[], Iterable[dict]],
    out: str | Path,
    *,
    seed: int = 0,
    balance: str = "uniform",
    balance_unit: str = DEFAULT_BALANCE_UNIT,
    per_unit: int | None = None,
    heldout_episodes: int = 1000,
    heldout_fraction: float = 0.05,
    val_episodes: int = 0,
    per_shard: int = 1000,
    params: RuleParams | None = None,
    source: str = "",
    progress: bool = False,
    num_episodes: int | None = None,
) -> dict:
    """Caption the episodes ``episodes()`` yields (called twice, same order) into ``out``.

    ``balance_unit`` ("category" or "rule") is what ``balance`` evens out, ``per_unit`` its
    clips per unit (see zoo.captions.balance). ``heldout_episodes`` episodes form the test
    split; ``val_episodes`` others, if > 0, a validation split for checkpoint selection (so the
    test split is never used for choosing).
    Returns the manifest (also written to out/manifest.json).
    """
    if per_shard < 1:
        raise ValueError(f"--per-shard must be >= 1, got {per_shard}")
    if balance not in BALANCE_MODES or balance_unit not in BALANCE_UNITS:  # fail before the scan
        raise ValueError(
            f"balance {balance!r} / unit {balance_unit!r} not in {BALANCE_MODES} / {BALANCE_UNITS}"
        )
    params = params or RuleParams()
    vocab = load_vocabulary()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)

    if val_episodes < 0:
        raise ValueError(f"--val-episodes must be >= 0, got {val_episodes}")
    infos, refs = find_captions(episodes(), vocab, params, progress, num_episodes)
    ids = np.array([i.episode for i in infos], np.int64)
    n_test = heldout_count(len(infos), heldout_episodes, heldout_fraction)
    if val_episodes and n_test + val_episodes >= len(ids):
        raise ValueError(
            f"--val-episodes {val_episodes} with {n_test} test episodes leaves no training "
            f"episode of {len(ids)}"
        )
    # Child seeds in a fixed order (split, train, test, val): adding val changes no other split.
    split_seed, *balance_seeds = np.random.SeedSequence(seed).spawn(4)
    order = np.random.default_rng(split_seed).permutation(ids)
    split_ids = {
        "test": np.sort(order[:n_test]),
        "val": np.sort(order[n_test : n_test + val_episodes]),
    }
    split_ids["train"] = np.setdiff1d(ids, np.concatenate(list(split_ids.values())))
    splits = [s for s in SPLITS if len(split_ids[s])]
    split_seeds = dict(zip(("train", "test", "val"), balance_seeds))

    caption_names, rule_names = vocab.texts(), vocab.rules()
    caption_category = np.array([CATEGORIES.index(c.category) for c in vocab.captions], np.int64)

    def tally(rows: CaptionRefs) -> dict[str, dict[str, int]]:
        return {
            "categories": count_by(CATEGORIES, caption_category[rows.caption]),
            "rules": count_by(rule_names, rows.rule),
            "captions": count_by(caption_names, rows.caption),
        }

    kept: dict[str, CaptionRefs] = {}
    split_meta: dict[str, dict] = {}
    for split in splits:
        part = refs.take(np.flatnonzero(np.isin(refs.episode, split_ids[split])))
        levels = unit_levels(balance_unit, caption_category[part.caption], part.rule, part.caption)
        chosen = part.take(balance_indices(levels, split_seeds[split], balance, per_unit))
        if len(chosen) == 0:
            raise ValueError(
                f"the {split} split is empty: its {len(split_ids[split])} episodes fired no "
                "caption rule; generate longer or more episodes"
            )
        kept[split] = chosen
        after = tally(chosen)
        split_meta[split] = {
            "episodes": len(split_ids[split]),
            "samples": len(chosen),
            "counts_before": tally(part),
            "counts_after": after,
            "shares": {level: shares(after[level]) for level in ("categories", "rules")},
        }

    plan = {
        "format_version": FORMAT_VERSION,
        "seed": seed,
        "balance": balance,
        "balance_unit": balance_unit,
        "per_unit": per_unit,
        "per_shard": per_shard,
        "rule_params": asdict(params),
        "episodes": ids.tolist(),
        "heldout": split_ids["test"].tolist(),
        **({"val_episodes": split_ids["val"].tolist()} if val_episodes else {}),
        "samples": {s: len(kept[s]) for s in splits},
        "selection_sha1": {s: kept[s].digest() for s in splits},
    }
    _check_plan(out / "plan.json", plan)

    shards = _write_shards(episodes, infos, kept, vocab, out, per_shard, params.history, progress)
    for split in splits:
        split_meta[split]["shards"] = shards[split]
    manifest = {
        "dataset": "craftercaption",
        **plan,
        "source": source,
        "clip": {"length": params.history + 2, "steps": [-params.history, 1]},
        "captions": [
            {"id": c.id, "caption": c.text, "rule": c.rule, "category": c.category}
            for c in vocab.captions
        ],
        "splits": split_meta,
    }
    atomic_write_text(out / "manifest.json", json.dumps(manifest, indent=1))
    return manifest


def _check_plan(path: Path, plan: dict) -> None:
    """Record what this run writes; refuse to resume into a folder made by a different run."""
    if path.exists():
        previous = json.loads(path.read_text())
        if previous != plan:
            changed = sorted(k for k in plan if previous.get(k) != plan[k])
            raise ValueError(
                f"{path.parent} holds shards of a different caption run (differs in {changed}); "
                "use an empty --out folder"
            )
        return
    atomic_write_text(path, json.dumps(plan, indent=1))


def _write_shards(
    episodes: Callable[[], Iterable[dict]],
    infos: list[EpisodeInfo],
    kept: dict[str, CaptionRefs],
    vocab: Vocabulary,
    out: Path,
    per_shard: int,
    history: int,
    progress: bool,
) -> dict[str, list[dict]]:
    """Second pass: cut the kept clips in episode order and fill shards of ``per_shard``.

    Clips bound for a shard that already exists (a resumed run) are not encoded.
    """
    seen = {i.episode for i in infos}
    compressor = zstandard.ZstdCompressor(level=ZSTD_LEVEL)
    splits = list(kept)
    shards: dict[str, list[dict]] = {s: [] for s in splits}
    buffers: dict[str, list] = {s: [] for s in splits}
    order = {s: np.lexsort((kept[s].caption, kept[s].step, kept[s].episode)) for s in splits}
    cursor = {s: 0 for s in splits}

    def shard_path(split: str) -> Path:
        return out / _shard_name(split, len(shards[split]))

    def flush(split: str) -> None:
        path, batch = shard_path(split), buffers[split]
        sha = sha256_file(path) if path.exists() else _write_tar(path, batch)
        shards[split].append({"name": path.name, "samples": len(batch), "sha256": sha})
        buffers[split] = []

    for episode in tqdm(
        episodes(), total=len(infos), desc="caption clips", unit="episode", disable=not progress
    ):
        info = episode_info(episode)
        if info.episode not in seen:
            raise ValueError(f"episode {info.episode} was not in the first pass over the input")
        frames = np.asarray(episode["frames"])
        for split in splits:
            refs, idx = kept[split], order[split]
            while cursor[split] < len(idx) and refs.episode[idx[cursor[split]]] == info.episode:
                row = idx[cursor[split]]
                cursor[split] += 1
                step, caption = int(refs.step[row]), vocab.captions[int(refs.caption[row])]
                if not shard_path(split).exists():
                    clip = frames[step - history : step + 2]
                    buffers[split].append(_encode_sample(clip, info, step, caption, compressor))
                else:
                    buffers[split].append(None)
                if len(buffers[split]) == per_shard:
                    flush(split)
    for split in splits:
        if buffers[split]:
            flush(split)
        if cursor[split] != len(order[split]):
            raise ValueError(
                f"{split}: {len(order[split]) - cursor[split]} kept clips were not found in the "
                "second pass; the input changed between passes"
            )
    return shards


def _encode_sample(
    clip: np.ndarray, info: EpisodeInfo, step: int, caption: Caption,
    compressor: zstandard.ZstdCompressor,
) -> tuple[str, dict[str, bytes]]:
    meta = {
        "caption": caption.text, "caption_id": caption.id, "rule": caption.rule,
        "category": caption.category, "episode": info.episode, "seed": info.seed,
        "step": step, "env": info.env, "expert": info.expert,
    }
    files = {"frames.npy.zst": _encode_clip(clip, compressor), "json": json.dumps(meta).encode()}
    return _sample_key(info.episode, step, caption.id), files


def caption_dataset(src: str | Path, out: str | Path, **kwargs) -> dict:
    """Caption the CrafterPlay shards under ``src`` (see write_caption_dataset for options)."""
    from zoo.data.reader import iter_episodes, list_shards

    urls = list_shards(src)
    if not urls:
        raise ValueError(f"{src}: manifest lists no CrafterPlay shards")
    manifest = json.loads((Path(src) / "manifest.json").read_text())
    num_episodes = sum(int(shard["episodes"]) for shard in manifest["shards"])
    return write_caption_dataset(
        lambda: iter_episodes(urls), out, source=str(src), num_episodes=num_episodes, **kwargs
    )
