"""The problem-agnostic solver interface shared by FISTA, TwIST, TVAL3 and GPSR.

Solvers see a :class:`~spslidar.operators.LinearOperator` ``A``, data ``y`` of shape ``(m, K)``
(or ``(m,)``), a regulariser ``reg`` (an object with ``__call__`` and ``prox``, see
:mod:`spslidar.solvers.regularisers`) and its weight ``lam``; they return ``x`` of shape
``(n, K)`` and a :class:`SolveInfo`. They never know about lidar. Every solver minimises

    F(x) = 1/2 ||A x - y||_2^2 + lam * R(x)                                    (eq. 18)

over the whole block of K columns at once (the sum over columns of the per-column objective),
unless its docstring says it solves an equivalent constrained form.

Solvers are step-wise (:class:`Solver`: ``setup`` / ``step`` / ``done`` / ``run`` / ``finish``,
as PyLops' ``basesolver`` and SigPy's ``Alg``), with callbacks after every iteration
(:func:`progress`). They are looked up by name in :data:`spslidar.solvers.SOLVERS`
(:func:`get_solver`, :func:`solve`), which imports a solver's module on first use.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, TextIO

import numpy as np

from ..arrays import real_scalar
from ..errors import ConfigError
from ..operators.base import LinearOperator
from ..operators.parallel import parallel


def as_operator(A: Any) -> Any:
    """``A`` as the solvers take it: a :class:`~spslidar.operators.LinearOperator` (or an
    object with ``shape``, ``matvec`` and ``rmatvec``) as it is, an ndarray as a
    :class:`~spslidar.operators.MatrixOperator` sharing it; anything else a one-line
    :class:`~spslidar.errors.ConfigError` naming ``A`` (a list was an ``AttributeError``: an
    audit of 2026-12-02)."""
    if isinstance(A, np.ndarray):  # (a matrix: an AttributeError on 'rmatvec', an audit)
        from ..operators import MatrixOperator

        return MatrixOperator(A, copy=False)  # (for this solve only)
    if not (hasattr(A, "shape") and callable(getattr(A, "matvec", None))
            and callable(getattr(A, "rmatvec", None))):
        raise ConfigError(f"A must be a LinearOperator (spslidar.operators) or an (m, n) "
                          f"ndarray, got {type(A).__name__}")
    return A


@dataclass
class StopRule:
    """Stopping rules shared by all solvers; the first one met stops the iteration.

    Parameters
    ----------
    max_iter : int
        Maximum number of iterations.
    rtol : float
        Stop when ``||x_k - x_{k-1}|| <= rtol * ||x_k||`` (relative change of the iterate).
    obj_rtol : float or None
        Stop when the relative decrease of the objective over one iteration falls below this.
        A solver that rejects steps (TwIST, FISTA with ``monotone``, GPSR's non-monotone
        variant, and GPSR with continuation, whose rule waits for its last stage) records
        the objective again unchanged after a rejected step, which this rule reads as no
        decrease: it stopped GPSR at iteration 37, 2.5 % above its optimum
        (an outside audit). Use ``rtol`` with those. (Skipping repeated objectives instead
        kept an exact fit, whose objective stays 0, running to ``max_iter``: a review.)
    target : float or None
        Stop as soon as the objective is at or below this value (used by benchmarks to time
        solvers to the same objective).
    max_time : float or None
        Stop after this many seconds of wall time.
    """

    max_iter: int = 200
    rtol: float = 1e-4
    obj_rtol: float | None = None
    target: float | None = None
    max_time: float | None = None

    def __post_init__(self):
        if (isinstance(self.max_iter, bool) or not isinstance(self.max_iter, (int, np.integer))
                or self.max_iter < 1):  # (5.5 was taken, an audit)
            raise ValueError(f"max_iter must be a whole number >= 1, got {self.max_iter!r}")
        self.max_iter = int(self.max_iter)
        # (NaN was taken; a string failed in a comparison naming no field: audits). Checked,
        # not cast: a NumPy scalar tolerance computes as it did
        real_scalar(self.rtol, "rtol", low=0.0)
        if self.obj_rtol is not None:
            real_scalar(self.obj_rtol, "obj_rtol", low=0.0)
        if self.target is not None:
            real_scalar(self.target, "target", low=-np.inf)
        if self.max_time is not None:
            real_scalar(self.max_time, "max_time", low=0.0)


@dataclass
class SolveInfo:
    """What a solver reports besides its solution."""

    solver: str
    iterations: int = 0
    objective: list[float] = field(default_factory=list)
    stop_reason: str = ""
    time_s: float = 0.0
    extra: dict[str, Any] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """The record as plain JSON values (what ``metrics.json`` holds under ``solver``)."""
        return {
            "solver": self.solver,
            "iterations": self.iterations,
            "final_objective": self.objective[-1] if self.objective else None,
            "stop_reason": self.stop_reason,
            "time_s": self.time_s,
            **self.extra,
        }


class Monitor:
    """Book-keeping of one solve: objective history, timing and the stop test.

    Solvers call :meth:`check` once per iteration with the new and previous iterates and the
    current objective value (``None`` when they do not compute it every iteration); it returns
    the reason to stop or ``''``.
    """

    def __init__(self, name: str, stop: StopRule):
        self.stop = stop
        self.info = SolveInfo(solver=name)
        self.t0 = time.perf_counter()

    def check(
        self,
        it: int,
        x: np.ndarray,
        x_old: np.ndarray | None,
        obj: float | None,
        step: np.ndarray | None = None,
        step_norm: float | None = None,
        final: bool = True,
    ) -> str:
        """Record iteration ``it`` and return the reason to stop (``''`` to go on).

        The change test of ``StopRule.rtol`` applies when ``x_old`` or ``step_norm`` is
        given. ``step``, when given, is ``x - x_old`` already formed by the solver, and
        ``step_norm`` its norm (each saves a pass over the iterate). ``final`` False (a
        continuation stage before the last, whose objective is not yet the one minimised)
        records the objective without the ``obj_rtol`` test (GPSR's kept best objective
        repeats in early stages, which ``obj_rtol`` read as converged: it stopped at 3.5-6
        times the optimum, a review); ``target`` still applies, the objective being ``F``
        at the final weight in every stage.
        """
        info, stop = self.info, self.stop
        info.iterations = it
        if obj is not None:
            prev = info.objective[-1] if info.objective else None
            info.objective.append(float(obj))
            if not np.isfinite(obj):
                return "diverged"
            if stop.target is not None and obj <= stop.target:
                return "target"
            if final and stop.obj_rtol is not None and prev is not None and it > 1:
                if abs(prev - obj) <= stop.obj_rtol * max(abs(obj), 1e-300):
                    return "obj_rtol"
        if (x_old is not None or step_norm is not None) and stop.rtol > 0 and it > 1:
            if step_norm is not None:
                dx = float(step_norm)
            else:
                dx = _norm(step if step is not None else x - x_old)
            if dx <= stop.rtol * max(_norm(x), 1e-300):
                return "rtol"
        return self.limit(it)

    def limit(self, it: int) -> str:
        """The reason to stop at iteration ``it`` by the rules that need no iterate:
        ``"max_time"``, ``"max_iter"`` or ``''`` (:meth:`check`'s last rules; a solver's
        :meth:`Solver.step` applies them too where ``_step`` never asks)."""
        stop = self.stop
        if stop.max_time is not None and time.perf_counter() - self.t0 >= stop.max_time:
            return "max_time"
        if it >= stop.max_iter:
            return "max_iter"
        return ""

    def finish(self, reason: str) -> SolveInfo:
        self.info.stop_reason = reason or "max_iter"
        self.info.time_s = time.perf_counter() - self.t0
        return self.info


def _norm(a: np.ndarray) -> float:
    """Euclidean norm of a whole array.

    float32 through BLAS ``sdot`` (its float32 accumulation is ample for the relative tests of
    :class:`StopRule`, and four times faster than accumulating in float64), anything else
    accumulated in float64 without BLAS (whose threaded float64 dot product is
    pathologically slow under load on small machines).
    """
    a = np.asarray(a)
    if a.dtype == np.float32:
        a = a.ravel()  # a copy only for non-contiguous input
        return float(np.sqrt(max(float(np.dot(a, a)), 0.0)))
    a = a.ravel()
    return float(np.sqrt(np.einsum("i,i->", a, a, dtype=np.float64)))


def col_dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Per-column inner products ``<a[:, k], b[:, k]>`` of two ``(n, K)`` blocks, accumulated
    in float64 (the solvers' step sizes, line searches and objectives)."""
    return np.einsum("ik,ik->k", a, b, dtype=np.float64)


