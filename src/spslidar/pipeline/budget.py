"""Memory and time of a run, estimated from its configuration before any work is done.

``measure`` calls :func:`check_budget` once the scene, the code and the range gate are known
(all cheap) and before the patterns are drawn, so a configuration that cannot run on this
machine is refused in well under a second, with one line giving the estimate and what to
change, instead of being killed by the kernel (or ending in a ``MemoryError``) minutes later.

The model counts the large arrays of each stage (measured peaks of the default path on a
2-core machine agree within about 30 %: e.g. 128x128 at 25 %, 1.03 GB measured against
1.1 GB estimated); it is meant to tell 3 GB from 30 GB, not 3.0 from 3.3. The time is an
order of magnitude, from the dominant products at a conservative BLAS rate.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from ..errors import SpslidarError
from ..machine import _gb, available_memory, parse_duration

__all__ = ["Budget", "available_memory", "check_budget", "check_time", "estimate_budget",
           "parse_duration"]

#: memory of the interpreter with NumPy, SciPy and spslidar imported
BASE_BYTES = 150e6
#: copies of an ``(M, Q)`` dense pattern matrix alive during a run (the patterns, the centred
#: solve operator and its transpose, float64 blocks while centring)
DENSE_PATTERN_COPIES = 4.0
#: ``(Q, K)`` blocks a solver keeps (iterates, momentum, gradient, TV dual and temporaries)
SOLVER_BLOCKS = 16
#: bytes per element of the ``(Q, n_lags)`` slice block after the solve (float32 slices, the
#: estimator's float64 copy and temporaries) for an estimator whose registry entry gives no
#: ``slice_bytes``; each built-in's gives its own (the MRF's 70: with 20 for every estimator,
#: a 512x512 Hadamard run peaked at 1.95 GB against 1.69 GB estimated, 2026-11-28)
SLICE_BYTES = 70
#: seconds per element of that block at the depth stage for an estimator whose registry entry
#: gives no ``slice_seconds`` (the MRF family's)
SLICE_SECONDS = 4.5e-7
#: seconds per element of the slices the noise verdict reads (``metrics`` stage: measured
#: 0.073-0.135 us at 64x64 over 3 337 slices, 2026-11-28)
VERDICT_SECONDS = 1.5e-7
#: sustained multiply-adds per second assumed for the time estimate (2 cores, BLAS), float64:
#: measured 4.3e10 in a 64x64 dense solve on the 2-core machine (2026-11-28, the TV prox
#: included), taken at 0.6 of it for slower machines
FLOP_RATE = 2.5e10
#: the same in float32 (the default dtype): measured 5.1e10 (64x64 camera, where fixed costs
#: weigh most) to 8.5e10 (128x128, every solver alike); 2e10 for both dtypes, with 100
#: iterations for every solver, priced a 128x128 Gaussian run at 152 s for 27 s taken and
#: refused sweeps --max-time would have held
FLOP_RATE_FLOAT32 = 5e10
#: seconds per simulated TDC bin (Poisson draw, expected counts, matched filter): 4.7e-8
#: measured on the 2-core machine (256x256 Hadamard at 100 %: 50 s for 65536 patterns of
#: 16383 bins), rounded up
SECONDS_PER_BIN = 5e-8
#: seconds every run takes whatever its size (the scene's resize, the depth estimator, the
#: metrics): 0.06-0.07 s measured at 8x8 and 16x16 on 255 bits, where the rest was estimated
#: at 0.001-0.011 s, so a sweep of 40 such runs was estimated at 0.43 s and took 13 s
RUN_OVERHEAD_S = 0.05


def flop_rate(dtype: str) -> float:
    """Multiply-adds per second assumed for ``dtype`` (:data:`FLOP_RATE_FLOAT32` or
    :data:`FLOP_RATE`)."""
    return FLOP_RATE_FLOAT32 if str(dtype) == "float32" else FLOP_RATE


@dataclass
class Budget:
    """A run's estimated peak memory (bytes) and time (s), with the parts behind them."""

    bytes: float
    seconds: float
    parts: dict[str, float] = field(default_factory=dict)

    def describe(self) -> str:
        """The estimate in words: memory with its largest part, and time where it is
        estimated (the refusals' and announcements' sentence)."""
        big = max(self.parts, key=self.parts.get) if self.parts else "total"
        time = f" and ~{_secs(self.seconds)}" if self.seconds > 0 else ""
        return (f"~{_gb(self.bytes)} of memory (largest part: {big}, "
                f"{_gb(self.parts.get(big, self.bytes))}){time}")


