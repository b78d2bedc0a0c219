"""The one place the kernel modules get Numba from (``from .._numba import njit, prange``).

Importing this module imports Numba and makes its on-disk cache safe for this project's use
(issue 35): the kernels are ``@njit(cache=True)`` and the test suite, the app, batch and Dask
workers and the offload helper all compile into the same cache (``__pycache__`` next to the
sources, or ``NUMBA_CACHE_DIR``), often several processes at the same time on a fresh install.
Two rules keep every process of every cache state crash-free:

1. **A compiled function never calls a ``parallel=True`` one.** Numba's cache of a function
   that calls a parallel function is not safe (numba issues #8578, #4807, open): with an empty
   cache, two processes running Paparazzi at the same time wrote a cached
   ``render.kernels._lambert_image_vjp`` (which then called the parallel
   ``_normal_vjp_terms_par`` through ``_normal_vjp``), and every later process that loaded it
   died with a segmentation fault in its first image derivative. Parallel kernels are called
   from Python only: the Python wrapper picks the parallel or the serial kernel and does the
   (serial, compiled) rest in a separate call. ``tests/algorithms/test_numba_cache.py`` checks
   the rule on the source of every kernel module and, across fresh processes, on a cache built
   by concurrent first compiles.
2. **Cache entries are written and read under a file lock.** Numba writes a function's cache
   as an index (signature -> data file name) and data files; two processes compiling *different*
   signatures of one function at once can both pick the data file ``...1.nbc`` for their own
   signature, and the index of one then points at the machine code of the other (numba issue
   #10128 describes the same race for GUFuncs). :func:`guard_cache` wraps Numba's
   ``IndexDataCacheFile.save`` / ``load`` in an ``fcntl.flock`` of one lock file per cache
   folder (exclusive to save, shared to load), so an index and its data files always belong
   together. Where the lock file cannot be made (a read-only install; Numba then does not
   write there either) or ``fcntl`` is missing (Windows), the calls run unguarded, as before.

The cache of a parallel function itself (called from Python) is safe across thread counts in
this Numba (issue #7518 was fixed in 0.56) and is checked across fresh processes with 1 and 2
threads by the same test.
"""

from __future__ import annotations

import contextlib
import os

from numba import njit, prange

__all__ = ["njit", "prange", "guard_cache", "cache_guarded", "LOCK_NAME"]

LOCK_NAME = "stylize3d-numba-cache.lock"
"""The lock file's name in each cache folder."""

_GUARDED = False


@contextlib.contextmanager
def _locked(folder: str, exclusive: bool):
    """An ``flock`` of ``folder/LOCK_NAME`` (exclusive or shared) while the block runs; no lock
    where one cannot be taken (no ``fcntl``, or the folder cannot hold the lock file)."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - Windows
        yield
        return
    try:
        fd = os.open(os.path.join(folder, LOCK_NAME), os.O_RDWR | os.O_CREAT, 0o666)
    except OSError:
        yield
        return
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH)
        except OSError:  # pragma: no cover - a file system without locks
            pass
        yield
    finally:
        os.close(fd)  # releases the lock


def guard_cache() -> None:
    """Wrap Numba's cache file ``save`` / ``load`` in the folder's lock (module docstring).
    Idempotent; called when this module is imported."""
    global _GUARDED
    if _GUARDED:
        return
    from numba.core import caching

    cls = caching.IndexDataCacheFile
    save, load = cls.save, cls.load

    def locked_save(self, key, data):
        with _locked(self._cache_path, exclusive=True):
            return save(self, key, data)

    def locked_load(self, key):
        with _locked(self._cache_path, exclusive=False):
            return load(self, key)

    locked_save.__wrapped__ = save
    locked_load.__wrapped__ = load
    cls.save = locked_save
    cls.load = locked_load
    _GUARDED = True


def cache_guarded() -> bool:
    """Whether :func:`guard_cache` is in place."""
    return _GUARDED


guard_cache()

