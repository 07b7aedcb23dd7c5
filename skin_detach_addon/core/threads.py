"""The one thread pool of the core: numpy and scipy release the GIL inside their loops, so row
blocks and vertex chunks run side by side on the machine's cores."""

import os
import threading
from concurrent.futures import ThreadPoolExecutor

import numpy as np

#: Threads used (at most four: the work is memory-bound beyond that).
WORKERS = max(1, min(4, os.cpu_count() or 1))
#: Sparse products of at least this many rows split them over the threads (scipy's products
#: release the GIL): the rebuild's, the diffusion's.
PARALLEL_MIN_ROWS = 100_000
#: Output elements per piece of a numpy call that keeps the GIL throughout (``np.repeat``,
#: ``np.cumsum``): a few milliseconds each, so the other thread runs between two pieces (one
#: ``np.repeat`` of the background's diffusion kept Blender's main thread waiting 0.35 s at 10M).
PIECE = 1 << 20
_POOL = None
#: Per thread: whether :func:`map_blocks` runs its blocks one after the other (the background
#: thread: it keeps to one core and never queues the pool behind the artist's work).
_LOCAL = threading.local()
_BACKGROUND = None


def pool():
    """The shared :class:`ThreadPoolExecutor` of :data:`WORKERS` threads (made on first use)."""
    global _POOL
    if _POOL is None:
        _POOL = ThreadPoolExecutor(max_workers=WORKERS, thread_name_prefix="skin_detach")
    return _POOL


def shutdown():
    """Stop the background thread and the pool's threads (after the work given to them); the
    next :func:`pool` or :func:`background` makes new ones."""
    global _POOL, _BACKGROUND
    if _BACKGROUND is not None:
        _BACKGROUND.shutdown(wait=True)
        _BACKGROUND = None
    if _POOL is not None:
        _POOL.shutdown(wait=True)
        _POOL = None


def row_blocks(n, most=None):
    """Row ranges (a, b) covering rows 0..n: one per thread (:data:`WORKERS`) from
    :data:`PARALLEL_MIN_ROWS` rows on, one below, and more where ``most`` rows a range at most
    asks for them (for :func:`map_blocks`)."""
    count = WORKERS if n >= PARALLEL_MIN_ROWS else 1
    if most is not None:
        count = max(count, -(-n // most))
    bounds = np.linspace(0, n, count + 1).astype(int)
    return list(zip(bounds[:-1].tolist(), bounds[1:].tolist()))


def _serial():
    """Make this thread's :func:`map_blocks` calls run their blocks one after the other."""
    _LOCAL.serial = True


def map_blocks(function, blocks):
    """``[function(block) for block in blocks]``, run on the pool when there is more than one
    (one after the other on the background thread, see :func:`background`)."""
    if len(blocks) <= 1 or WORKERS == 1 or getattr(_LOCAL, "serial", False):
        return [function(block) for block in blocks]
    return [done.result() for done in [pool().submit(function, block) for block in blocks]]


def background(function, *args):
    """Run ``function(*args)`` on the one background thread, after what was given to it before
    (the work of an opened file, one mesh at a time, while Blender's main thread answers events);
    returns its :class:`concurrent.futures.Future` (which keeps what it raised). The function
    uses numpy and scipy only: they release the GIL in their loops, so the main thread runs
    beside it; its :func:`map_blocks` calls keep to that thread."""
    global _BACKGROUND
    if _BACKGROUND is None:
        _BACKGROUND = ThreadPoolExecutor(max_workers=1, thread_name_prefix="skin_detach_background",
                                         initializer=_serial)
    return _BACKGROUND.submit(function, *args)


def beside(function, *args):
    """Run ``function(*args)`` on one of the pool's threads while the caller goes on (its
    :func:`map_blocks` calls one block after the other there, so the pool's other threads stay
    the caller's); returns its :class:`concurrent.futures.Future`."""
    def serially():
        _serial()
        try:
            return function(*args)
        finally:
            _LOCAL.serial = False
    return pool().submit(serially)


def cumsum(values):
    """(n,) ``np.cumsum(values)`` of 1-D ``values`` (n,), the same bits (each piece starts from the
    last sum), made :data:`PIECE` elements at a time: numpy keeps the GIL through an accumulation."""
    values = np.asarray(values)
    out = np.empty(values.shape[0], dtype=np.cumsum(values[:0]).dtype)
    for a in range(0, values.shape[0], PIECE):
        b = min(a + PIECE, values.shape[0])
        out[a:b] = values[a:b]
        if a:
            out[a] += out[a - 1]
        np.cumsum(out[a:b], out=out[a:b])
    return out


def pieces(ends):
    """Row ranges (a, b) covering rows 0..n of a layout whose rows end at ``ends`` (n,) (a
    :func:`cumsum` of their sizes), each holding about :data:`PIECE` elements (a row larger than
    that alone)."""
    n = ends.shape[0]
    if n == 0:
        return []
    cuts = np.searchsorted(ends, np.arange(PIECE, int(ends[-1]), PIECE), side="right")
    bounds = np.unique(np.concatenate([[0], cuts, [n]]))
    return [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:])]


def repeat(values, counts):
    """``np.repeat(values, counts)`` of 1-D ``values`` (n,) and ``counts`` (n,) int, made in
    :func:`pieces` (numpy keeps the GIL through a repeat)."""
    values, counts = np.asarray(values), np.asarray(counts)
    ends = cumsum(counts)
    out = np.empty(int(ends[-1]) if ends.size else 0, dtype=values.dtype)
    for a, b in pieces(ends):
        out[ends[a] - counts[a]:ends[b - 1]] = np.repeat(values[a:b], counts[a:b])
    return out