def col_sum(a: np.ndarray) -> np.ndarray:
    """Per-column sums of an ``(n, K)`` block, accumulated in float64."""
    return np.einsum("ik->k", a, dtype=np.float64)


def _axpy(x: np.ndarray, y: np.ndarray, a) -> None:
    """In place ``y += a * x``."""
    if a == 0:
        return
    y += y.dtype.type(a) * x


def as_block(y: np.ndarray) -> tuple[np.ndarray, bool]:
    """Return ``y`` as a 2-D ``(m, K)`` block and whether it was 1-D."""
    y = np.asarray(y)
    if y.ndim == 1:
        return y[:, None], True
    if y.ndim != 2:
        raise ValueError(f"expected a 1-D (n,) or 2-D (n, K) array, got shape {y.shape}")
    return y, False


def data_misfit(A, x: np.ndarray, y: np.ndarray) -> float:
    """``1/2 ||A x - y||^2`` summed over all columns."""
    r = A.matvec(x) - y
    return 0.5 * float(np.vdot(r, r).real)


Callback = Callable[["Solver"], Any]


class Solver:
    """Base class of the step-wise solvers: ``setup`` / ``step`` / ``run`` / ``finish``.

    In the style of PyLops' ``optimization.basesolver.Solver`` and SigPy's ``alg.Alg``, a
    solve is ``setup(A, y, reg, lam, x0)`` (state, first objective), then :meth:`step` (one
    iteration) until :meth:`done` (a rule of the :class:`StopRule` met, judged by the
    :class:`Monitor` at the end of every step), then :meth:`finish`, which returns
    ``(x, info)``. :meth:`solve` does all of it in one call, inside the parallel context of
    large problems, with optional callbacks after every iteration::

        x, info = FISTA(stop=StopRule(60)).solve(A, y, reg, lam, callback=progress(10))

        s = FISTA(stop=StopRule(60))       # the same, driven by hand
        s.setup(A, y, reg, lam)
        while not s.done():
            s.step()
            print(s.it, s.info.objective[-1])
        x, info = s.finish()

    Subclasses set :attr:`name` and implement :meth:`_setup`, :meth:`_step` (one iteration,
    returning the stop reason of :meth:`Monitor.check`) and :meth:`_finish`; their state
    lives in attributes between steps, so an instance serves one solve at a time (not to be
    shared between threads; a new :meth:`setup` starts afresh). The pipeline's defaults are
    the class attributes ``default_iterations``, ``default_lam_scale`` and
    ``default_regulariser`` (for the in-tree solvers read from their registry entries).

    Driving by hand gives the iterates of :meth:`solve` bitwise for problems below
    :attr:`PARALLEL_MIN_WORK`; above it, enter ``with s.parallel_context(A, y):`` around
    ``setup`` ... ``finish`` as :meth:`solve` does (:meth:`run` enters it for the iterations
    only).

    Parameters
    ----------
    stop : StopRule, optional
    threads : int, optional
        Threads for large problems (``A.shape[0] * A.shape[1] * K >=``
        :attr:`PARALLEL_MIN_WORK`): the solve then runs inside
        :func:`spslidar.operators.parallel.parallel` (BLAS on one thread, dense products and
        the TV prox split over our own threads). Default: the CPUs available; at most 4 in
        any case (``info.extra['threads']`` says how many ran); ``1`` leaves BLAS alone.
        The iterates do not depend on it.
    **options
        Solver-specific options (documented on each subclass).

    Attributes
    ----------
    A, y, reg, lam
        The problem of the current solve (``y`` as an ``(m, K)`` block in the working dtype).
    it : int
        Iterations done so far.
    reason : str
        Why the iteration stopped (``''`` while it goes on).
    monitor : Monitor or None
        Book-keeping of the current solve (``None`` before :meth:`setup`).
    """

    name = "base"
    #: iteration cap of the pipeline (``--iterations``) when the config leaves it unset
    default_iterations: int = 100
    #: multiplies the data-derived regularisation weight (see ``spslidar.pipeline``)
    default_lam_scale: float = 0.3
    #: the regulariser that ``--regulariser auto`` picks (``tv``, ``tv-aniso``, ``l1`` or
    #: ``wavelet``)
    default_regulariser: str = "tv"
    #: multiply-adds of one product with the whole block above which the solve is parallel
    PARALLEL_MIN_WORK = 1 << 24

    def __init__(self, stop: StopRule | None = None, threads: int | None = None, **options):
        self.stop = stop if stop is not None else StopRule()
        if threads is not None:  # (1.5 was taken as 1: an audit of 2026-12-02)
            from ..arrays import positive_number

            threads = positive_number(threads, "threads", integer=True)
        self.threads = threads
        self.options = options
        self.monitor: Monitor | None = None
        self.it = 0
        self.reason = ""
        self._was_1d = False
        self._threads_used = 1

    # -- the step-wise interface -----------------------------------------------------------
    def setup(self, A: LinearOperator, y: np.ndarray, reg, lam: float,
              x0: np.ndarray | None = None) -> None:
        """Check the problem, reset ``reg``'s state and initialise the iteration.

        Parameters
        ----------
        A : LinearOperator
            Shape ``(m, n)``.
        y : ndarray, shape (m,) or (m, K)
        reg : Regulariser
            Its :meth:`~spslidar.solvers.regularisers.Regulariser.reset` is called first, so a
            regulariser reused from an earlier solve starts from scratch (no warm start).
        lam : float
            Non-negative weight.
        x0 : ndarray, shape (n,) or (n, K), optional
            Starting point (default zeros); one column starts every column of ``y`` there.
        """
        # (NaN returned NaN, inf a ZeroDivisionError in TVAL3, a string or None a comparison's
        # TypeError: audits)
        real_scalar(lam, "lam", low=0.0, finite=True)
        A = as_operator(A)
        if not callable(getattr(reg, "prox", None)):
            # (None: "'NoneType' object has no attribute 'values'", an audit of 2026-11-29)
            raise ValueError(f"reg must be a regulariser (with a prox: "
                             f"spslidar.solvers.regularisers' TV, L1, Zero...), got {reg!r}")
        yb, self._was_1d = as_block(y)
        if np.iscomplexobj(yb) or yb.dtype.kind not in "biuf":
            # (complex data were cast to their real part with numpy's warning: an audit)
            raise ValueError(f"the data y must be real numbers, got dtype {yb.dtype}")
        if not yb.size:  # (a reshape or index error inside the iteration: an audit)
            raise ValueError(f"the data y are empty (shape {np.shape(y)}): nothing to solve")
        if not np.isfinite(yb).all():  # (an all-NaN estimate came back, an audit)
            raise ValueError("the data y hold a NaN or an infinity")
        if yb.shape[0] != A.shape[0]:
            raise ValueError(f"data has {yb.shape[0]} rows, operator expects {A.shape[0]}")
        if x0 is not None:
            x0, _ = as_block(x0)
            if np.iscomplexobj(x0) or x0.dtype.kind not in "biuf":
                # (a complex x0 was cast to its real part with numpy's warning: an audit)
                raise ValueError(f"x0 must be real numbers, got dtype {x0.dtype}")
            if x0.shape[0] != A.shape[1] or x0.shape[1] not in (1, yb.shape[1]):
                raise ValueError(f"x0 of shape {np.shape(x0)} for {A.shape[1]} unknowns and "
                                 f"{yb.shape[1]} column(s): give ({A.shape[1]},) or "
                                 f"({A.shape[1]}, {yb.shape[1]})")
            if not np.isfinite(x0).all():
                raise ValueError("x0 holds a NaN or an infinity")
        reset = getattr(reg, "reset", None)
        if callable(reset):
            reset()
        self.A, self.y, self.reg, self.lam = A, yb, reg, float(lam)
        self.monitor = Monitor(self.name, self.stop)
        self.it = 0
        self.reason = ""
        self._threads_used = 1
        self._setup(A, yb, reg, float(lam), x0)

    def step(self) -> None:
        """One iteration (the monitor then records it and decides whether to stop)."""
        if self.monitor is None:
            raise RuntimeError(f"{type(self).__name__}.step() before setup()")
        self.it += 1
        reason = self._step()
        if not isinstance(reason, str):
            # (a plugin's _step without its return ran forever under --iterations and
            # --max-time alike: an outside audit of 2026-12-01)
            raise ConfigError(f"the solver {self.name!r} ({type(self).__module__}."
                              f"{type(self).__qualname__}): its _step() returned {reason!r}, "
                              f"where it must return self.monitor.check(...)'s reason to stop "
                              f"('' to go on)")
        # (a _step that never asks the monitor still stops at the cap and the time limit)
        self.reason = reason or self.monitor.limit(self.it)

    def done(self) -> bool:
        """Whether a stopping rule has been met (see :class:`StopRule`)."""
        return bool(self.reason)

    def run(self, callback: Callback | Sequence[Callback] | None = None) -> None:
        """Step until :meth:`done`, calling ``callback(self)`` after every iteration.

        Runs inside the parallel context of large problems (the enclosing one within
        :meth:`solve`).

        Parameters
        ----------
        callback : callable or sequence of callables, optional
            Each is called as ``callback(solver)`` once per iteration, after the monitor has
            recorded it (``solver.it``, ``solver.x``, ``solver.info.objective[-1]``); see
            :func:`progress`. Callbacks must not modify the solver's arrays.
        """
        if self.monitor is None:
            raise RuntimeError(f"{type(self).__name__}.run() before setup()")
        cbs = _callbacks(callback)
        with self.parallel_context(self.A, self.y) as ctx:
            self._threads_used = ctx.threads if ctx is not None else 1
            while not self.done():
                self.step()
                for cb in cbs:
                    cb(self)

    def finish(self) -> tuple[np.ndarray, SolveInfo]:
        """Final work (e.g. GPSR's debiasing) and the result ``(x, info)``.

        ``x`` is shaped like ``A.H @ y``; ``info.stop_reason`` is ``'stopped'`` when the
        iteration was left before a rule was met.
        """
        if self.monitor is None:
            raise RuntimeError(f"{type(self).__name__}.finish() before setup()")
        x = self._finish()
        want = (self.A.shape[1], self.y.shape[1])
        if np.shape(x) != want:
            # (a plugin's (Q - 1, K) or (Q,) ended as a broadcast error's traceback deep in
            # the depth stage: an outside audit of 2026-12-01)
            raise ConfigError(f"the solver {self.name!r} ({type(self).__module__}."
                              f"{type(self).__qualname__}): its _finish() returned an array of "
                              f"shape {np.shape(x)}, where {want} (unknowns x columns) is "
                              f"expected")
        info = self.monitor.finish(self.reason or "stopped")
        info.extra["threads"] = self._threads_used
        return (x[:, 0] if self._was_1d else x), info

    def solve(self, A: LinearOperator, y: np.ndarray, reg, lam: float,
              x0: np.ndarray | None = None,
              callback: Callback | Sequence[Callback] | None = None
              ) -> tuple[np.ndarray, SolveInfo]:
        """Minimise the solver's objective; return ``(x, info)``, ``x`` shaped like ``A.H @ y``.

        :meth:`setup`, :meth:`run` (with ``callback``) and :meth:`finish` in one parallel
        context (for large problems, see ``threads``).
        """
        A = as_operator(A)
        yb, _ = as_block(y)
        with self.parallel_context(A, yb):
            self.setup(A, y, reg, lam, x0)
            self.run(callback)
            return self.finish()

    def parallel_context(self, A, y: np.ndarray):
        """The :func:`~spslidar.operators.parallel.parallel` context for this problem size
        (``threads`` threads when ``A.shape[0] * A.shape[1] * K >= PARALLEL_MIN_WORK``, else
        none); :meth:`solve` and :meth:`run` enter it."""
        k = y.shape[1] if np.ndim(y) == 2 else 1
        big = A.shape[0] * A.shape[1] * k >= self.PARALLEL_MIN_WORK
        return parallel(self.threads if big else 1)

    # -- progress of the current solve -----------------------------------------------------
    @property
    def info(self) -> SolveInfo:
        """The :class:`SolveInfo` being filled (objective history so far...)."""
        if self.monitor is None:
            raise RuntimeError("no solve set up")
        return self.monitor.info

    @property
    def x(self) -> np.ndarray:
        """The current estimate, shaped like the result (what a stop now would return,
        before :meth:`finish`'s final work). Do not modify it in place."""
        if self.monitor is None:
            raise RuntimeError("no solve set up")
        x = self._current()
        return x[:, 0] if self._was_1d else x

    # -- to implement ----------------------------------------------------------------------
    def _setup(self, A, y: np.ndarray, reg, lam: float,
               x0: np.ndarray | None) -> None:  # pragma: no cover - abstract
        """Initialise the state from the problem (``y``, ``x0``: blocks; options parsed)."""
        raise NotImplementedError

    def _step(self) -> str:  # pragma: no cover - abstract
        """One iteration; returns ``self.monitor.check(...)``'s reason to stop (or ``''``)."""
        raise NotImplementedError

    def _current(self) -> np.ndarray:
        """The current estimate as an ``(n, K)`` block (default: ``self._x``)."""
        return self._x

    def _finish(self) -> np.ndarray:
        """Final work and the solution as an ``(n, K)`` block (default: :meth:`_current`)."""
        return self._current()


