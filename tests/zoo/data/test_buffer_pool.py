"""The recorders' buffer pool: prefilled buffers are the ones handed out, and a prefill never
makes more buffers than asked for in all (those in use count)."""

from zoo.data.shards import BufferPool


def test_prefill_makes_buffers_up_to_the_count_in_use_or_spare():
    pool = BufferPool()
    taken = pool.take((4, 8))  # one made on demand, in use
    pool.prefill((4, 8), 3)  # two more, spare
    spares = [pool.take((4, 8)), pool.take((4, 8))]
    assert all(b.shape == (4, 8) and b.dtype.name == "uint8" for b in [taken, *spares])
    assert len({id(b) for b in [taken, *spares]}) == 3
    for b in [taken, *spares]:
        pool.give(b)
    pool.prefill((4, 8), 3)  # all three exist: nothing new
    again = {id(pool.take((4, 8))) for _ in range(3)}
    assert again == {id(b) for b in [taken, *spares]}


def test_prefill_keeps_shapes_apart():
    pool = BufferPool()
    pool.prefill((2, 3), 1)
    assert pool.take((3, 2)).shape == (3, 2)
    assert pool.take((2, 3)).shape == (2, 3)
