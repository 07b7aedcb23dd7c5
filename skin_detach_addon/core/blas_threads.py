"""The threads of the BLAS libraries numpy and scipy brought (OpenBLAS: numpy's, and scipy's own
copy, each with its own worker threads), kept to one while a drag answers an event.

A drag move's BLAS calls are small (the proxy's triangular solves, (n, 3) by (3, 3) products,
4 x 4 inversions): OpenBLAS hands some of them to its worker thread and waits for it, and its
workers poll for work after each call. On a machine whose cores are busy (Blender drawing, other
programs) the caller then waits for a worker the system has not scheduled: a 4 x 4 solve of 13 us
took 2-5 ms, and whole moves took two to four times their work (issue 53, the cow beside two
other processes on two cores). One thread does the same arithmetic (the products' rows are split
between threads, not their sums), so the shapes stay the same bits.

:func:`one_thread` is a context manager; without OpenBLAS (another BLAS, a library that cannot
be found or answers no thread count) it does nothing.
"""

import contextlib
import ctypes
import glob
import importlib
import os
import sys
import threading

#: (set, get) function name pairs OpenBLAS builds export: numpy's 64-bit-integer build suffixes
#: them, scipy's (scipy-openblas) prefixes them.
NAMES = [(f"{prefix}_set_num_threads{suffix}", f"{prefix}_get_num_threads{suffix}")
         for prefix in ("openblas", "scipy_openblas") for suffix in ("64_", "", "_64")]
#: Packages whose bundled OpenBLAS is looked for (in their wheels' library folders).
PACKAGES = ("numpy", "scipy")
_LOCK = threading.Lock()
_FOUND = None
#: Nesting depth of :func:`one_thread` (the outermost one sets and restores).
_DEPTH = [0]


def _library_files(package):
    """Paths of the OpenBLAS libraries ``package``'s wheel brought (Linux: ``<package>.libs``,
    macOS: ``<package>/.dylibs``, Windows: ``<package>.libs`` or ``<package>/.libs``)."""
    module = sys.modules.get(package)
    if module is None or not getattr(module, "__file__", None):
        return []
    folder = os.path.dirname(module.__file__)
    found = []
    for where in (folder + ".libs", os.path.join(folder, ".libs"), os.path.join(folder, ".dylibs")):
        found += sorted(glob.glob(os.path.join(where, "*openblas*")))
    return found


def _loaded(path):
    """Whether the library at ``path`` is loaded in this process already (Linux: its memory map;
    elsewhere a wheel's library is loaded with its package, which is imported)."""
    maps = "/proc/self/maps"
    if not os.path.exists(maps):
        return True
    try:
        with open(maps, encoding="utf-8", errors="replace") as lines:
            return any(os.path.basename(path) in line for line in lines)
    except OSError:
        return False


def controls():
    """[(set_num_threads, get_num_threads)] of every OpenBLAS numpy and scipy loaded (found once;
    empty when there is none)."""
    global _FOUND
    with _LOCK:
        if _FOUND is None:
            found = []
            for package in PACKAGES:
                if package == "scipy":
                    with contextlib.suppress(ImportError):
                        importlib.import_module("scipy.linalg")  # loads scipy's BLAS, as the core does
                for path in _library_files(package):
                    if not _loaded(path):
                        continue
                    try:
                        library = ctypes.CDLL(path)
                    except OSError:
                        continue
                    for set_name, get_name in NAMES:
                        if hasattr(library, set_name) and hasattr(library, get_name):
                            setter, getter = getattr(library, set_name), getattr(library, get_name)
                            setter.argtypes, setter.restype = [ctypes.c_int], None
                            getter.argtypes, getter.restype = [], ctypes.c_int
                            found.append((setter, getter))
                            break
            _FOUND = found
        return _FOUND


@contextlib.contextmanager
def one_thread():
    """Run the block with every OpenBLAS numpy and scipy use on one thread, their thread counts
    set back after it (nested blocks: the outermost sets and restores; meant for Blender's main
    thread, whose drag events do not overlap)."""
    _DEPTH[0] += 1
    saved = []
    try:
        if _DEPTH[0] == 1:
            for setter, getter in controls():
                count = getter()
                if count > 1:
                    setter(1)
                    saved.append((setter, count))
        yield
    finally:
        for setter, count in saved:
            setter(count)
        _DEPTH[0] -= 1


def counts():
    """The thread count of every OpenBLAS found (see :func:`controls`)."""
    return [getter() for _, getter in controls()]
