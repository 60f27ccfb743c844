"""Two-way (n-way) parallel execution of a solve on a small machine.

A solve alternates dense products with ``A`` (BLAS) and element-wise NumPy work (the TV
prox). OpenBLAS parallelises the former but not the latter, and its worker threads busy-wait
after every product, so a second thread of ours doing element-wise work in the meantime
competes with a spinning BLAS thread instead of using the idle core (measured on 2 cores: a
2-thread TV prox gained nothing next to 2-thread BLAS, and 1.7x next to 1-thread BLAS).

:func:`parallel` therefore holds BLAS to one thread (``threadpoolctl``) and provides a pool of
our own threads instead: inside it, :class:`~spslidar.operators.MatrixOperator` splits large
products into ``MATMUL_BANDS`` bands of output rows shared out among the threads (one
single-threaded BLAS call per band, measured as fast as OpenBLAS' own threading for these
shapes; a fixed number of bands, so the same numbers whatever the threads), and the TV prox runs its
two row bands concurrently. Outside it nothing changes. The solvers enter it for large
problems (:meth:`spslidar.solvers.Solver.solve`).
"""

from __future__ import annotations

import contextvars
import functools
import os
import threading
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..capture import carried

__all__ = [
    "ParallelContext", "available_cpus", "banded_matmul", "current", "one_blas_thread",
    "parallel", "row_bands",
    "run_parts", "sum_parts",
]

#: at most this many threads
MAX_THREADS = 4
#: large products are computed in this many bands of output rows whatever the threads (each
#: band one single-threaded BLAS call): a float32 product rounds differently in other bands,
#: so bands that followed the threads made a run's numbers depend on the CPUs it was given
#: (``taskset -c 0``: a GPSR run 0.0329 -> 0.0309 m, every solver's iterates; an audit of
#: 2026-11-28)
MATMUL_BANDS = 4
#: products with fewer multiply-adds than this run in one BLAS call
SPLIT_MIN_WORK = 1 << 21
#: element-wise work on arrays with at least this many entries is done in two row bands
BAND_MIN_SIZE = 1 << 17

_CURRENT: contextvars.ContextVar[ParallelContext | None] = contextvars.ContextVar(
    "spslidar_parallel", default=None
)


