"""The 61 captions, their rules and categories, and the paraphrase bank."""

from __future__ import annotations

from pathlib import Path

import pytest
import yaml

from zoo.captions.rules import CATEGORIES, all_rules
from zoo.captions.vocabulary import (
    CAPTIONS_FILE,
    PARAPHRASES_FILE,
    load_vocabulary,
    read_captions,
    read_paraphrases,
)

PAPER_RULES = {  # the paper's Table C.1: rule -> (category, template)
    "harvest": ("achievement", "obtain {item}"),
    "place": ("achievement", "place {item} on {material}"),
    "craft": ("achievement", "craft {item}"),
    "kill": ("achievement", "kill {mob}"),
    "sleep": ("achievement", "go to sleep"),
    "stay": ("movement", "stay"),
    "move": ("movement", "move to {dir}"),
    "approach": ("movement", "approach {mob}"),
    "flee": ("movement", "flee from {mob}"),
    "explore": ("movement", "go explore"),
    "shelter": ("construction", "place {item} to build shelter"),
    "path": ("construction", "build path over {material}"),
    "tunnel": ("construction", "dig a tunnel"),
    "attacked_by": ("combat", "attacked by {mob}"),
    "block_attack": ("combat", "block attack from {mob} with {item}"),
}


def test_fifteen_rules_match_the_paper_table():
    rules = all_rules()
    assert {n: (r.category, r.template) for n, r in rules.items()} == PAPER_RULES
    assert {r.category for r in rules.values()} == set(CATEGORIES)


def test_exactly_61_distinct_captions_all_reachable():
    vocab = load_vocabulary()
    texts = vocab.texts()
    assert len(texts) == len(set(texts)) == 61
    rules = all_rules()
    producible = {c: name for name, r in rules.items() for c in r.captions()}
    assert set(producible) == set(texts)
    for caption in vocab.captions:
        assert producible[caption.text] == caption.rule
        assert caption.category == rules[caption.rule].category
    assert all(rule.captions() for rule in rules.values())
    assert [c.id for c in vocab.captions] == list(range(61))


def test_known_captions_present():
    vocab = load_vocabulary()
    for text in ("obtain stone", "place table on grass", "craft wood pickaxe", "kill cow",
                 "move to north", "approach zombie", "flee from skeleton",
                 "place stone to build shelter", "build path over water",
                 "block attack from zombie with stone", "attacked by skeleton"):
        assert text in vocab


def test_paraphrase_bank_complete_exact_and_unique():
    vocab = load_vocabulary()
    raw = yaml.safe_load(PARAPHRASES_FILE.read_text())
    assert set(raw) == set(vocab.texts()), "paraphrase keys must be exactly the captions"
    for caption, variants in raw.items():
        assert len(variants) >= 40, f"{caption!r} has only {len(variants)} paraphrases"
        assert len(set(variants)) == len(variants), f"{caption!r} repeats a paraphrase"
        assert caption not in variants
        assert all(v == v.strip() and v and v[0].islower() for v in variants), caption


def test_variants_start_with_the_caption():
    vocab = load_vocabulary()
    variants = vocab.variants("kill cow")
    assert variants[0] == "kill cow" and len(variants) >= 41


def test_unknown_caption_lookup_names_the_file():
    with pytest.raises(KeyError, match="captions.yaml"):
        load_vocabulary()["kill dragon"]


def _write(tmp_path: Path, name: str, data) -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(data))
    return path


def test_wrong_category_is_rejected(tmp_path):
    data = yaml.safe_load(CAPTIONS_FILE.read_text())
    data["captions"][0]["category"] = "combat"
    with pytest.raises(ValueError, match="category 'combat'"):
        read_captions(_write(tmp_path, "c.yaml", data), all_rules())


def test_missing_caption_is_rejected(tmp_path):
    data = yaml.safe_load(CAPTIONS_FILE.read_text())
    data["captions"] = data["captions"][1:]
    with pytest.raises(ValueError, match="missing from the file.*obtain wood"):
        read_captions(_write(tmp_path, "c.yaml", data), all_rules())


def test_caption_outside_its_template_is_rejected(tmp_path):
    data = yaml.safe_load(CAPTIONS_FILE.read_text())
    data["captions"][0]["caption"] = "attack cow"
    with pytest.raises(ValueError, match="'attack cow' cannot be produced by rule 'harvest'"):
        read_captions(_write(tmp_path, "c.yaml", data), all_rules())


def test_paraphrase_key_that_is_not_a_caption_is_rejected(tmp_path):
    path = _write(tmp_path, "p.yaml", {"attack cow": ["hit the cow"]})
    with pytest.raises(ValueError, match="not captions: \\['attack cow'\\]"):
        read_paraphrases(path, ["kill cow"])
