"""``pack_sequences``: chunks joined and cut into exact sequences, each step copied once."""

from __future__ import annotations

import numpy as np

from zoo.data.sequences import pack_sequences


def _chunk(episode: int, offset: int, n: int, start: int) -> dict:
    frames = np.arange(start, start + n, dtype=np.uint8).reshape(n, 1, 1, 1) * np.ones(
        (1, 2, 2, 3), np.uint8)
    return {"frames": frames, "actions": np.arange(start, start + n) % 17,
            "meta": {"episode": episode, "offset": offset}}


def test_chunks_are_cut_into_exact_sequences_across_chunk_edges() -> None:
    """Chunks of 5, 3 (the same episode) and 9 (a new one) steps at sequence length 4: 17
    steps give 4 sequences of consecutive steps (the 1 left over is dropped); ``first`` marks
    step 0 of each episode; every sequence owns its memory (no view of a chunk)."""
    chunks = [_chunk(0, 0, 5, 0), _chunk(0, 5, 3, 5), _chunk(1, 0, 9, 8)]
    sequences = list(pack_sequences(chunks, seq_len=4))
    assert len(sequences) == 4
    steps = np.concatenate([s["frames"][:, 0, 0, 0] for s in sequences])
    assert steps.tolist() == list(range(16))
    assert np.concatenate([s["first"] for s in sequences]).nonzero()[0].tolist() == [0, 8]
    assert np.concatenate([s["episode"] for s in sequences]).tolist() == [0] * 8 + [1] * 8
    assert np.concatenate([s["step"] for s in sequences]).tolist() == [*range(8), *range(8)]
    for sequence in sequences:
        assert all(value.shape[0] == 4 for value in sequence.values())
        assert not any(np.shares_memory(sequence["frames"], c["frames"]) for c in chunks)
