"""Goal embeddings: per CrafterPlay step, the C-CLIP video embedding and the caption that fires.

C-Steve-1's hindsight relabelling (paper 4.3) needs, for every step t of every episode, the
C-CLIP embedding of the clip o_{t-4..t+1} (the goal when a later step is chosen) and the
CrafterCaption caption fired at t (event segments are runs of one caption). Both are computed
once by `zoo goals embed` (zoo/goals/embed_writer.py) so training never runs the video tower.

Layout of an embedding folder: ``embed-{i:06d}.tar`` per CrafterPlay shard i (same episodes,
same order) and ``manifest.json``. One tar sample per episode, keyed ``{episode:09d}``:
``.goal.npy`` float16 (T, D) unit-norm rows (clip indices clamped into [0, T-1] at the
edges), ``.caption.npy`` int16 (T,) caption id or -1, ``.json`` {"episode", "length", "seed"}.
This module holds the format and the reader; it needs neither torch nor the model.
"""

from __future__ import annotations

import io
import json
import tarfile
from collections import defaultdict
from pathlib import Path

import numpy as np

from zoo.captions.rules import EpisodeView, RuleParams, all_rules, scan_episode
from zoo.captions.vocabulary import Vocabulary
from zoo.data.manifest import MANIFEST
from zoo.data.manifest import MissingDatasetError, require_manifest
from zoo.data.storage import join, sha256_of

FORMAT = "crafter-zoo-goal-embeddings"
FORMAT_VERSION = 1
SHARD_PATTERN = "embed-{index:06d}.tar"
GOAL, CAPTION, META = "goal.npy", "caption.npy", "json"
GOAL_DTYPE, CAPTION_DTYPE = np.dtype(np.float16), np.dtype(np.int16)
CLIP = {"history": 4, "future": 1}
NO_CAPTION = -1
CAPTION_PRIORITY = ("achievement", "construction", "combat", "movement")
"""When several captions fire at one step the first category here wins, then the lowest id:
an achievement is the rarest, most goal-like event; movement fires almost everywhere."""


class EmbeddingMismatchError(ValueError):
    """Embeddings were made from another CrafterPlay set or another C-CLIP checkpoint."""


def clip_indices(
    length: int, history: int = CLIP["history"], future: int = CLIP["future"]
) -> np.ndarray:
    """(T, history+future+1) frame indices of the clip o_{t-history..t+future} per step t,
    clamped into [0, T-1] so every step has a goal, the first and last steps included."""
    offsets = np.arange(-history, future + 1)
    return np.clip(np.arange(length)[:, None] + offsets, 0, length - 1)


def step_captions(
    view: EpisodeView, vocab: Vocabulary, params: RuleParams | None = None
) -> np.ndarray:
    """(T,) int16 caption id fired at each step (-1: none), one per step by CAPTION_PRIORITY.

    Uses the same `scan_episode` as CrafterCaption, so step t's caption labels the same clip
    o_{t-4..t+1} that row t of the goal embeddings encodes.
    """
    out = np.full(view.length, NO_CAPTION, CAPTION_DTYPE)
    best: dict[int, tuple[int, int]] = {}
    for t, _, text in scan_episode(view, all_rules(), params):
        caption = vocab[text]
        key = (CAPTION_PRIORITY.index(caption.category), caption.id)
        if t not in best or key < best[t]:
            best[t] = key
    for t, (_, caption_id) in best.items():
        out[t] = caption_id
    return out


def _npy(array: np.ndarray) -> bytes:
    buffer = io.BytesIO()
    np.save(buffer, np.ascontiguousarray(array), allow_pickle=False)
    return buffer.getvalue()


def sample_members(
    episode: int, seed: int, goal: np.ndarray, caption: np.ndarray
) -> list[tuple[str, bytes]]:
    """The tar members (name, bytes) of one episode's sample, in a fixed order."""
    key = f"{episode:09d}"
    meta = {"episode": episode, "length": len(goal), "seed": seed}
    return [
        (f"{key}.{GOAL}", _npy(goal.astype(GOAL_DTYPE))),
        (f"{key}.{CAPTION}", _npy(caption.astype(CAPTION_DTYPE))),
        (f"{key}.{META}", json.dumps(meta, sort_keys=True).encode()),
    ]


