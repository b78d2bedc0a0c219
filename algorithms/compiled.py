"""The one switch for the compiled (Numba) kernels of every method, and their threads.

Kernel modules (``algorithms/deform/kernels.py``, ``algorithms/multigrid/kernels.py``,
``algorithms/render/kernels.py``, ``algorithms/mesh/_selfparam_kernels.py``) import Numba; the
methods load them lazily through a :class:`KernelModule`, so importing a method never imports
Numba, and fall back to NumPy / SciPy / PyAMG code when it returns None: Numba missing, the
environment variable ``STYLIZE3D_NUMBA=0`` (also ``false`` / ``no``), or switched off with
:meth:`KernelModule.set` (for comparisons).

Threads (issue 25). The heavy kernels exist twice, compiled from the same per-item code: a
parallel one (``@njit(parallel=True)``, a ``prange`` over fixed-size chunks of items) and a
serial one (the same chunks in a plain loop). :func:`use_threads` picks between them at each
call. Every parallel kernel is written so that each output value is computed by one thread, by
the same operations in the same order, whatever the number of threads: no ``prange``
reductions and no scatter-adds (sums over items are gathered per output, or per-item partial
results are added up afterwards in a serial loop). So the parallel and the serial kernel give
the same bits, for any thread count (tested).

* The thread count is Numba's: ``NUMBA_NUM_THREADS`` (default: ``OMP_NUM_THREADS`` where that
  is set, else the number of cores, as OpenMP's, so that a parallel launch does not change the
  thread count PyTorch then uses on that thread: :func:`_numba_threads_as_openmp`) or
  :func:`numba.set_num_threads` (per Python thread). With 1 thread the serial kernels run:
  ``NUMBA_NUM_THREADS=1`` is the single-thread code of before, without any threading layer.
* Threading layer: Numba's default choice (``tbb``, then ``omp``, then ``workqueue``). On this
  project's machines only ``omp`` (GNU OpenMP, bundled with Numba's wheel) and ``workqueue``
  are there; ``omp`` is used. It may be launched from any Python thread (the app's QThread
  workers, several at once). GNU OpenMP is not fork-safe: a process forked after the parent
  launched its threads is killed by Numba at its first parallel launch ("fork() called from a
  process already using GNU OpenMP"). :func:`use_threads` therefore answers False in such a
  child, which then runs the serial kernels (the same results). The project's own process pools
  (batch, isolated computations, training data) use "spawn", where the threads work as usual.
  GNU OpenMP's threads spin while they wait for work by default (``OMP_WAIT_POLICY`` unset):
  on a machine whose cores are busy with other processes a kernel's end-of-loop barrier then
  waits for the spinning thread's time slice, and each parallel kernel took ~10 ms instead of
  ~0.1 ms (measured at load average 11 on 2 cores: a cubic iteration 7x slower on 2 threads
  than on 1). This module therefore sets ``OMP_WAIT_POLICY=PASSIVE`` (threads sleep when idle)
  when it is imported and the variable is not set (the runtime reads it when Numba loads it);
  measured there: 2 threads as fast as 1 at that load, instead of 7x slower.
  ``workqueue`` (chosen when nothing else is there, or with ``NUMBA_THREADING_LAYER``) aborts
  when two Python threads launch kernels at the same time, so :func:`use_threads` answers True
  for it on the main thread only (other threads run the serial kernels).
"""

from __future__ import annotations

import importlib
import os
import threading
from types import ModuleType

__all__ = ["numba_wanted", "KernelModule", "use_threads", "thread_count", "threading_layer"]

# before Numba loads GNU OpenMP (see the module docstring); a value the user set is kept
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")


