"""The Caption Generator: 15 rules label 6-frame clips with 61 captions (CrafterCaption).

`zoo.captions.rules` holds the machinery (windows, registry), the rules live in
rules_achievement/movement/construction/combat, `vocabulary` loads the caption and
paraphrase data files, `balance` evens out rule categories (or rules), `dataset` writes the shards.
"""

from zoo.captions.balance import balance_indices
from zoo.captions.dataset import caption_dataset, decode_caption_sample, list_caption_shards
from zoo.captions.rules import EpisodeView, Rule, RuleParams, Window, all_rules, scan_episode
from zoo.captions.vocabulary import Caption, Vocabulary, load_vocabulary

__all__ = [
    "Caption", "EpisodeView", "Rule", "RuleParams", "Vocabulary", "Window", "all_rules",
    "balance_indices", "caption_dataset", "decode_caption_sample", "list_caption_shards",
    "load_vocabulary", "scan_episode",
]
