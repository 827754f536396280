"""The instruction schedule of ``zoo data generate --instructions``, with CrafterCaption ids.

The scripted expert names its instructions by caption text and sits below ``zoo.captions``;
the shards record caption ids. This layer sees both, so it pairs them once, into the schedule
that the manifest stores.
"""

from __future__ import annotations

from zoo.captions.vocabulary import load_vocabulary
from zoo.experts.scripted.schedule import InstructionSchedule, read_schedule


def instruction_schedule(spec: str, timeout: int) -> InstructionSchedule:
    """The schedule of ``--instructions SPEC`` (a named caption set or a file of captions with
    optional weights, ``read_schedule``) with each caption's CrafterCaption id."""
    captions, weights = read_schedule(spec)
    vocab = load_vocabulary()
    # a text that is no caption is refused by the schedule, as one the expert cannot follow
    ids = [vocab[text].id if text in vocab else 0 for text in captions]
    return InstructionSchedule(captions, tuple(ids), timeout, weights)