def available_cpus() -> int:
    """CPUs this process may run on (its affinity mask where the platform has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - non-Linux
        return os.cpu_count() or 1


@dataclass
class ParallelContext:
    """The active parallel context: ``threads`` threads, of which ``threads - 1`` in ``pool``
    (the calling thread is the other one)."""

    threads: int
    pool: ThreadPoolExecutor

    def matmul(self, M: np.ndarray, x: np.ndarray) -> np.ndarray:
        """``M @ x`` computed as :func:`banded_matmul`'s bands of rows of ``M``, shared out
        among the threads (thread ``j`` takes bands ``j, j + threads, ...``).

        Parameters
        ----------
        M : ndarray, shape (m, n)
        x : ndarray, shape (n, k)

        Returns
        -------
        ndarray, shape (m, k)
        """
        return banded_matmul(M, x, self)


def banded_matmul(M: np.ndarray, x: np.ndarray,
                  ctx: ParallelContext | None = None) -> np.ndarray:
    """``M @ x`` as ``MATMUL_BANDS`` bands of rows of ``M``, each one BLAS call: the same
    numbers whatever the threads (``ctx``'s, which share the bands out; none: one after the
    other)."""
    m = M.shape[0]
    out = np.empty((m, x.shape[1]), dtype=np.result_type(M.dtype, x.dtype))
    edges = np.linspace(0, m, MATMUL_BANDS + 1).astype(int)
    bands = [(a, b) for a, b in zip(edges[:-1], edges[1:], strict=True) if b > a]

    def work(j: int, step: int) -> None:
        for a, b in bands[j::step]:
            np.matmul(M[a:b], x, out=out[a:b])

    step = 1 if ctx is None else max(1, min(ctx.threads, len(bands)))
    futures = ([ctx.pool.submit(carried(work), j, step) for j in range(1, step)] if ctx
               else [])
    try:
        work(0, step)
    finally:
        for f in futures:
            f.result()
    return out


def current() -> ParallelContext | None:
    """The parallel context active in this thread, or ``None``."""
    return _CURRENT.get()


def row_bands(n_rows: int, size: int) -> list[tuple[int, int]]:
    """Row bands ``[(a, b), ...]`` for element-wise work on an array of ``size`` entries with
    ``n_rows`` rows: two halves from :data:`BAND_MIN_SIZE` entries on, else one band. Fixed by
    the shape alone, so per-band partial sums add up the same way whatever the threads."""
    if n_rows >= 2 and size >= BAND_MIN_SIZE:
        h = n_rows // 2
        return [(0, h), (h, n_rows)]
    return [(0, n_rows)]


def run_parts(fn, n_parts: int) -> list:
    """``[fn(0), ..., fn(n_parts - 1)]``, run concurrently on the threads of the active
    context (``fn(0)`` in the calling thread), else one after the other."""
    ctx = current()
    if ctx is None or n_parts < 2:
        return [fn(i) for i in range(n_parts)]
    futures = [ctx.pool.submit(carried(fn), i) for i in range(1, n_parts)]
    try:
        first = fn(0)
    finally:
        results = [f.result() for f in futures]
    return [first, *results]


def sum_parts(parts: list) -> list:
    """Add the per-band tuples of partial sums that :func:`run_parts` returned, element by
    element and in band order (so the totals do not depend on the threads)."""
    return [sum(p[j] for p in parts) for j in range(len(parts[0]))]


#: the one thread that sets and restores BLAS's limit (see :func:`_single_threaded_blas`)
_SETTER: list[ThreadPoolExecutor] = []
#: whether the "BLAS not held" warning was given in this process
_WARNED: list[bool] = []


def _on_setter(fn):
    """``fn()`` run on the module's own setter thread (started on first use)."""
    if not _SETTER:
        _SETTER.append(ThreadPoolExecutor(1, thread_name_prefix="spslidar-blas"))
    return _SETTER[0].submit(fn).result()


def _single_threaded_blas() -> Any:
    """BLAS's limit set to one thread, from the module's own setter thread, or ``None``
    without ``threadpoolctl``.

    OpenBLAS (pthreads) ignores ``openblas_set_num_threads`` called from any other thread
    once the main thread has called it: a run in a worker thread after one in the main
    thread had BLAS on every core, and gave other numbers than the same run alone (24 of 24
    configurations' slices, 9 of 24 depth maps, up to 3 m on 8 pixels), and concurrent runs
    left BLAS on one thread for good in 3 of 5 processes (an outside audit of 2026-11-30;
    threadpoolctl's issue #205). Set and restored from one thread of ours, never the
    caller's, the limit holds whichever thread runs. Where it still does not (the main thread
    set it through threadpoolctl itself), one warning says so."""
    try:
        from threadpoolctl import threadpool_info, threadpool_limits
    except ImportError:  # pragma: no cover - threadpoolctl is optional
        return None

    def limit():
        lim = threadpool_limits(limits=1, user_api="blas")
        held = all(i["num_threads"] == 1 for i in threadpool_info() if i["user_api"] == "blas")
        return lim, held

    lim, held = _on_setter(limit)
    if not held and not _WARNED:
        import warnings

        _WARNED.append(True)
        warnings.warn("BLAS could not be held to one thread (OpenBLAS ignores a limit set "
                      "from another thread once the main thread has set one, e.g. through "
                      "threadpoolctl): products may round differently from a run alone; set "
                      "OPENBLAS_NUM_THREADS=1 before importing numpy to make them equal",
                      RuntimeWarning, stacklevel=1)
    return lim


_BLAS_LOCK = threading.Lock()
_BLAS: dict[str, Any] = {"depth": 0, "limits": None}


