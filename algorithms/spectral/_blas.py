"""One BLAS thread around spectral coarsening's eigensolves (issue 25).

ARPACK's Lanczos work (level-2 BLAS on an n x 2k basis) and LAPACK's dense ``eigh`` of the
coarse operators call OpenBLAS many times on mid-sized data. With OpenBLAS's threads and the
machine's cores busy with other work, each call waits for a descheduled thread: measured here
(30k-vertex Laplacian, k 101, load 12 on 2 cores) ARPACK took 84 s of wall time with the
default threads and 28 s with one; a 404 x 404 ``eigh`` took 3-4 s instead of ~0.1 s. The
panel's child process already runs with one BLAS thread (``algorithms.steps.isolated_iter``);
:func:`single_blas_thread` gives an in-process run (CLI, batch, tests) the same setting for
the duration of a call, through the ``*openblas_set_num_threads*`` entry points of the OpenBLAS
libraries NumPy and SciPy loaded (found in ``/proc/self/maps``). Where none is found (another
BLAS, another OS) it does nothing.
"""

from __future__ import annotations

import contextlib
import ctypes
import threading

_LOCK = threading.Lock()
_LIBS: list | None = None


def _openblas_controls() -> list:
    """(get, set) function pairs of every loaded OpenBLAS, found once."""
    global _LIBS
    if _LIBS is not None:
        return _LIBS
    found = []
    try:
        import numpy  # noqa: F401 - make sure the libraries are loaded
        import scipy.linalg  # noqa: F401

        with open("/proc/self/maps") as fh:
            paths = sorted({line.split()[-1] for line in fh
                            if "openblas" in line.lower() and line.split()[-1].startswith("/")})
    except OSError:
        paths = []
    for path in paths:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for prefix in ("scipy_openblas", "openblas"):
            for suffix in ("64_", ""):
                try:
                    get = getattr(lib, f"{prefix}_get_num_threads{suffix}")
                    set_ = getattr(lib, f"{prefix}_set_num_threads{suffix}")
                except AttributeError:
                    continue
                get.restype = ctypes.c_int
                set_.argtypes = [ctypes.c_int]
                found.append((get, set_))
                break
            else:
                continue
            break
    _LIBS = found
    return found


@contextlib.contextmanager
def single_blas_thread():
    """Run the block with one OpenBLAS thread, then restore the previous counts."""
    controls = _openblas_controls()
    with _LOCK:
        previous = []
        for get, set_ in controls:
            try:
                previous.append((set_, int(get())))
                set_(1)
            except Exception:  # noqa: BLE001 - a library that refuses: leave it as it is
                continue
    try:
        yield
    finally:
        with _LOCK:
            for set_, count in previous:
                try:
                    set_(count)
                except Exception:  # noqa: BLE001
                    pass
