"""The caption vocabulary: the 61 captions (captions.yaml) and their paraphrases (paraphrases.yaml).

Both are data files so captions can be edited without touching code; loading checks them
against the rule registry (every caption producible by its rule, every rule's output listed)
and the paraphrase keys against the captions, so the two files can never drift apart.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from pathlib import Path

import yaml

from zoo.captions.rules import Rule, all_rules

HERE = Path(__file__).parent
CAPTIONS_FILE = HERE / "captions.yaml"
PARAPHRASES_FILE = HERE / "paraphrases.yaml"


@dataclass(frozen=True)
class Caption:
    """One template caption; ``id`` is its position in captions.yaml."""

    id: int
    text: str
    rule: str
    category: str


@dataclass(frozen=True)
class Vocabulary:
    """The captions with lookups by text, and each caption's paraphrases."""

    captions: tuple[Caption, ...]
    paraphrases: dict[str, tuple[str, ...]]

    def __post_init__(self) -> None:
        object.__setattr__(self, "_by_text", {c.text: c for c in self.captions})

    def __len__(self) -> int:
        return len(self.captions)

    def __getitem__(self, text: str) -> Caption:
        try:
            return self._by_text[text]  # type: ignore[attr-defined]
        except KeyError:
            raise KeyError(f"{text!r} is not a caption in {CAPTIONS_FILE.name}") from None

    def __contains__(self, text: object) -> bool:
        return text in self._by_text  # type: ignore[attr-defined]

    def texts(self) -> list[str]:
        return [c.text for c in self.captions]

    def variants(self, text: str) -> tuple[str, ...]:
        """The caption followed by its paraphrases: what C-CLIP samples uniformly from."""
        return (self[text].text, *self.paraphrases.get(text, ()))

    def rules(self) -> list[str]:
        """Rule names in caption order, each once."""
        return list(dict.fromkeys(c.rule for c in self.captions))


def read_captions(path: Path, rules: dict[str, Rule]) -> tuple[Caption, ...]:
    """Parse captions.yaml and check it against the registered rules."""
    data = yaml.safe_load(Path(path).read_text())
    entries = data.get("captions") if isinstance(data, dict) else None
    if not isinstance(entries, list):
        raise ValueError(f"{path}: expected a top-level 'captions:' list")
    captions = []
    for i, entry in enumerate(entries):
        if not isinstance(entry, dict) or set(entry) != {"caption", "rule", "category"}:
            raise ValueError(f"{path}: entry {i} must have caption, rule, category: {entry!r}")
        rule = rules.get(entry["rule"])
        if rule is None:
            raise ValueError(
                f"{path}: entry {i} names unknown rule {entry['rule']!r}; known {sorted(rules)}"
            )
        if entry["category"] != rule.category:
            raise ValueError(
                f"{path}: entry {i} ({entry['caption']!r}) has category {entry['category']!r}, "
                f"but rule {rule.name!r} is in {rule.category!r}"
            )
        if entry["caption"] not in rule.captions():
            raise ValueError(
                f"{path}: {entry['caption']!r} cannot be produced by rule {rule.name!r} "
                f"(template {rule.template!r})"
            )
        captions.append(Caption(i, entry["caption"], rule.name, rule.category))
    texts = [c.text for c in captions]
    duplicates = sorted({t for t in texts if texts.count(t) > 1})
    if duplicates:
        raise ValueError(f"{path}: duplicate captions {duplicates}")
    missing = [c for r in rules.values() for c in r.captions() if c not in texts]
    if missing:
        raise ValueError(f"{path}: rules produce captions missing from the file: {missing}")
    return tuple(captions)


def read_paraphrases(path: Path, captions: list[str]) -> dict[str, tuple[str, ...]]:
    """Parse paraphrases.yaml: caption -> list of paraphrases; keys must be captions."""
    data = yaml.safe_load(Path(path).read_text()) or {}
    if not isinstance(data, dict):
        raise ValueError(f"{path}: expected a mapping caption -> list of paraphrases")
    unknown = sorted(set(data) - set(captions))
    if unknown:
        raise ValueError(f"{path}: keys that are not captions: {unknown}")
    out = {}
    for key, variants in data.items():
        if not isinstance(variants, list) or not all(isinstance(v, str) for v in variants):
            raise ValueError(f"{path}: {key!r} must map to a list of strings")
        out[key] = tuple(variants)
    return out


@cache
def load_vocabulary(
    captions_file: Path = CAPTIONS_FILE, paraphrases_file: Path = PARAPHRASES_FILE
) -> Vocabulary:
    """The checked vocabulary (cached per file pair)."""
    captions = read_captions(captions_file, all_rules())
    paraphrases = read_paraphrases(paraphrases_file, [c.text for c in captions])
    return Vocabulary(captions, paraphrases)
