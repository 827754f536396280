"""C-Steve-1's goal data (paper §4.3, "Dataset Generation"): the C-CLIP embedding of every
CrafterPlay step's clip (``embed``, ``embed_writer``), hindsight relabelling of those clips into
goals (``relabel``, attached to training chunks by ``attach``; measured by ``relabel_stats``),
and the (video, text) embedding pairs the CVAE prior trains on (``prior_pairs``).

It reads CrafterPlay (``zoo.data``) and CrafterCaption (``zoo.captions``); neither imports it.
Commands: ``zoo goals embed | prior-pairs | relabel-stats``.
"""