def _callbacks(callback) -> tuple[Callback, ...]:
    if callback is None:
        return ()
    if callable(callback):
        return (callback,)
    cbs = tuple(callback)
    for cb in cbs:
        if not callable(cb):
            raise TypeError(f"callback {cb!r} is not callable")
    return cbs


def progress(every: int = 10, stream: TextIO | None = None) -> Callback:
    """A callback printing the iteration and objective every ``every`` iterations.

    Parameters
    ----------
    every : int
        Print at iterations ``every, 2 every, ...`` and at the last one.
    stream : file, optional
        Default ``sys.stderr``.

    Returns
    -------
    callable
        ``callback(solver)`` for :meth:`Solver.run` / :meth:`Solver.solve`.
    """
    if int(every) < 1:
        raise ValueError("every must be >= 1")
    every = int(every)

    def callback(solver: Solver) -> None:
        if solver.it % every and not solver.done():
            return
        obj = solver.info.objective
        f = f"{obj[-1]:.6g}" if obj else "-"
        end = f" ({solver.reason})" if solver.done() else ""
        print(f"{solver.name} it {solver.it:5d}  F = {f}{end}", file=stream or sys.stderr)

    return callback


def _registry():
    from .entries import SOLVERS  # the registry (lists the in-tree solvers by path)

    return SOLVERS


