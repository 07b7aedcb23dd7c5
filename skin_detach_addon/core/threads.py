"""The threads of the core: one pool (numpy and scipy release the GIL inside their loops, so row
blocks and vertex chunks run side by side on the machine's cores) and the one mechanism that runs
work beside Blender's main thread (:func:`submit`: the build, an opened file's preparation, the
stretch, the free rebuild), as cancellable :class:`Job` objects whose errors are reported once."""

import concurrent.futures
import os
import sys
import threading
import traceback
from concurrent.futures import ThreadPoolExecutor

import numpy as np

from .errors import SkinDetachError

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
#: lane's thread: it keeps to one core and never queues the pool behind the artist's work), and
#: the :class:`Job` it runs (:func:`checkpoint`).
_LOCAL = threading.local()
#: The lanes jobs run on (:func:`submit`): :data:`BACKGROUND` one thread, one job after the other,
#: its :func:`map_blocks` calls serial; :data:`FOREGROUND` (work the artist waits for, a build)
#: a few threads, their :func:`map_blocks` calls on the pool.
BACKGROUND, FOREGROUND = "background", "foreground"
_LANES = {}
#: Jobs submitted and not yet ended (:func:`cancel_all`), under :data:`_JOBS_LOCK`.
_LIVE = set()
_JOBS_LOCK = threading.Lock()


class Cancelled(Exception):
    """A :class:`Job` was cancelled (:meth:`Job.cancel`, :func:`cancel_all`): raised in it at its
    next :func:`checkpoint`, and by its :meth:`Job.result`."""


class Job:
    """One function run on a lane's thread (:func:`submit`).

    name       what it does (said when its error is printed)
    cancelled  whether :meth:`cancel` (or :func:`cancel_all`) was called

    Its error is reported once: raised by the first :meth:`result` that finds it (None from later
    ones), or, for a job nobody waits for (``watched=False``), printed on the console when it
    ends. Cancelling a queued job means it never runs; a running one stops at its next
    :func:`checkpoint` (the progress callbacks and the pieces of :func:`map_blocks`,
    :func:`cumsum`, :func:`repeat` check). A cancelled job's error is nobody's: dropped."""

    def __init__(self, name, watched=True, event=None):
        self.name = name
        self._event = threading.Event() if event is None else event
        self._watched = watched
        self._taken = False
        self._lock = threading.Lock()
        self._future = None

    @property
    def cancelled(self):
        return self._event.is_set()

    def cancel(self):
        """Stop the job: never run when still queued, else at its next :func:`checkpoint`."""
        self._event.set()
        if self._future is not None:
            self._future.cancel()

    def done(self):
        """Whether it ended (returned, raised, or was cancelled)."""
        return self._future.done()

    def wait(self, timeout=None):
        """Wait until it ended, at most ``timeout`` seconds; returns :meth:`done`."""
        concurrent.futures.wait([self._future], timeout)
        return self.done()

    def result(self, timeout=None):
        """What the function returned, waited for (at most ``timeout`` seconds, else
        :class:`TimeoutError`). Raises :class:`Cancelled` when it was cancelled, and the error it
        raised the first time it is asked for (later: None, the error was reported)."""
        try:
            return self._future.result(timeout)
        except concurrent.futures.CancelledError:
            raise Cancelled(f"{self.name}: cancelled before it ran") from None
        except (Cancelled, TimeoutError, concurrent.futures.TimeoutError):
            raise
        except Exception:  # noqa: BLE001 (what the job raised, reported once)
            if self.cancelled:
                raise Cancelled(f"{self.name}: cancelled") from None
            if self._take():
                raise
            return None

    def _take(self):
        """True the first time only: the caller reports the job's error."""
        with self._lock:
            taken, self._taken = self._taken, True
        return not taken

    def _ended(self, future):
        with _JOBS_LOCK:
            _LIVE.discard(self)
        if self._watched or future.cancelled() or self.cancelled:
            return
        error = future.exception()
        if error is not None and not isinstance(error, Cancelled) and self._take():
            print(f"Skin Detach: {self.name} failed in the background:", file=sys.stderr)
            traceback.print_exception(error, file=sys.stderr)


