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


# The one background mechanism (issue 52, item 9): jobs that are cancellable and report their
# errors once; a surface's rebuild cache shared between threads behind one lock.

import threading  # noqa: E402
import time  # noqa: E402

from skin_detach_addon.core.detached_surface import SkinDetachedSurface  # noqa: E402


def _fails():
    raise ValueError("broken on purpose")


def test_an_unwatched_jobs_error_is_printed_once_and_not_raised_again(capsys):
    job = threads.submit(_fails, watched=False, name="the failing job")
    assert job.wait(10)
    time.sleep(0.05)  # the done-callback runs on the job's thread right after it ends
    assert job.result() is None  # reported already: not raised to a later poll
    assert job.result() is None
    err = capsys.readouterr().err
    assert err.count("the failing job failed in the background") == 1 and err.count("ValueError: broken") == 1


def test_a_watched_jobs_error_is_raised_by_the_first_poll_only_and_never_printed(capsys):
    job = threads.submit(_fails, name="the failing job")
    assert job.wait(10)
    with pytest.raises(ValueError, match="broken on purpose"):
        job.result()
    assert job.result() is None  # the error was reported: once
    time.sleep(0.05)
    assert "broken on purpose" not in capsys.readouterr().err


def test_a_cancelled_queued_job_never_runs():
    release, ran = threading.Event(), []
    blocker = threads.submit(release.wait, 10)  # the background lane runs one job at a time
    queued = threads.submit(ran.append, "ran")
    queued.cancel()
    release.set()
    assert blocker.result(10) is True and queued.wait(10)
    assert ran == [] and queued.cancelled
    with pytest.raises(threads.Cancelled):
        queued.result()


def _counting(steps, started):
    started.set()
    for _ in range(100_000):
        threads.checkpoint()  # a progress report's check
        steps.append(1)
        time.sleep(0.001)


def test_a_cancelled_running_job_stops_at_its_next_checkpoint():
    steps, started = [], threading.Event()
    job = threads.submit(_counting, steps, started)
    assert started.wait(10)
    time.sleep(0.05)
    job.cancel()
    begun = time.perf_counter()
    assert job.wait(1.0), "the job did not stop at its next checkpoint"
    assert time.perf_counter() - begun < 0.5
    counted = len(steps)
    time.sleep(0.05)
    assert 0 < counted == len(steps) < 100_000
    with pytest.raises(threads.Cancelled):
        job.result()


def _summing(started):
    """Long numpy work in pieces (threads.cumsum checks between two pieces)."""
    started.set()
    values = np.ones(8 * threads.PIECE)
    for _ in range(10_000):
        threads.cumsum(values)


def test_cancel_all_stops_the_running_and_queued_jobs_and_the_next_starts_at_once(capsys):
    started = threading.Event()
    running = threads.submit(_summing, started, watched=False)
    queued = threads.submit(_summing, threading.Event(), watched=False)
    assert started.wait(10)
    begun = time.perf_counter()
    threads.cancel_all()
    after = threads.submit(time.perf_counter)  # submitted after: not cancelled
    ran_at = after.result(10)
    assert ran_at - begun < 1.0, f"the next job waited {ran_at - begun:.2f} s for the cancelled ones"
    assert running.cancelled and queued.cancelled and running.done() and queued.done()
    assert capsys.readouterr().err == ""  # a cancellation is no error: nothing printed


def test_shutdown_returns_quickly_while_a_job_runs():
    started = threading.Event()
    job = threads.submit(_summing, started, watched=False)
    assert started.wait(10)
    begun = time.perf_counter()
    threads.shutdown()
    assert time.perf_counter() - begun < 1.0 and job.done()
    assert threads.submit(lambda: 7).result(10) == 7  # the next job makes new threads


class _WatchedDict(dict):
    """A dict that records a change made by one thread while another iterates it; an iteration
    waits (at most 3 s) for ``go`` before it starts, so a change meanwhile is certain to land in it."""

    def __init__(self, *args):
        super().__init__(*args)
        self.go, self.iterating, self.clashes = threading.Event(), None, []

    def __iter__(self):
        self.iterating = threading.get_ident()
        try:
            self.go.wait(3)
            yield from list(dict.__iter__(self))
        finally:
            self.iterating = None

    def _changed(self):
        if self.iterating not in (None, threading.get_ident()):
            self.clashes.append(threading.current_thread().name)

    def __setitem__(self, key, value):
        self._changed()
        super().__setitem__(key, value)

    def pop(self, *args):
        self._changed()
        return super().pop(*args)

    def __delitem__(self, key):
        self._changed()
        super().__delitem__(key)


def test_a_surfaces_rebuilds_are_never_changed_while_another_thread_iterates_them(bundled):
    """A layout's rebuild made on one thread (it looks through the kept layouts) while the free
    rebuild is made on another: the kept rebuilds change under one lock only."""
    points, tris = bundled("spot")
    sds = SkinDetachedSurface.build(points, tris, target_faces=300)
    sds.attach_topology(sds.triangles)  # nothing made yet
    watched = sds._rebuilds = _WatchedDict({"old layout": None, "older layout": None})
    groups = np.full(sds.proxy_vertices.shape[0], -1)
    groups[:5] = 0
    failures = []

    def layout():
        try:
            sds.prepare_layout(groups)
        except Exception as exc:  # noqa: BLE001 (seen by the test)
            failures.append(exc)

    def free():
        try:
            while watched.iterating is None and not failures:  # the layout's thread looks through them first
                time.sleep(0.001)
            sds.prepare_free_rebuild(background=False)
        except Exception as exc:  # noqa: BLE001
            failures.append(exc)
        finally:
            watched.go.set()

    workers = [threading.Thread(target=layout, name="layout"), threading.Thread(target=free, name="free")]
    for worker in workers:
        worker.start()
    for worker in workers:
        worker.join(60)
    assert not failures and watched.clashes == []
    assert sds.free_rebuild_ready
    bent = sds.proxy_vertices * 1.01
    assert np.allclose(sds.reconstruct(bent, groups=groups), sds.reconstruct(bent, groups=groups))


def test_one_blas_thread_inside_the_block_and_the_counts_back_after_it():
    """numpy's and scipy's OpenBLAS (the wheels here bring both) run on one thread in the block,
    nested blocks too, and get their own counts back after it, also when it raises."""
    from skin_detach_addon.core import blas_threads
    import scipy.sparse.linalg  # noqa: F401 (scipy's BLAS loaded, as the core loads it)
    if not blas_threads.controls():
        pytest.skip("no OpenBLAS found (another BLAS)")
    before = blas_threads.counts()
    with blas_threads.one_thread():
        assert blas_threads.counts() == [1] * len(before)
        with blas_threads.one_thread():
            assert blas_threads.counts() == [1] * len(before)
        assert blas_threads.counts() == [1] * len(before)
    assert blas_threads.counts() == before
    with pytest.raises(ZeroDivisionError):
        with blas_threads.one_thread():
            1 / 0
    assert blas_threads.counts() == before
