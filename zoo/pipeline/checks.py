"""Is a stage's output there and intact? Each check returns the output's key file (its sha256
fingerprints the output for the stages that read it) or raises why not.

The checks reuse what each format already records: CrafterPlay and goal-embedding shards are
re-hashed against their manifests (as ``zoo data info`` does), CrafterCaption shards against
theirs, checkpoints are rebuilt with ``zoo.weights.export.load_model`` (weights-only, no Lightning),
reports and prior pairs are parsed.
"""

from __future__ import annotations

import json
from pathlib import Path

from zoo.files import sha256_file


class Missing(Exception):
    """Nothing there yet: the stage runs."""


class Incomplete(Exception):
    """An intact part of the output: the same command, run again, finishes it in place."""


class Bad(Exception):
    """The output fails verification: it is moved aside and the stage runs again."""


def _folder(out: Path) -> None:
    """An absent or empty folder (a failed ``zoo fit`` removes its run) is not an output."""
    if not out.exists() or (out.is_dir() and not any(out.iterdir())):
        raise Missing(f"{out} holds nothing yet")


def _read_json(path: Path) -> dict:
    if not path.is_file():
        raise Bad(f"{path} is missing (an interrupted run?)")
    try:
        return json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as err:
        raise Bad(f"{path}: not valid JSON ({err})") from None


def _sums_match(root: Path, entries: list[dict], name_key: str) -> None:
    for entry in entries:
        path = root / entry[name_key]
        if not path.is_file():
            raise Bad(f"{path} is missing")
        if sha256_file(path) != entry["sha256"]:
            raise Bad(f"{path}: sha256 differs from its manifest's")


def crafterplay(out: Path) -> Path:
    """Manifest present, every planned shard listed, every shard's sha256 as recorded."""
    from zoo.data.generate import GenerationConfig
    from zoo.data.info import check_shards
    from zoo.data.manifest import MANIFEST, load_manifest

    _folder(out)
    try:
        manifest = load_manifest(out)
    except ValueError as err:
        raise Bad(str(err)) from None
    if manifest is None:
        raise Incomplete(f"{out} has no {MANIFEST} yet")
    bad = check_shards(out, manifest).bad
    if bad:
        raise Bad(f"{bad[0][0]}: {bad[0][1]}")
    planned = GenerationConfig(**manifest["config"]).num_shards
    if len(manifest["shards"]) < planned:
        raise Incomplete(f"{out}: {len(manifest['shards'])} of {planned} shards")
    return out / MANIFEST


def craftercaption(out: Path) -> Path:
    """Manifest present (written last) and every split's shards as recorded."""
    _folder(out)
    if not (out / "manifest.json").exists():
        raise Incomplete(f"{out} has no manifest.json yet")
    manifest = _read_json(out / "manifest.json")
    for split in manifest.get("splits", {}).values():
        _sums_match(out, split["shards"], "name")
    return out / "manifest.json"


def embeddings(out: Path, play: Path) -> Path:
    """Goal-embedding manifest present, one intact shard per CrafterPlay shard of ``play``."""
    from zoo.goals.embed import load_embedding_manifest

    _folder(out)
    if not (out / "manifest.json").exists():
        raise Incomplete(f"{out} has no manifest.json yet")
    try:
        manifest = load_embedding_manifest(out)
    except ValueError as err:
        raise Bad(str(err)) from None
    _sums_match(out, manifest["shards"], "file")
    planned = len(_read_json(play / "manifest.json")["shards"])
    if len(manifest["shards"]) < planned:
        raise Incomplete(f"{out}: {len(manifest['shards'])} of {planned} shards")
    return out / "manifest.json"


def prior_pairs(out: Path) -> Path:
    """``pairs.npz`` reads (every array, so zip CRCs are checked) and its sidecar parses."""
    from zoo.goals.prior_pairs import read_prior_pairs

    _folder(out)
    pairs = out / "pairs.npz"
    _read_json(out / "pairs.json")
    if not pairs.is_file():
        raise Bad(f"{pairs} is missing")
    try:
        read_prior_pairs(pairs)
    except Exception as err:  # noqa: BLE001 - numpy/zipfile raise many kinds on bad bytes
        raise Bad(f"{pairs}: {err}") from None
    return pairs


def checkpoint(out: Path, kind: str, pattern: str = "best-*.ckpt") -> Path:
    """The run folder's one ``checkpoints/<pattern>`` (default: the checkpoint validation chose;
    ``last.ckpt``: the newest weights), rebuilt as a ``kind`` network without Lightning."""
    from zoo.weights.export import load_model

    _folder(out)
    found = sorted(out.glob(f"*/checkpoints/{pattern}"))
    if len(found) != 1:
        raise Bad(f"{out}: expected one */checkpoints/{pattern}, found {len(found)}")
    try:
        load_model(found[0], kind)
    except Exception as err:  # noqa: BLE001 - torch.load raises many kinds on bad bytes
        raise Bad(f"{found[0]} does not load: {err}") from None
    return found[0]


def report(out: Path, field: str) -> Path:
    """``report.json`` parses and has ``field``."""
    _folder(out)
    if field not in _read_json(out / "report.json"):
        raise Bad(f"{out / 'report.json'} has no {field!r}")
    return out / "report.json"


def scale(out: Path) -> Path:
    """``zoo scale``'s ``scale.json`` parses and its ``scale.md`` is there."""
    _folder(out)
    _read_json(out / "scale.json")
    if not (out / "scale.md").is_file():
        raise Bad(f"{out / 'scale.md'} is missing")
    return out / "scale.json"
