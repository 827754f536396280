"""Transformer-XL: cached/segmented runs equal one pass; episode starts cut attention."""

from __future__ import annotations

import pytest
import torch

from zoo.models.trxl import TransformerXL


def _trxl(memory_len: int) -> TransformerXL:
    torch.manual_seed(0)
    trxl = TransformerXL(d_model=16, d_ff=32, n_heads=2, n_layers=2, memory_len=memory_len).eval()
    for layer in trxl.layers:  # non-zero positional bias so positions matter in the test
        torch.nn.init.normal_(layer.attn.relative_bias.weight)
    return trxl


def _run_segments(trxl, x, first, bounds):
    state = trxl.initial_state(x.shape[0])
    outs = []
    for start, end in zip(bounds[:-1], bounds[1:], strict=True):
        y, state = trxl(x[:, start:end], first[:, start:end], state)
        outs.append(y)
    return torch.cat(outs, dim=1), state


@pytest.mark.parametrize("memory_len", [3, 8, 40])
def test_stepwise_and_segmented_equal_one_pass(memory_len: int) -> None:
    trxl = _trxl(memory_len)
    x = torch.randn(3, 20, 16)
    first = torch.zeros(3, 20, dtype=torch.bool)
    first[0, 0] = first[1, 7] = first[2, 3] = first[2, 15] = True
    with torch.no_grad():
        full, full_state = trxl(x, first, trxl.initial_state(3))
        stepwise, step_state = _run_segments(trxl, x, first, list(range(21)))
        segmented, _ = _run_segments(trxl, x, first, [0, 5, 6, 17, 20])
    torch.testing.assert_close(stepwise, full, atol=1e-5, rtol=0)
    torch.testing.assert_close(segmented, full, atol=1e-5, rtol=0)
    torch.testing.assert_close(step_state.memory, full_state.memory, atol=1e-5, rtol=0)
    assert torch.equal(step_state.blocked, full_state.blocked)


def test_attention_span_is_memory_len() -> None:
    """A step more than memory_len steps back (through every layer) cannot matter."""
    trxl = _trxl(memory_len=4)
    x = torch.randn(1, 12, 16)
    first = torch.zeros(1, 12, dtype=torch.bool)
    changed = x.clone()
    changed[0, 0] = torch.randn(16)
    with torch.no_grad():
        a, _ = trxl(x, first, trxl.initial_state(1))
        b, _ = trxl(changed, first, trxl.initial_state(1))
    # 2 layers x span 4: step 0 reaches steps 0..8 and no further
    assert not torch.allclose(a[0, 8], b[0, 8])
    torch.testing.assert_close(a[0, 9:], b[0, 9:], atol=0, rtol=0)


def test_episode_start_blocks_everything_before_it() -> None:
    trxl = _trxl(memory_len=8)
    first = torch.zeros(1, 10, dtype=torch.bool)
    first[0, 6] = True
    x = torch.randn(1, 10, 16)
    changed = x.clone()
    changed[0, :6] = torch.randn(6, 16)
    with torch.no_grad():
        # the memory from an earlier segment is different too
        state_a = trxl(torch.randn(1, 5, 16), torch.zeros(1, 5, dtype=torch.bool), trxl.initial_state(1))[1]
        state_b = trxl(torch.randn(1, 5, 16), torch.zeros(1, 5, dtype=torch.bool), trxl.initial_state(1))[1]
        a, _ = trxl(x, first, state_a)
        b, _ = trxl(changed, first, state_b)
    torch.testing.assert_close(a[0, 6:], b[0, 6:], atol=1e-6, rtol=0)
    assert not torch.allclose(a[0, :6], b[0, :6])


def test_first_step_with_memory_ignores_memory() -> None:
    trxl = _trxl(memory_len=8)
    x = torch.randn(2, 1, 16)
    first = torch.ones(2, 1, dtype=torch.bool)
    with torch.no_grad():
        state = trxl(torch.randn(2, 6, 16), torch.zeros(2, 6, dtype=torch.bool), trxl.initial_state(2))[1]
        with_memory, _ = trxl(x, first, state)
        fresh, _ = trxl(x, first, trxl.initial_state(2))
    torch.testing.assert_close(with_memory, fresh, atol=1e-6, rtol=0)


def test_memory_is_detached() -> None:
    trxl = _trxl(memory_len=4).train()
    x = torch.randn(1, 6, 16, requires_grad=True)
    _, state = trxl(x, torch.zeros(1, 6, dtype=torch.bool), trxl.initial_state(1))
    assert not state.memory.requires_grad
    y, _ = trxl(torch.randn(1, 3, 16), torch.zeros(1, 3, dtype=torch.bool), state)
    y.sum().backward()
    assert x.grad is None


def test_bad_first_shape_is_a_clear_error() -> None:
    trxl = _trxl(memory_len=4)
    with pytest.raises(ValueError, match=r"first must have shape \(2, 5\)"):
        trxl(torch.randn(2, 5, 16), torch.zeros(2, 4, dtype=torch.bool), trxl.initial_state(2))