def registered_defaults(name: str) -> tuple[int, float, str]:
    """``(iterations, lam_scale, regulariser)`` of the registry entry ``name``: where the
    in-tree solvers' ``default_*`` class attributes come from (one copy of the numbers)."""
    d = _registry().get(name).defaults
    return int(d["iterations"]), float(d["lam_scale"]), str(d["regulariser"])


def register(cls: type[Solver]) -> type[Solver]:
    """Class decorator adding a solver class to :data:`spslidar.solvers.SOLVERS`.

    The entry is named ``cls.name``; its defaults are the class's ``default_iterations``,
    ``default_lam_scale`` and ``default_regulariser``, its help the first line of the
    docstring. A class already registered by import path under that name keeps its entry.
    """
    solvers = _registry()
    path = f"{cls.__module__}:{cls.__qualname__}"
    if cls.name in solvers and solvers.get(cls.name).target in (cls, path):
        return cls
    doc = (cls.__doc__ or "").strip().splitlines()
    solvers.add(cls.name, cls, getattr(cls, "display", "") or cls.name,
                doc[0] if doc else "", iterations=cls.default_iterations,
                lam_scale=cls.default_lam_scale, regulariser=cls.default_regulariser)
    return cls


def available_solvers() -> list[str]:
    """Names of the registered solvers, sorted."""
    return sorted(_registry().names())


def get_solver(name: str) -> type[Solver]:
    """The solver class registered under ``name`` (its module imported on first use).

    The name is read case-insensitively where that is one entry (``"FISTA"``), as
    :func:`spslidar.reconstruct`'s ``solver`` and the configuration read it.

    Raises
    ------
    ConfigError
        (a ``ValueError``) for an unknown name, listing the registered ones.
    """
    registry = _registry()
    return registry.load(registry.canonical(name))


def solve(A: LinearOperator, y: np.ndarray, reg, lam: float,
          method: str = "fista", x0: np.ndarray | None = None, stop: StopRule | None = None,
          callback: Callback | Sequence[Callback] | None = None, **options
          ) -> tuple[np.ndarray, SolveInfo]:
    """Solve eq. (18) with the named method: ``x, info = solve(A, y, reg, lam, 'fista')``."""
    return get_solver(method)(stop=stop, **options).solve(A, y, reg, lam, x0=x0,
                                                          callback=callback)