def _lane(lane):
    if lane not in _LANES:
        if lane == BACKGROUND:
            _LANES[lane] = ThreadPoolExecutor(max_workers=1, thread_name_prefix="skin_detach_background",
                                              initializer=_serial)
        elif lane == FOREGROUND:
            _LANES[lane] = ThreadPoolExecutor(max_workers=WORKERS, thread_name_prefix="skin_detach_foreground")
        else:
            raise SkinDetachError(f"lane: expected {BACKGROUND!r} or {FOREGROUND!r}, got {lane!r}")
    return _LANES[lane]


def submit(function, *args, lane=BACKGROUND, watched=True, cancel=None, name=None):
    """Run ``function(*args)`` on ``lane`` and return its :class:`Job`. On :data:`BACKGROUND`
    (the work of an opened file, one mesh at a time, while Blender's main thread answers events)
    after what was given to it before, its :func:`map_blocks` calls on that one thread; on
    :data:`FOREGROUND` (a build the artist waits for) at once, its :func:`map_blocks` calls on the
    pool. The function uses numpy and scipy only: they release the GIL in their loops, so the
    main thread runs beside it. ``watched``: whether someone takes its result (else its error is
    printed when it ends); ``cancel``: a :class:`threading.Event` that cancels it when set (a new
    one by default); ``name``: what it does (default: the function's name)."""
    job = Job(name or getattr(function, "__qualname__", repr(function)), watched, cancel)

    def run():
        _LOCAL.job = job
        try:
            checkpoint()
            return function(*args)
        finally:
            _LOCAL.job = None

    with _JOBS_LOCK:
        _LIVE.add(job)
    job._future = _lane(lane).submit(run)
    job._future.add_done_callback(job._ended)
    return job


def checkpoint():
    """Raise :class:`Cancelled` when the :class:`Job` this thread runs was cancelled (nothing on
    a thread that runs none: the main thread, the pool's)."""
    job = getattr(_LOCAL, "job", None)
    if job is not None and job._event.is_set():
        raise Cancelled(f"{job.name}: cancelled")


def cancel_all():
    """Cancel every job submitted so far (a file closed, the add-on unregistered): the queued ones
    never run, the running ones stop at their next :func:`checkpoint`; the next job starts at once."""
    with _JOBS_LOCK:
        live = list(_LIVE)
    for job in live:
        job.cancel()


def pool():
    """The shared :class:`ThreadPoolExecutor` of :data:`WORKERS` threads (made on first use)."""
    global _POOL
    if _POOL is None:
        _POOL = ThreadPoolExecutor(max_workers=WORKERS, thread_name_prefix="skin_detach")
    return _POOL


def shutdown():
    """Cancel every job (:func:`cancel_all`) and stop the lanes' threads and the pool's once their
    running jobs reached their next :func:`checkpoint`; the next :func:`pool` or :func:`submit`
    makes new ones."""
    global _POOL
    cancel_all()
    for lane in list(_LANES):
        _LANES.pop(lane).shutdown(wait=True, cancel_futures=True)
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
    (one after the other on the :data:`BACKGROUND` lane, see :func:`submit`); a cancelled job's
    blocks stop at the next one (:func:`checkpoint`)."""
    if len(blocks) <= 1 or WORKERS == 1 or getattr(_LOCAL, "serial", False):
        out = []
        for block in blocks:
            checkpoint()
            out.append(function(block))
        return out
    job = getattr(_LOCAL, "job", None)

    def run(block):  # the pool's thread checks the caller's job
        _LOCAL.job = job
        try:
            checkpoint()
            return function(block)
        finally:
            _LOCAL.job = None
    return [done.result() for done in [pool().submit(run, block) for block in blocks]]


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
        checkpoint()
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
        checkpoint()
        out[ends[a] - counts[a]:ends[b - 1]] = np.repeat(values[a:b], counts[a:b])
    return out
