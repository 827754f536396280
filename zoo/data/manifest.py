"""manifest.json: what a CrafterPlay folder holds and how it was made.

It records the generation arguments once (``config``) and one entry per complete shard
(file, sha256, episodes, steps, seeds, versions, noop and achievement statistics). It is
rewritten atomically after every shard, so a killed run leaves a manifest that lists
exactly the shards that were finished and verified.
"""

from __future__ import annotations

import json
from importlib import metadata
from pathlib import Path

from zoo.data.storage import join, read_bytes
from zoo.files import atomic_write_text

MANIFEST = "manifest.json"
FORMAT = "crafterplay"
FORMAT_VERSION = 2
VERSIONED_PACKAGES = ("crafter-zoo", "crafter", "craftax", "jax", "numpy", "zstandard")


class DatasetMismatchError(RuntimeError):
    """A folder already holds CrafterPlay data made with other generation arguments."""


def package_versions() -> dict[str, str | None]:
    """Versions of the packages whose behaviour decides a shard's bytes."""
    out = {}
    for name in VERSIONED_PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def new_manifest(config: dict) -> dict:
    return {"format": FORMAT, "format_version": FORMAT_VERSION, "config": config, "shards": []}


class MissingDatasetError(FileNotFoundError):
    """A data folder without the data asked for (no manifest.json, or none of a split's
    shards): a user's error, so ``zoo fit`` reports it in one line, not as a traceback."""


def load_manifest(root: str | Path) -> dict | None:
    """The manifest of ``root`` (a folder or folder URL, ``zoo.data.storage``), or None when
    there is none yet."""
    path = join(root, MANIFEST)
    try:
        text = read_bytes(path)
    except FileNotFoundError:
        return None
    try:
        manifest = json.loads(text)
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: not valid JSON ({err})") from err
    if manifest.get("format") != FORMAT or "shards" not in manifest:
        raise ValueError(f"{path}: not a CrafterPlay manifest (expected format {FORMAT!r})")
    if manifest.get("format_version") == 1:
        _upgrade_from_version_1(manifest)
    if manifest.get("format_version") != FORMAT_VERSION:
        raise ValueError(
            f"{path}: CrafterPlay format version {manifest.get('format_version')!r}, this zoo "
            f"reads versions 1 and {FORMAT_VERSION}; regenerate the data with this version"
        )
    return manifest


def _upgrade_from_version_1(manifest: dict) -> None:
    """Read a version-1 manifest as version 2 writes it. Its shards are the same bytes; its
    ``config`` spelled three defaults as null (frames "stored", start_states "default",
    expert_options {}) and may lack the fields added during version 1 (dagger, instructions,
    start_states). A resumed generation saves it back as version 2."""
    config = manifest.get("config", {})
    defaults = {"frames": "stored", "start_states": "default", "expert_options": {}}
    for key, value in defaults.items():
        if config.get(key) is None:
            config[key] = value
    for key in ("dagger", "instructions"):
        config.setdefault(key, None)
    manifest["format_version"] = FORMAT_VERSION


def require_manifest(root: str | Path) -> dict:
    """The manifest of a CrafterPlay folder (or folder URL); MissingDatasetError if it has none."""
    manifest = load_manifest(root)
    if manifest is None:
        raise MissingDatasetError(
            f"{join(root, MANIFEST)} not found: not a CrafterPlay folder (make it with"
            " `zoo data generate`)"
        )
    return manifest


def save_manifest(root: str | Path, manifest: dict) -> None:
    """Write via a temp file and rename, so readers never see half a manifest."""
    path = Path(root) / MANIFEST
    manifest["shards"] = sorted(manifest["shards"], key=lambda entry: entry["index"])
    atomic_write_text(path, json.dumps(manifest, indent=1, sort_keys=True) + "\n")


def config_diff(
    stored: dict, config: dict, here: str = "there", there: str = "now", prefix: str = ""
) -> str:
    """The generation arguments that differ, as "key: a here vs b there, ..." ("" if none);
    a key one side lacks counts as None (fields added later keep old manifests equal). Nested
    settings both sides have are compared key by key ("dagger.beta: ...")."""
    diffs = []
    for key in sorted(set(stored) | set(config)):
        ours, theirs = stored.get(key), config.get(key)
        if isinstance(ours, dict) and isinstance(theirs, dict):
            diffs.append(config_diff(ours, theirs, here, there, f"{prefix}{key}."))
        elif ours != theirs:
            diffs.append(f"{prefix}{key}: {ours!r} {here} vs {theirs!r} {there}")
    return ", ".join(d for d in diffs if d)


def check_same_config(manifest: dict, config: dict, root: str | Path) -> None:
    """Refuse to mix datasets: the stored generation arguments must equal the new ones."""
    lines = config_diff(manifest.get("config", {}), config)
    if lines:
        raise DatasetMismatchError(
            f"{Path(root)} already holds CrafterPlay data generated with other arguments "
            f"({lines}); use another --out folder or the original arguments to resume"
        )
