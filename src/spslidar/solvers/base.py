"""The problem-agnostic solver interface shared by FISTA, TwIST, TVAL3 and GPSR.

Solvers see a :class:`~spslidar.operators.LinearOperator` ``A``, data ``y`` of shape ``(m, K)``
(or ``(m,)``), a regulariser ``reg`` (an object with ``__call__`` and ``prox``, see
:mod:`spslidar.solvers.regularisers`) and its weight ``lam``; they return ``x`` of shape
``(n, K)`` and a :class:`SolveInfo`. They never know about lidar. Every solver minimises

    F(x) = 1/2 ||A x - y||_2^2 + lam * R(x)                                    (eq. 18)

over the whole block of K columns at once (the sum over columns of the per-column objective),
unless its docstring says it solves an equivalent constrained form.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from scipy.linalg.blas import get_blas_funcs

from ..operators.parallel import parallel


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
        if int(self.max_iter) < 1:
            raise ValueError("max_iter must be >= 1")
        if self.rtol < 0 or (self.obj_rtol is not None and self.obj_rtol < 0):
            raise ValueError("tolerances must be non-negative")


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
    ) -> str:
        """Record iteration ``it`` and return the reason to stop (``''`` to go on).

        The change test of ``StopRule.rtol`` applies when ``x_old`` or ``step_norm`` is
        given. ``step``, when given, is ``x - x_old`` already formed by the solver, and
        ``step_norm`` its norm (each saves a pass over the iterate).
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
            if stop.obj_rtol is not None and prev is not None and it > 1:
                if abs(prev - obj) <= stop.obj_rtol * max(abs(obj), 1e-300):
                    return "obj_rtol"
        if (x_old is not None or step_norm is not None) and stop.rtol > 0 and it > 1:
            if step_norm is not None:
                dx = float(step_norm)
            else:
                dx = _norm(step if step is not None else x - x_old)
            if dx <= stop.rtol * max(_norm(x), 1e-300):
                return "rtol"
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
    """In place ``y += a * x`` for C-contiguous arrays of one float dtype (BLAS ``?axpy``)."""
    if a == 0:
        return
    if not (y.flags.c_contiguous and x.dtype == y.dtype):
        y += y.dtype.type(a) * x
        return
    axpy = get_blas_funcs("axpy", (y,))
    out = axpy(np.ascontiguousarray(x).ravel(), y.ravel(), a=float(a))
    if not np.shares_memory(out, y):  # pragma: no cover - f2py copied instead of in place
        y.ravel()[:] = out


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


class Solver:
    """Base class: subclasses set ``name`` and implement :meth:`_solve`.

    Parameters
    ----------
    stop : StopRule, optional
    threads : int, optional
        Threads for large problems (``A.shape[0] * A.shape[1] * K >=``
        :attr:`PARALLEL_MIN_WORK`): the solve then runs inside
        :func:`spslidar.operators.parallel.parallel` (BLAS on one thread, dense products and
        the TV prox split over our own threads). Default: the CPUs available, at most 4;
        ``1`` leaves BLAS alone. The iterates do not depend on it.
    **options
        Solver-specific options (documented on each subclass).
    """

    name = "base"
    #: multiplies the data-derived regularisation weight (see ``spslidar.pipeline``); set per
    #: solver because the solvers state their objectives with different scalings.
    default_lam_scale = 1.0
    #: multiply-adds of one product with the whole block above which the solve is parallel
    PARALLEL_MIN_WORK = 1 << 24

    def __init__(self, stop: StopRule | None = None, threads: int | None = None, **options):
        self.stop = stop if stop is not None else StopRule()
        if threads is not None and int(threads) < 1:
            raise ValueError("threads must be >= 1")
        self.threads = None if threads is None else int(threads)
        self.options = options

    def solve(self, A, y, reg, lam: float, x0: np.ndarray | None = None):
        """Minimise the solver's objective; return ``(x, info)``, ``x`` shaped like ``A.H @ y``."""
        if lam < 0:
            raise ValueError("lam must be non-negative")
        yb, was_1d = as_block(y)
        if yb.shape[0] != A.shape[0]:
            raise ValueError(f"data has {yb.shape[0]} rows, operator expects {A.shape[0]}")
        if x0 is not None:
            x0, _ = as_block(x0)
        mon = Monitor(self.name, self.stop)
        big = A.shape[0] * A.shape[1] * yb.shape[1] >= self.PARALLEL_MIN_WORK
        with parallel(self.threads if big else 1) as ctx:
            x, reason = self._solve(A, yb, reg, float(lam), x0, mon)
        info = mon.finish(reason)
        info.extra["threads"] = ctx.threads if ctx is not None else 1
        return (x[:, 0] if was_1d else x), info

    def _solve(self, A, y, reg, lam, x0, mon):  # pragma: no cover - abstract
        raise NotImplementedError


_REGISTRY: dict[str, type[Solver]] = {}


def register(cls: type[Solver]) -> type[Solver]:
    """Class decorator adding a solver to the registry under ``cls.name``."""
    _REGISTRY[cls.name] = cls
    return cls


def available_solvers() -> list[str]:
    return sorted(_REGISTRY)


def get_solver(name: str) -> type[Solver]:
    try:
        return _REGISTRY[name]
    except KeyError:
        raise ValueError(
            f"unknown solver {name!r}; choose one of {', '.join(available_solvers())}"
        ) from None


def solve(A, y, reg, lam: float, method: str = "fista", x0=None, stop: StopRule | None = None,
          **options):
    """Solve eq. (18) with the named method: ``x, info = solve(A, y, reg, lam, 'fista')``."""
    return get_solver(method)(stop=stop, **options).solve(A, y, reg, lam, x0=x0)