def _after_fork_in_child() -> None:
    """A forked child has none of its parent's threads: the setter thread's executor
    believed it had one idle and a child's first run waited for it forever (``fork`` pools
    of multiprocessing, Linux's default before Python 3.14: a review of 2026-11-30); the
    child starts its own, with nothing held."""
    global _BLAS_LOCK
    _SETTER.clear()
    _BLAS_LOCK = threading.Lock()
    _BLAS.update(depth=0, limits=None)


if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_after_fork_in_child)


@contextmanager
def _blas_held():
    """BLAS held to one thread while any thread of this process is inside (yields whether it
    is: False without ``threadpoolctl``). The limit is process-wide, so it is set by the
    first thread to enter and restored by the last to leave: each thread setting and
    restoring its own left BLAS on one thread for good after runs in a thread pool, and let
    one run's products go multi-threaded while another's entry had set one (an audit of
    2026-11-29: seed 3 at 32x32 then differed from its sequential run by 12 % in its slices)."""
    with _BLAS_LOCK:
        if _BLAS["depth"] == 0:
            _BLAS["limits"] = _single_threaded_blas()
        _BLAS["depth"] += 1
        held = _BLAS["limits"] is not None
    try:
        yield held
    finally:
        with _BLAS_LOCK:
            _BLAS["depth"] -= 1
            if _BLAS["depth"] == 0 and _BLAS["limits"] is not None:
                _on_setter(_BLAS["limits"].restore_original_limits)
                _BLAS["limits"] = None
                # (the idle setter thread kept the process multi-threaded between runs, and
                # Python 3.12+ warns at every fork() after one: an audit of 2026-11-30; the
                # next hold starts its own, on which it both sets and restores)
                _SETTER.pop().shutdown(wait=True)


def one_blas_thread(fn):
    """Run ``fn`` with BLAS on one thread (a decorator), so that its results do not depend on
    how many threads BLAS may use.

    A float32 product on two BLAS threads rounds differently from one on one thread: a sweep
    run in-process (BLAS on every core) and in ``--jobs 2`` workers (one thread each, as
    joblib gives them) differed on 12 of 40 points at 16x16 (RMSE up to 0.4 %, a point's
    noise level at 1e-11), and ``run`` could differ from the sweep row of its seed. What needs
    threads takes them from :func:`parallel` (BLAS on one thread there too); the rest is small
    beside the solve: on 2 cores the default run, a 64x64 TVAL3 run and a 128x128 Hadamard run
    took 0.95 / 10.1 / 6.1 s against 1.10 / 9.3 / 7.4 s with BLAS on both (2026-11-28).
    """
    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with _blas_held():
            return fn(*args, **kwargs)
    return wrapper


@contextmanager
def parallel(threads: int | None = None):
    """Run the enclosed solve on ``threads`` threads of our own, BLAS on one thread.

    Parameters
    ----------
    threads : int, optional
        Default: the CPUs available. At most :data:`MAX_THREADS` (4) in any case: a larger
        number given runs that many. With one thread, BLAS is
        held to one thread and nothing else changes (the same numbers as on several); without
        ``threadpoolctl`` (which is needed to hold BLAS to one thread), nothing changes.

    Yields
    ------
    ParallelContext or None
        The active context (an enclosing one is reused).

    Notes
    -----
    The BLAS thread limit is process-wide while the context is active (as in the simulation
    stage of :mod:`spslidar.pipeline`): other threads' BLAS calls run on one thread meanwhile,
    and it is restored when the last thread inside leaves.
    """
    ctx = current()
    n = available_cpus() if threads is None else int(threads)
    n = min(n, MAX_THREADS)
    if ctx is not None:
        yield ctx
        return
    with _blas_held() as held:
        if not held:  # pragma: no cover - threadpoolctl is a dependency
            yield None
            return
        if n < 2:  # BLAS on one thread too: a float32 product on several rounds otherwise
            yield None
            return
        with ThreadPoolExecutor(n - 1, thread_name_prefix="spslidar") as pool:
            ctx = ParallelContext(n, pool)
            token = _CURRENT.set(ctx)
            try:
                yield ctx
            finally:
                _CURRENT.reset(token)