def _secs(s: float) -> str:
    if s < 10:
        return f"{s:.2g} s"
    if s < 120:
        return f"{s:.0f} s"
    if s < 7200:
        return f"{s / 60:.0f} min"
    return f"{s / 3600:.0f} h"


def _solver_copies(solver: str) -> float:
    """The dense ``(M, Q)`` pattern copies a solver makes beyond :data:`DENSE_PATTERN_COPIES`:
    its registry default ``pattern_copies`` (GPSR's wavelet-composed matrix), else 0."""
    from ..solvers import SOLVERS

    return float(SOLVERS.get(solver).defaults.get("pattern_copies", 0))


def _slice_cost(depth: str, key: str, default: float) -> float:
    """The depth estimator's cost per slice-block entry, its registry default ``key``
    (``slice_bytes`` or ``slice_seconds``), else ``default`` (:data:`SLICE_BYTES`,
    :data:`SLICE_SECONDS`)."""
    from ..depth import ESTIMATORS

    return float(ESTIMATORS.get(depth).defaults.get(key, default))


def depth_seconds(depth: str, q: int, n_lags: int) -> float:
    """The depth stage's and the noise verdict's share of the time estimate: the estimator's
    ``slice_seconds`` per pixel and gated slice, and :data:`VERDICT_SECONDS` per slice of
    the pixels the verdict reads (at most ``NOISE_VERDICT_PIXELS``). A 0-150 m gate at 64x64
    took 17.3 s, 12 s of it the MRF and 3.5 s the verdict, where the estimate, which left
    both out, said 2.5 s (an audit of 2026-11-28)."""
    from ..depth.profile import NOISE_VERDICT_PIXELS

    return (_slice_cost(depth, "slice_seconds", SLICE_SECONDS) * float(q) * n_lags
            + VERDICT_SECONDS * float(min(q, NOISE_VERDICT_PIXELS)) * n_lags)


def estimate_budget(cfg, *, n_patterns: int, period: int, n_lags: int, n_ulags: int,
                    window_bins: int, pattern_bytes_per_entry: float | None,
                    threads: int = 2) -> Budget:
    """Estimate a run's peak memory and time.

    Parameters
    ----------
    cfg : Config
    n_patterns : int
        M.
    period : int
        TDC bins per code period (the simulated histogram length).
    n_lags, n_ulags : int
        Gated delays, and distinct delays modulo the period.
    window_bins : int
        Bins spanned by the scene's depths (what an automatic gate keeps).
    pattern_bytes_per_entry : float or None
        Bytes per entry of the ``(M, Q)`` pattern matrix, or None for implicit patterns.
    threads : int
        Simulation threads.
    """
    q = cfg.size * cfg.size
    m = n_patterns
    k_solve = n_ulags if cfg.auto_gate is False else min(n_ulags, window_bins + 32)
    if cfg.auto_gate is None and n_ulags <= 256:
        k_solve = n_ulags
    shifts = min(n_ulags + 2, 2 * q)
    parts = {
        "interpreter": BASE_BYTES,
        "patterns": ((DENSE_PATTERN_COPIES + _solver_copies(cfg.solver)) * m * q
                     * pattern_bytes_per_entry
                     if pattern_bytes_per_entry else 2.0 * m * shifts * 8),
        "simulation": threads * 3.0 * 64 * period * 4 + shifts * period * 4.0
        + q * shifts * 8.0 + 2.0 * m * n_ulags * 4,
        **reconstruction_parts(cfg, q, k_solve, n_lags),
    }
    # the solve at the solver's own cap (a floored weight's five-fold cap is priced again
    # once the weight is known)
    seconds = (RUN_OVERHEAD_S + m * period * SECONDS_PER_BIN
               + m * q * shifts / flop_rate(cfg.dtype)
               + config_solve_seconds(cfg, m, q, k_solve, pattern_bytes_per_entry is not None)
               + refit_seconds(cfg, m, q, k_solve, pattern_bytes_per_entry is not None)
               + depth_seconds(cfg.depth, q, n_lags))
    return Budget(sum(parts.values()), seconds, parts)