def load_embedding_manifest(root: str | Path) -> dict:
    """The manifest of an embedding folder; FileNotFoundError/ValueError name the file."""
    path = Path(root) / MANIFEST
    if not path.is_file():
        raise MissingDatasetError(f"{path} not found: not a goal-embedding folder (zoo goals embed)")
    try:
        manifest = json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: not valid JSON ({err})") from err
    if manifest.get("format") != FORMAT or manifest.get("version") != FORMAT_VERSION:
        raise ValueError(
            f"{path}: format {manifest.get('format')!r} version {manifest.get('version')!r}, "
            f"expected {FORMAT!r} version {FORMAT_VERSION}"
        )
    return manifest


def _load_npy(data: bytes, name: str, dtype: np.dtype, shape: tuple) -> np.ndarray:
    array = np.load(io.BytesIO(data), allow_pickle=False)
    if array.dtype != dtype or array.ndim != len(shape) or any(
        want is not None and got != want for got, want in zip(array.shape, shape)
    ):
        raise ValueError(f"{name} is {array.dtype} {array.shape}, expected {dtype} {shape}")
    return array


def read_embedding_shard(path: str | Path) -> dict[int, dict[str, np.ndarray]]:
    """episode -> {"goal": (T, D) float16, "caption": (T,) int16}, in file order.

    A shard that is truncated (even exactly between samples: the end-of-archive blocks are
    checked), unreadable or malformed raises ValueError naming the file.
    """
    path = Path(path)
    try:
        raw = path.read_bytes()
        if len(raw) % tarfile.BLOCKSIZE or raw[-2 * tarfile.BLOCKSIZE :].count(0) != (
            2 * tarfile.BLOCKSIZE
        ):
            raise ValueError("truncated shard (no end-of-archive blocks)")
        members: dict[str, dict[str, bytes]] = defaultdict(dict)
        with tarfile.open(fileobj=io.BytesIO(raw), mode="r:") as tar:
            for info in tar:
                key, _, ext = info.name.partition(".")
                data = tar.extractfile(info)
                if data is None:
                    raise ValueError(f"member {info.name} is not a regular file")
                members[key][ext] = data.read()
        out = {}
        for key, files in members.items():
            missing = [ext for ext in (GOAL, CAPTION, META) if ext not in files]
            if missing:
                raise ValueError(f"sample {key} lacks {missing}")
            meta = json.loads(files[META])
            n = int(meta["length"])
            goal = _load_npy(files[GOAL], f"{key}.{GOAL}", GOAL_DTYPE, (n, None))
            caption = _load_npy(files[CAPTION], f"{key}.{CAPTION}", CAPTION_DTYPE, (n,))
            out[int(meta["episode"])] = {"goal": goal, "caption": caption}
    except (OSError, ValueError, KeyError, tarfile.TarError) as err:
        raise ValueError(f"{path}: corrupt goal-embedding shard ({err})") from err
    return out


def check_embeddings_match(
    embed_root: str | Path, play_root: str | Path, allow_partial: bool = False
) -> None:
    """Raise ValueError unless ``embed_root`` was made from exactly ``play_root``'s CrafterPlay
    manifest and covers all of its shards (some of them, with ``allow_partial``)."""
    embed = load_embedding_manifest(embed_root)
    play_path = join(play_root, MANIFEST)  # the CrafterPlay folder may be a URL
    play = require_manifest(play_root)
    play_sha = sha256_of(play_path)
    made_from = embed["source"]["manifest_sha256"]
    if made_from != play_sha:
        raise EmbeddingMismatchError(
            f"{Path(embed_root) / MANIFEST} was made from a CrafterPlay manifest with sha256 "
            f"{made_from}, but {play_path} has sha256 {play_sha}; rerun zoo goals embed"
        )
    have, want = len(embed["shards"]), len(play["shards"])
    if have != want and not (allow_partial and have > 0):
        raise EmbeddingMismatchError(
            f"{Path(embed_root) / MANIFEST} lists {have} shards, {play_path} lists {want}; "
            "embed the missing shards (zoo goals embed without --shards), or train on the "
            "embedded ones alone (data.init_args.partial_embeddings=true)"
        )
