"""Core: the numpy calls made in pieces (so Blender's main thread runs beside the background
thread) give what the whole calls give, bit for bit."""

import numpy as np
import pytest

from skin_detach_addon.core import geometry, threads


@pytest.mark.parametrize("n", [0, 1, 7, 3000, 50_000])
def test_pieces_give_the_whole_calls_bits(monkeypatch, n):
    monkeypatch.setattr(threads, "PIECE", 997)  # many pieces, rows cut anywhere
    rng = np.random.default_rng(n)
    counts = rng.integers(0, 9, n)
    values = rng.random(n)
    starts = rng.integers(0, 1000, n).astype(np.int32)
    assert np.array_equal(threads.repeat(values, counts), np.repeat(values, counts))
    for array in (counts, counts.astype(np.int32), values):
        summed = threads.cumsum(array)
        assert summed.dtype == np.cumsum(array).dtype and np.array_equal(summed, np.cumsum(array))
    positions, owner = geometry.flat_ranges(starts, starts + counts)
    expected_owner = np.repeat(np.arange(n), counts)
    expected = starts[expected_owner] + (np.arange(expected_owner.size) - np.repeat(np.cumsum(counts) - counts, counts))
    assert np.array_equal(owner, expected_owner) and np.array_equal(positions, expected)


def test_a_row_larger_than_a_piece_stays_whole(monkeypatch):
    monkeypatch.setattr(threads, "PIECE", 10)
    ends = np.cumsum([3, 40, 2, 2, 30])
    # A cut after each row whose end passes a multiple of 10: rows 0 | 1-3 | 4.
    assert threads.pieces(ends) == [(0, 1), (1, 4), (4, 5)]
    assert threads.pieces(np.zeros(0, dtype=np.int64)) == []



@pytest.mark.parametrize("n, most", [(0, None), (10, None), (250_000, None), (1_000_000, 1 << 19), (5, 2)])
def test_row_blocks_cover_the_rows_in_order_once(n, most):
    spans = threads.row_blocks(n, most)
    assert spans[0][0] == 0 and spans[-1][1] == n
    assert all(p[1] == q[0] for p, q in zip(spans, spans[1:]))
    if most is not None:
        assert all(b - a <= most for a, b in spans)
    if n < threads.PARALLEL_MIN_ROWS and most is None:
        assert spans == [(0, n)]