#: seconds per entry of the ``Q x K`` slices per iteration that the fast transform's solve
#: spends beside its products (the TV prox's inner steps, the momentum): measured on the
#: 2-core machine (2026-11-28), 128x128 and 256x256 Hadamard at 25 / 10 %, 16.5-17.5 ns,
#: where the products' count alone priced the 256x256 solve at 4.1 s for 21 s taken and a
#: --max-time 15 run ran 24 s (an audit); dense patterns' products dominate and are over-
#: rather than under-estimated (64x64: 1.54 s priced, 0.61 s taken)
FAST_SECONDS_PER_ENTRY = 1.6e-8


#: seconds every iteration of a solve takes whatever its size (Python, the stopping test,
#: the small arrays): 83-173 us measured at 8x8 over 3 000 iterations, GPSR to TVAL3
#: (2026-11-28); without it ``--iterations 1000000`` was priced at 2.9 s and took 162 s,
#: past a ``--max-time`` (an audit)
ITERATION_SECONDS = 1.8e-4


def solve_seconds(m: int, q: int, k: int, dense: bool, iterations: int,
                  rate: float = FLOP_RATE) -> float:
    """The solve's share of :func:`estimate_budget`: ``iterations`` products with ``A`` and
    its adjoint over ``k`` slices (``M Q`` per slice for dense patterns, ``2 Q log2 Q`` for
    the fast Hadamard transform, which also pays :data:`FAST_SECONDS_PER_ENTRY` per slice
    entry), and :data:`ITERATION_SECONDS` each."""
    q = int(q)
    per_product = (int(m) * q if dense else 2 * q * max(1, q.bit_length())) * int(k)
    rest = 0.0 if dense else FAST_SECONDS_PER_ENTRY * q * int(k)
    return iterations * (2 * per_product / rate + rest + ITERATION_SECONDS)


def config_solve_seconds(cfg, m: int, q: int, k: int, dense: bool,
                         iterations: int | None = None) -> float:
    """:func:`solve_seconds` of ``cfg``'s solve: ``iterations``, by default ``cfg``'s or its
    solver's own cap (FISTA and TwIST 60, TVAL3 100, GPSR 120), at ``cfg``'s dtype's rate
    (:func:`flop_rate`)."""
    from .weights import solver_default

    if iterations is None:
        iterations = cfg.iterations or int(solver_default(cfg.solver, "iterations"))
    return solve_seconds(m, q, k, dense, iterations, flop_rate(cfg.dtype))


def refit_seconds(cfg, m: int, q: int, k: int, dense: bool) -> float:
    """The reflectivity refit's share (:func:`spslidar.refit.refit_reflectivity`): its
    iterations and the product that takes other surfaces out, each a product with ``A`` and
    its adjoint over at most the ``k`` solved slices (:func:`solve_seconds`); five times as
    many iterations for noiseless data, whose weight is the floor."""
    from ..refit import REFIT_ITERATIONS
    from .weights import FLOORED_ITERATIONS

    iterations = REFIT_ITERATIONS * (FLOORED_ITERATIONS if cfg.noiseless else 1)
    return solve_seconds(m, q, k, dense, iterations + 1, flop_rate(cfg.dtype))


def reconstruction_parts(cfg, q: int, k: int, n_lags: int) -> dict[str, float]:
    """The bytes of a reconstruction's own arrays (:func:`estimate_budget`'s ``solver`` and
    ``range slices``): the solver's blocks over ``k`` solved slices and the depth stage's
    over the ``n_lags`` gated ones."""
    item = 4 if cfg.dtype == "float32" else 8
    return {"solver": SOLVER_BLOCKS * float(q) * k * item,
            "range slices": _slice_cost(cfg.depth, "slice_bytes", SLICE_BYTES) * float(q)
            * n_lags}