def _numba_threads_as_openmp() -> None:
    """Numba's thread count := ``OMP_NUM_THREADS`` when that is set and ``NUMBA_NUM_THREADS``
    is not; before Numba loads. Numba's ``omp`` layer sets
    the calling thread's OpenMP thread count to Numba's at every parallel launch, and PyTorch's
    CPU kernels use that same per-thread count: with OMP_NUM_THREADS=1 and Numba on 2 threads,
    one image derivative (``image_vjp``) on a thread made the image classifier's logits on that
    thread differ in their last bits from another thread's, and a study replay, which runs the
    logged run on another thread, reported a mismatch (issue 23, sixth pass). With the two
    counts equal, a launch leaves the count as it was. (``NUMBA_NUM_THREADS`` set alone:
    OpenMP's default becomes it, where OpenMP is not loaded yet.)"""
    if "NUMBA_NUM_THREADS" in os.environ:
        n = os.environ["NUMBA_NUM_THREADS"].strip()
        if n.isdigit() and int(n) >= 1:
            os.environ.setdefault("OMP_NUM_THREADS", n)
        return
    n = os.environ.get("OMP_NUM_THREADS", "").strip()
    if n.isdigit() and int(n) >= 1:     # neither set: both default to the number of cores
        os.environ["NUMBA_NUM_THREADS"] = n


_numba_threads_as_openmp()


def numba_wanted() -> bool:
    """False when ``STYLIZE3D_NUMBA`` is 0 / false / no (the pure Python paths are used)."""
    return os.environ.get("STYLIZE3D_NUMBA", "1").strip().lower() not in ("0", "false", "no")


class KernelModule:
    """A lazily imported kernel module that may be unavailable or switched off."""

    def __init__(self, name: str):
        self.name = name
        self._enabled: bool | None = None
        self._module: ModuleType | None = None

    def get(self) -> ModuleType | None:
        """The module, or None (see the module docstring)."""
        if self._enabled is None:
            self._enabled = numba_wanted()
        if not self._enabled:
            return None
        if self._module is None:
            try:
                self._module = importlib.import_module(self.name)
            except ImportError:
                self._enabled = False
                return None
        return self._module

    def set(self, enabled: bool) -> bool:
        """Switch the kernels on or off; returns the previous setting. Switching on where Numba
        is missing leaves them off."""
        previous = self.get() is not None
        self._enabled = bool(enabled)
        return previous


# ------------------------------------------------------------------------------ threads
_LAYER: str | None = None  # Numba's threading layer, once started
_FORKED_LAYER: str | None = None  # in a forked child: the layer the parent had started


def _after_fork_in_child() -> None:
    global _FORKED_LAYER
    import sys

    par = sys.modules.get("numba.np.ufunc.parallel")
    if par is not None and getattr(par, "_is_initialized", False):
        _FORKED_LAYER = str(getattr(par, "_threading_layer", None))


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_after_fork_in_child)


def thread_count() -> int:
    """Numba's thread count for the calling Python thread (1 where Numba is missing)."""
    try:
        import numba
    except ImportError:
        return 1
    return int(numba.get_num_threads())


def threading_layer() -> str:
    """The name of Numba's threading layer ("omp", "tbb" or "workqueue"), starting it if needed;
    "none" where Numba is missing."""
    global _LAYER
    if _LAYER is None:
        try:
            import numba
        except ImportError:
            return "none"
        from numba.np.ufunc import parallel

        parallel._launch_threads()
        _LAYER = str(numba.threading_layer())
    return _LAYER


def use_threads() -> bool:
    """True when a kernel called now should run its parallel version: Numba has more than one
    thread for the calling Python thread, and the threading layer can launch here (not in a
    process forked after its parent started GNU OpenMP; for ``workqueue``, only on the main
    thread). The parallel and serial versions give the same bits (module docstring)."""
    if thread_count() <= 1:
        return False
    layer = threading_layer()
    if layer == "omp" and _FORKED_LAYER == "omp":
        return False  # forked after the parent started GNU OpenMP: it would kill this process
    if layer == "workqueue":
        return threading.current_thread() is threading.main_thread()
    return True
