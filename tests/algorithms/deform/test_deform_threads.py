"""Issue 25: the deform kernels on Numba's threads give the same bits for any thread count.

Every parallel kernel computes each output value in one thread, by the same operations in the
same order as the serial kernel (see :mod:`algorithms.compiled`), so 1 and 2 threads agree bit
for bit, and two runs with 2 threads too. The runs happen in child processes started with
``NUMBA_NUM_THREADS`` set (the variable is read when Numba starts), plus a check in this process
with :func:`numba.set_num_threads`, one from a non-main Python thread (the app's workers) and
one in a process forked after the threads were started (GNU OpenMP would kill it: the serial
kernels run there).
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from algorithms import compiled
from algorithms.deform import arap

ROOT = Path(__file__).resolve().parents[3]

pytestmark = pytest.mark.skipif(arap.compiled_kernels() is None,
                                reason="compiled kernels unavailable or switched off")

CHILD = r"""
import hashlib, sys
import numpy as np
sys.path.insert(0, sys.argv[1])
from algorithms import compiled
from algorithms.deform.cubic import CubicParams, CubicStylizer
from algorithms.mesh import icosphere
V, F = icosphere(3)
V = V * (1.0 + 0.1 * np.random.default_rng(3).standard_normal((len(V), 1)))
steps = list(CubicStylizer(V, F).steps(CubicParams(lam=0.4, max_iterations=12,
                                                   rel_displacement_tol=0.0)))
h = hashlib.sha256()
for s in steps:
    h.update(s.V.tobytes())
    h.update(np.float64(s.metrics["energy"]).tobytes())
print(compiled.thread_count(), compiled.use_threads(), h.hexdigest())
"""


def run_child(threads: int) -> tuple[str, str, str]:
    env = dict(os.environ, NUMBA_NUM_THREADS=str(threads))
    out = subprocess.run([sys.executable, "-c", CHILD, str(ROOT)], env=env, capture_output=True,
                         text=True, timeout=600, cwd=ROOT)
    assert out.returncode == 0, out.stderr[-3000:]
    return tuple(out.stdout.split()[-3:])


def test_cubic_runs_give_the_same_bits_for_one_and_two_threads():
    one = run_child(1)
    two_a = run_child(2)
    two_b = run_child(2)
    assert one[:2] == ("1", "False")  # one thread: the serial kernels
    assert two_a[:2] == ("2", "True")  # two threads: the parallel kernels
    assert two_a[2] == two_b[2]  # same bits twice with two threads
    assert one[2] == two_a[2]  # and the same bits as with one thread


def kernel_outputs():
    """Every parallel deform kernel on a 20k-vertex-sized random problem (several chunks and
    Jacobi blocks); returns the outputs as bytes."""
    from algorithms.deform.cubic import AdmmState, CubicParams, CubicStylizer, admm_local_step
    from algorithms.mesh import icosphere

    V, F = icosphere(5)  # 10242 vertices: 20 chunks, 81 blocks
    V = V * (1.0 + 0.05 * np.random.default_rng(1).standard_normal((len(V), 1)))
    st = CubicStylizer(V, F)
    system = st.system
    U = st.V_normalized + 1e-3 * np.random.default_rng(2).standard_normal(V.shape)
    p = CubicParams(lam=0.3)
    S = system.covariances(U)
    state = AdmmState.initial(st.n, p.rho0)
    R, it = admm_local_step(S, st.normals, p.lam * st.areas, st.style_prox(p), state, p)
    kern = arap.compiled_kernels()
    out = [S, R, it, state.z, state.u, state.rho, system.rhs(R),
           arap.procrustes_rotations(S),
           np.array(system.energy(U, R, exact=False, covariances=S)),
           np.array(kern.cube_l1_energy(R, st.normals, None, np.ones(3), p.lam * st.areas)),
           np.array(arap.relative_displacement(U, st.V_normalized, st.V_normalized))]
    return [np.ascontiguousarray(a).tobytes() for a in out]


def test_kernels_same_bits_with_set_num_threads_and_from_a_worker_thread():
    import numba

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("Numba has one thread here (NUMBA_NUM_THREADS=1)")
    previous = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        assert not compiled.use_threads()
        serial = kernel_outputs()
    finally:
        numba.set_num_threads(previous)
    numba.set_num_threads(2)
    try:
        assert compiled.use_threads()
        parallel = kernel_outputs()
    finally:
        numba.set_num_threads(previous)
    assert serial == parallel

    # the same kernels from a non-main Python thread (the app runs jobs on QThreads), two at once
    results, errors = {}, []

    def work(k):
        try:
            numba.set_num_threads(2)  # per Python thread
            results[k] = (compiled.use_threads(), kernel_outputs())
        except Exception as e:  # pragma: no cover - reported below
            errors.append(e)

    threads = [threading.Thread(target=work, args=(k,)) for k in range(2)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(600)
    assert not errors, errors
    if compiled.threading_layer() != "workqueue":
        assert results[0][0] and results[1][0]
    assert results[0][1] == serial and results[1][1] == serial


@pytest.mark.skipif(not hasattr(os, "fork"), reason="no fork here")
def test_a_forked_child_runs_the_serial_kernels():
    """After this process started Numba's threads, a forked child must not launch GNU OpenMP
    threads (Numba would kill it); it runs the serial kernels and gets the same bits."""
    from algorithms.deform.cubic import CubicParams, CubicStylizer
    from algorithms.mesh import icosphere

    V, F = icosphere(3)
    st = CubicStylizer(V, F)
    p = CubicParams(max_iterations=5, rel_displacement_tol=0.0)
    ref = hashlib.sha256(list(st.steps(p))[-1].V.tobytes()).hexdigest()
    compiled.threading_layer()  # the threads are started
    r, w = os.pipe()
    pid = os.fork()
    if pid == 0:  # pragma: no cover - the child
        code = 1
        try:
            os.close(r)
            h = hashlib.sha256(list(st.steps(p))[-1].V.tobytes()).hexdigest()
            os.write(w, f"{compiled.use_threads()} {h}".encode())
            code = 0
        finally:
            os._exit(code)
    os.close(w)
    with os.fdopen(r) as fh:
        got = fh.read()
    _, status = os.waitpid(pid, 0)
    assert os.WIFEXITED(status) and os.WEXITSTATUS(status) == 0, status
    use, h = got.split()
    if compiled.threading_layer() == "omp":
        assert use == "False"
    assert h == ref


def test_numpy_path_matches_the_threaded_kernels():
    """The NumPy fallback (kernels off) gives the same result to round-off."""
    from algorithms.deform.cubic import CubicParams, CubicStylizer
    from algorithms.mesh import icosphere

    V, F = icosphere(3)
    st = CubicStylizer(V, F)
    p = CubicParams(lam=0.4, max_iterations=6, rel_displacement_tol=0.0)
    ours = list(st.steps(p))
    previous = arap.set_compiled_kernels(False)
    try:
        ref = list(st.steps(p))
    finally:
        arap.set_compiled_kernels(previous)
    for a, b in zip(ours, ref):
        np.testing.assert_allclose(a.V, b.V, rtol=0, atol=1e-9)
        assert a.metrics["energy"] == pytest.approx(b.metrics["energy"], rel=1e-9)
        assert a.metrics["l1"] == pytest.approx(b.metrics["l1"], rel=1e-12)