def reconstruction_seconds(cfg, m: int, q: int, k: int, n_lags: int,
                           dense: bool = True) -> float:
    """A reconstruction, priced: :func:`config_solve_seconds` and :func:`refit_seconds` of
    ``k`` solved slices (dense patterns, as a measured acquisition's are, unless ``dense`` is
    False) and :func:`depth_seconds` over the ``n_lags`` gated ones (``reconstruct``'s price
    before its file is read, and once its gate is known; ``spslidar.reconstruct``'s of a
    simulation reconstructed otherwise)."""
    return (config_solve_seconds(cfg, m, q, k, dense) + refit_seconds(cfg, m, q, k, dense)
            + depth_seconds(cfg.depth, q, n_lags))


#: a run estimated to take longer than this says so on stderr before it starts (seconds)
ANNOUNCE_SECONDS = 30.0


def _duration_arg(s: float) -> str:
    """``s`` seconds rounded up as ``--max-time`` reads it (``90s``, ``12min``, ``3h``): the
    refusal's example said ``2h`` for an 18 s run."""
    if s < 120:
        return f"{math.ceil(s)}s"
    if s < 7200:
        return f"{math.ceil(s / 60)}min"
    return f"{math.ceil(s / 3600)}h"


def check_time(seconds: float, max_time: float | None, what: str = "this run",
               announce: bool = True,
               reduce: str = "--size, --compression, --iterations or the range gate",
               basis: str = "its configuration") -> None:
    """Refuse (one line) work whose estimated time exceeds ``max_time`` seconds
    (``--max-time``); say the estimate on stderr before long work (over
    :data:`ANNOUNCE_SECONDS`). ``reduce`` names what to lower in the refusal."""
    import sys

    if max_time is not None and seconds > max_time:
        raise SpslidarError(
            f"{what} would take ~{_secs(seconds)} (estimated from {basis}), more "
            f"than --max-time {_secs(max_time)}: reduce {reduce}, or raise --max-time (e.g. "
            f"--max-time {_duration_arg(1.5 * seconds)})")
    if announce and seconds > ANNOUNCE_SECONDS:
        print(f"spslidar: {what} will take about {_secs(seconds)} (an estimate; --max-time "
              f"to change the limit)", file=sys.stderr, flush=True)


def check_budget(budget: Budget, max_memory_gb: float | None,
                 patterns: str | None = None, max_time: float | None = None,
                 announce: bool = False) -> None:
    """Refuse (one line, :class:`SpslidarError`) a run whose estimate exceeds the limits.

    Parameters
    ----------
    budget : Budget
    max_memory_gb : float or None
        The limit in GB (``--max-memory``); None: the memory available now.
    patterns : str, optional
        The run's pattern kind: an implicit kind is suggested only when it is a dense one.
    max_time : float, optional
        The limit in seconds (``--max-time``); None: no limit.
    announce : bool
        Say a long estimate on stderr (:func:`check_time`).
    """
    limit = available_memory() if max_memory_gb is None else max_memory_gb * 1e9
    if budget.bytes > limit:
        src = "--max-memory" if max_memory_gb is not None else "available"
        from ..patterns import PATTERNS

        implicit = [e.name for e in PATTERNS if not e.defaults.get("dense", False)]
        dense = patterns is None or PATTERNS.get(patterns).defaults.get("dense", False)
        alt = f", use --patterns {implicit[0]}" if implicit and dense else ""
        if limit < BASE_BYTES:  # (no run fits: it was told to reduce --size, an audit)
            raise SpslidarError(f"no run fits in the {_gb(limit)} {src}: the interpreter with "
                                f"its libraries alone takes ~{_gb(BASE_BYTES)}; raise "
                                f"--max-memory")
        raise SpslidarError(
            f"this run needs {budget.describe()}, more than the {_gb(limit)} {src}: reduce "
            f"--size, --compression or the --range-gate{alt}, or raise --max-memory")
    check_time(budget.seconds, max_time, announce=announce)
