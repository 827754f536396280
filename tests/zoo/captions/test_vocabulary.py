"""The 61 captions, their rules and categories, and the paraphrase bank."""

from __future__ import annotations

import re
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


def test_every_caption_reaches_its_paraphrases_through_the_vocabulary():
    """Keys are matched exactly: a key that differs from its caption ("kill" vs "attack") would
    leave the caption with no paraphrases, and a repeated key would silently drop a list."""
    vocab = load_vocabulary()
    raw = yaml.safe_load(PARAPHRASES_FILE.read_text())
    keys = [line for line in PARAPHRASES_FILE.read_text().splitlines() if line.startswith('"')]
    assert len(keys) == len(vocab)
    for caption in vocab.texts():
        assert vocab.variants(caption) == (caption, *raw[caption])


# Phrases that said a different event than the caption's rule (found in review, see
# docs/captions.md): hurting or chasing is not killing, drinking lowers thirst, resting is
# what "stay" does, confronting or being next to is more than approaching, keeping a distance
# is not fleeing, skeletons shoot, a block is placed (not raised) and does not counterattack,
# hiding or looking around is not building or exploring.
WRONG_MEANING = {
    "kill": r"\bknock|\bhunt(?!s? (down )?and kills?)|\bbeats?\b|fights? off|to the end",
    "harvest": r"(restor|refill)\w* (its |the )?thirst|cutting down|searching|from the ground",
    "sleep": r"^(?!.*sleep).*\brest|for the night",
    "approach": r"confront|next to",
    "flee": r"keeps? (its distance|away)|^let the arrow",
    "attacked_by": r"^(?=.*skeleton).*\b(blow|bit(e|ten)|maul|punch)",
    "block_attack": r"counter|\braises?\b",
    "place": r"\bgrows\b",
    "craft": r"\bfirst\b|upgrades? to an? \w+ sword",
    "shelter": r"\bhides?\b",
    "explore": r"look around",
}


@pytest.mark.parametrize("rule", sorted(WRONG_MEANING))
def test_paraphrases_do_not_change_the_event(rule):
    vocab = load_vocabulary()
    wrong = [
        (c.text, p)
        for c in vocab.captions if c.rule == rule
        for p in vocab.paraphrases[c.text] if re.search(WRONG_MEANING[rule], p)
    ]
    assert not wrong


# Words naming one choice of a caption's slot ({mob}, {dir}, {item}, {material}), synonyms
# included; a paraphrase may not name another choice of a slot its caption fills.
SLOTS = {
    "mob": {"cow": "cow", "zombie": "zombie", "skeleton": "skeleton"},
    "dir": {
        "north": "north|up|upward", "south": "south|down|downward",
        "east": "east|right|eastward", "west": "west|left|westward",
    },
    "item": {
        "stone": "stone|rock", "table": "table|workbench", "furnace": "furnace",
        "plant": "plant|sapling|seedling",
    },
    "material": {
        "grass": "grass|grassy|lawn|meadow", "sand": "sand|sandy|beach", "path": "path",
        "water": "water|lake|pond", "lava": "lava",
    },
}


def test_paraphrases_name_no_other_mob_direction_item_or_material():
    vocab = load_vocabulary()
    wrong = []
    for caption in vocab.captions:
        words = set(caption.text.split())
        for choices in SLOTS.values():
            named = {name for name in choices if name in words}
            if not named:
                continue
            others = "|".join(v for name, v in choices.items() if name not in named)
            pattern = rf"\b({others})\b"
            wrong += [(caption.text, p) for p in vocab.paraphrases[caption.text]
                      if re.search(pattern, p)]
    assert not wrong
