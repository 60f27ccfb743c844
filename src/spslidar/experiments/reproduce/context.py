"""The reproduction's shared state and runs: :class:`Context`, the canonical run parameters,
the picklable point functions, and running points through the sweep engine into tidy CSVs.

Every experiment builds its points with :func:`base_params` (so one configuration has one
cache key whichever experiment asks for it), runs them with :func:`run_points` (cached in
``DIR/cache/runs``, depth maps in ``DIR/cache/maps``) and writes them with :func:`write_rows`;
:func:`run_and_write` does both.
"""

from __future__ import annotations

import functools
import io
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from spslidar.constants import SPEED_OF_LIGHT
from spslidar.errors import ConfigError
from spslidar.experiments.report import QUICK_MARK
from spslidar.experiments.sweep import (
    ERROR_KEY,
    SEED_KEY,
    TRIAL_KEY,
    atomic_write_bytes,
    atomic_write_text,
    point_key,
    run_sweep,
    write_csv,
)

__all__ = [
    "BIN_DEPTH_M",
    "BIN_WIDTH_S",
    "CODE_NAMES",
    "PAPER",
    "SOLVER_NAMES",
    "Context",
    "cached_runs",
    "base_params",
    "load_map",
    "n_cached",
    "reproduce_point",
    "run_and_write",
    "run_points",
    "snr_point",
    "write_rows",
    "write_text",
]

#: TDC bin width at the default 10 GHz bit rate, and its depth (1.5 cm).
BIN_WIDTH_S = 1e-10
BIN_DEPTH_M = SPEED_OF_LIGHT * BIN_WIDTH_S / 2.0

#: The paper's numbers (docs/reading.md, "The paper's reported numbers"); RMSE in metres
#: unless noted.
PAPER: dict[str, Any] = {
    "fig2_time_s": (8.0, 78.0),  # 5 % and 85 % compression, 64x64, MATLAB
    "fig4_noqcr_rmse_m": {1023: 0.1, 32767: 0.033},  # printed as 1024 and 32768 bits
    "fig4_conventional_rmse_m": 0.201,
    "fig4_qcr_rmse_m": 0.02,  # at 16384 bits
    "fig6_conventional_rmse_m": 0.176,  # m_n = 10
    "fig6_noqcr_rmse_m": 0.035,  # m_n = 10
    "fig6_qcr_rmse_m": (0.005, 0.017),  # m_n = 5 .. 10
    "fig6_qcr_factor": 10.5,
    "fig6_qcr_reduction_m": 0.018,  # "MSE average reduction ... by the QCR is about 0.018 m"
    # Table I: MSE as printed ("cm", doubtful unit) and time [s], for m_n = 5 and 10
    "table1": {
        "tval3": {5: (0.033, 35.0), 10: (0.011, 57.0)},
        "gpsr": {5: (0.06, 13.0), 10: (0.018, 24.0)},
        "fista": {5: (0.042, 16.0), 10: (0.019, 24.0)},
        "twist": {5: (None, 20.0), 10: (None, 28.0)},  # its MSE: "shown in Fig. 6"
    },
}

SOLVER_NAMES = {"fista": "FISTA", "twist": "TwIST", "tval3": "TVAL3", "gpsr": "GPSR"}
CODE_NAMES = {"mseq": "m-sequence", "gold": "Gold code", "random": "Bernoulli code"}


# --------------------------------------------------------------------------------------------
# Context and run points
# --------------------------------------------------------------------------------------------


@dataclass
class Context:
    """Where and how one ``reproduce`` invocation runs.

    Attributes
    ----------
    out : Path
        The report folder ``DIR``.
    quick : bool
        Smoke-test settings (32x32, fewer and shorter settings, one trial).
    trials : int or None
        Monte-Carlo trials per setting; None: the experiment's default (3 for Fig. 4 in full
        mode, otherwise 1).
    jobs : int
        Local worker processes of the sweep engine.
    scheduler : Any
        Dask scheduler address or client (None: local).
    progress : bool
        Progress bars on stderr.
    seed : int
        The sweep seed every run's seed is derived from.
    failed : int
        Runs that failed so far (a failed run is a row with an ``error`` column).
    max_time : float or None
        Refuse a batch of runs estimated to take longer (seconds; ``--max-time``).
    """

    out: Path
    quick: bool = False
    trials: int | None = None
    jobs: int = 1
    scheduler: Any = None
    progress: bool = True
    seed: int = 0
    failed: int = 0
    max_time: float | None = None
    #: the estimated seconds of the batches run so far (``max_time`` bounds their sum)
    estimated_s: float = 0.0
    #: whether the running experiment asked for :meth:`n_trials` (``--trials`` is said to be
    #: ignored by one that did not: eq. (10)'s Monte-Carlo counts code periods)
    trials_read: bool = False

    @property
    def size(self) -> int:
        """Image side in pixels: 64 (the paper's), 32 in quick mode."""
        return 32 if self.quick else 64

    @functools.cached_property
    def code(self) -> str:
        """The fingerprint of the code that runs (:func:`spslidar.plugins.code_fingerprint`,
        taken once): a cached run of other code is run again."""
        from spslidar.plugins import code_fingerprint

        return code_fingerprint()

    @property
    def cache(self) -> Path:
        """The shared sweep folder (``runs/`` cache and ``maps/`` depth maps)."""
        return self.out / "cache"

    @property
    def maps(self) -> Path:
        """Folder of the depth maps of every run, ``<key>.npy``."""
        return self.cache / "maps"

    def n_trials(self, full: int = 1) -> int:
        """Trials for an experiment whose full-mode default is ``full``."""
        self.trials_read = True
        n = self.trials if self.trials is not None else (1 if self.quick else full)
        self.last_trials = n  # the map panels say which trial they show
        return n

    def folder(self, name: str) -> Path:
        """``DIR/<name>``, created."""
        path = self.out / name
        path.mkdir(parents=True, exist_ok=True)
        return path

    @property
    def mode(self) -> str:
        """One line saying which mode ran."""
        if self.quick:
            # what ran, not what was asked: an experiment that reads no trial count (eq. 10
            # counts code periods) ignores --trials, and said it had run them
            if not self.trials_read:
                trials = ("no repeated trials" if self.trials is None else
                          f"no repeated trials: --trials {self.trials} is ignored here")
            else:
                n = getattr(self, "last_trials", 1)
                trials = "one trial" if n == 1 else f"{n} trials"
            return (
                f"{QUICK_MARK} (32x32 pixels, fewer and shorter settings, {trials}): a smoke "
                f"test whose numbers are not comparable with the paper's 64x64 ones."
            )
        return ("Full mode (64x64 pixels; the paper's scenes, codes and photon levels, "
                "reconstructed with this project's defaults, FISTA and the mrf depth, where the "
                "paper used TwIST and its ML argmax: each section says what it ran).")


_FLOAT_KEYS = ("ones_ratio", "compression", "signal", "noise", "rep_rate")


def base_params(ctx: Context, **changes: Any) -> dict[str, Any]:
    """The canonical parameters of a reproduction run, with some changed.

    Every experiment builds its points here, so one configuration has one cache key whichever
    experiment asks for it (``1`` and ``1.0`` would hash differently: float keys are cast).

    Parameters
    ----------
    ctx : Context
        Gives the image size.
    **changes
        Run-config keys to set (see :class:`spslidar.config.Config`).

    Returns
    -------
    dict
        The run's parameters: scene ``camera``, PSST m-sequence of 16383 bits, 25 % Gaussian
        patterns, ``m_s = 5``, ``m_n = 10``, QCR, FISTA, unless changed.
    """
    params: dict[str, Any] = {
        "scene": "camera",
        "size": ctx.size,
        "lidar": "psst",
        "code": "mseq",
        "code_length": 16383,
        "ones_ratio": 0.5,
        "compression": 0.25,
        "signal": 5.0,
        "noise": 10.0,
        "qcr": True,
        "solver": "fista",
    }
    params.update(changes)
    for key in _FLOAT_KEYS:
        if key in params and params[key] is not None:
            params[key] = float(params[key])
    return params


def argmax_rmse(result) -> float:
    """Depth RMSE of the paper's ML estimator (argmax, eq. 2-3) on the run's own slices, so the
    report can put the paper's estimator beside the default one without a second solve."""
    if result.config.depth == "argmax":
        return float(result.metrics["depth_rmse_m"])
    from spslidar.constants import SPEED_OF_LIGHT
    from spslidar.depth import ESTIMATORS, DepthContext
    from spslidar.metrics import depth_errors

    c = result.config
    bin_width = 2.0 * result.metrics["bin_depth_m"] / SPEED_OF_LIGHT
    est = ESTIMATORS.load("argmax")().estimate(
        result.slices, DepthContext(result.lags, bin_width, c.pulse_width, (c.size, c.size),
                                    c.subbin))
    return depth_errors(est.depth.reshape(c.size, c.size), result.scene.depth,
                        result.scene.valid)["depth_rmse_m"]


def reproduce_point(params: dict[str, Any], maps_dir: str | None = None) -> dict[str, Any]:
    """Run the pipeline on one point, save its depth map, return its metrics.

    Top-level (picklable) so the sweep engine can run it in worker processes or on Dask; bind
    ``maps_dir`` with :func:`functools.partial`.

    Parameters
    ----------
    params : dict
        Run-config keys plus ``seed`` and ``trial`` (dropped: its effect is in ``seed``).
    maps_dir : str, optional
        Folder for the depth map, saved as ``<key>.npy`` (``key`` = the run's cache key,
        :func:`~spslidar.experiments.sweep.point_key` of ``params``).

    Returns
    -------
    dict
        Depth errors, edge correlation, sizes, timing, iterations, the code description and
        replica, the median estimated and true depth, and ``map_key``.
    """
    from spslidar.metrics import mostly_noise
    from spslidar.pipeline import run_shared

    config = {k: v for k, v in params.items() if k != TRIAL_KEY}
    result = run_shared(config)
    m = result.metrics
    key = point_key(params)
    if maps_dir is not None:
        folder = Path(maps_dir)
        folder.mkdir(parents=True, exist_ok=True)
        buffer = io.BytesIO()
        np.save(buffer, result.depth.astype(np.float32))
        atomic_write_bytes(folder / f"{key}.npy", buffer.getvalue())
    valid = result.scene.valid
    est = result.depth[valid]
    est = est[np.isfinite(est)]
    return {
        "depth_rmse_m": m["depth_rmse_m"],
        "depth_rmse_argmax_m": argmax_rmse(result),
        "depth_mae_m": m["depth_mae_m"],
        "depth_bias_m": m["depth_bias_m"],
        "missing_fraction": m["missing_fraction"],
        "edge_correlation": m["edge_correlation"],
        "depth_median_m": float(np.median(est)) if est.size else math.nan,
        "truth_median_m": float(np.median(result.truth[valid])),
        "n_patterns": m["n_patterns"],
        "n_slices": m["n_slices"],
        "n_slices_solved": m.get("n_slices_solved", m["n_slices"]),
        "unambiguous_range_m": m["unambiguous_range_m"],
        "code_description": m["code_description"],
        "replica": m["replica"],
        "lam": m["lam"],
        "iterations": m["solver_info"]["iterations"],
        "time_total_s": result.timing["total"],
        "time_simulate_s": result.timing["simulate"],
        "time_solve_s": result.timing["solve"],
        "n_warnings": len(result.warnings),
        "counts_per_dead_time": m["detector"]["counts_per_dead_time"],
        "map_key": key,
        # (after the columns above, which keep their order and values: whether the map is
        # mostly noise, read beside its RMSE, an outside review of 2026-11-29)
        "chance_rmse_m": m.get("chance_rmse_m"),
        "low_confidence_fraction": m.get("low_confidence_fraction"),
        "mostly_noise": mostly_noise(m),
    }


def snr_point(params: dict[str, Any]) -> dict[str, Any]:
    """One row of the SNR experiment: eq. (10) against its simulation (top-level, picklable).

    Parameters
    ----------
    params : dict
        ``code``, ``code_length``, ``ones_ratio``, ``signal``, ``noise``, ``size``,
        ``on_fraction``, ``periods`` (Monte-Carlo code periods), ``method`` and ``seed``.

    Returns
    -------
    dict
        The row of :func:`spslidar.snr.snr_table`.
    """
    from spslidar.snr import snr_table

    rows = snr_table(
        [params["code"]],
        [params["code_length"]],
        [params["ones_ratio"]],
        params["signal"],
        params["noise"],
        params["size"],
        params["on_fraction"],
        trials=params["periods"],
        rng=np.random.default_rng(params["seed"]),
        method=params["method"],
    )
    # the point's own keys stay the point's (an m-sequence's row gave its actual share of
    # ones as "ones_ratio", which the sweep engine now refuses as a changed parameter; the
    # share is the row's "ones_ratio_actual")
    return {k: v for k, v in rows[0].items() if k not in params}


def snr_point_seconds(params: dict[str, Any]) -> float:
    """The estimated time of one :func:`snr_point`: its simulation's, as ``spslidar snr``
    prices it (:func:`spslidar.snr.simulate.estimate_seconds`, 6e-8 s per simulated TDC bin,
    ``periods x code_length`` bins). The SNR experiment was priced at nothing, so
    ``--max-time 1s`` ran its 11.5 s (an outside audit of 2026-12-02); on the 2-core machine
    the estimate is 15.5 s for its 24 points (measured 9.9 s, 11.7 s for the command) and 1.5 s
    for ``--quick``'s 16 (measured 1.7 s, 2.4 s for the command): the per-bin rate was
    measured at 4.9e-8 s and rounded up, as the runs' budgets round up."""
    from spslidar.snr.simulate import estimate_seconds

    return estimate_seconds(int(params["code_length"]), int(params["periods"]),
                            str(params["method"]))


def _check_batch_time(ctx: Context, points: Sequence[dict[str, Any]],
                      price: Callable[[dict[str, Any]], float] | None = None) -> None:
    """Refuse a batch of runs whose estimated time (each distinct configuration's budget,
    :func:`spslidar.pipeline.preflight`, or ``price(point)`` where given, times its runs,
    over the workers), added to the batches' before it in this command, exceeds
    ``ctx.max_time``; one over 30 s says its estimate first. The experiments finished before
    a refusal keep their report sections."""
    from spslidar.experiments.sweep.grid import TRIAL_KEY
    from spslidar.experiments.sweep.store import cached_point
    from spslidar.pipeline import preflight
    from spslidar.pipeline.budget import check_time
    from spslidar.pipeline.measurement import processing_keys

    seconds: dict[str, float] = {}
    total = 0.0
    # (a plugin estimator's option is processing too: the static keys kept --window beside
    # the default depth, refused, an audit of plugins); a priced point function's runs are
    # seeded from all their parameters, as run_points runs them
    processing = processing_keys() if price is None else frozenset()
    for params in points:
        # its cache record, as run_sweep names and reads it: a cached run costs nothing
        if cached_point(ctx.cache / "runs", params, ctx.seed, processing,
                        ctx.code)[1] is not None:
            continue  # (a resumed fig2 was refused for the run it had cached)
        if price is not None:
            total += price(params)
            continue
        cfg = {k: v for k, v in params.items() if k != TRIAL_KEY and k not in processing}
        key = repr(sorted(cfg.items()))
        if key not in seconds:
            seconds[key] = preflight(cfg).seconds
        total += seconds[key]
    if ctx.scheduler is not None:  # the cluster's threads (--jobs, ignored there, divided it)
        from spslidar.experiments.sweep.engine import cluster_threads

        workers = max(1, min(len(points), cluster_threads(ctx.scheduler)))
    else:
        workers = max(1, min(len(points), ctx.jobs if ctx.jobs > 0 else 2))
    # the whole command's estimate, not each batch's (--max-time 10 ran 30 s of batches)
    check_time(ctx.estimated_s + total / workers, ctx.max_time,
               f"this reproduction (its earlier batches and this one of {len(points)} runs)",
               # (a priced point function, eq. (10)'s, reads no --trials)
               reduce="the work with --quick" + (" or fewer --trials" if price is None
                                                 else ""))
    ctx.estimated_s += total / workers


def run_points(
    ctx: Context,
    points: Sequence[dict[str, Any]],
    func: Callable[[dict[str, Any]], dict[str, Any]] | None = None,
    price: Callable[[dict[str, Any]], float] | None = None,
) -> list[dict[str, Any]]:
    """Run (or load from the cache) the points and count the failed ones in ``ctx.failed``.

    Parameters
    ----------
    ctx : Context
        Where (``ctx.cache``) and how (``jobs``, ``scheduler``, ``progress``, ``seed``) to run.
    points : sequence of dict
        The points, e.g. from :func:`~spslidar.experiments.sweep.expand_grid`.
    func : callable, optional
        The point function; default :func:`reproduce_point`, whose points that differ only in
        processing keys share their seed (a paired comparison on one simulated measurement)
        and whose every successful run must leave its depth map in ``ctx.maps`` (a cached run
        whose map is gone is run again here). Another function (e.g. :func:`snr_point`) is run
        as it is, seeded from all its parameters.
    price : callable, optional
        ``price(point)``: the estimated seconds of one of ``func``'s points (e.g.
        ``snr_point_seconds``), which ``--max-time`` bounds as it bounds the runs'; a
        ``func`` without one is not priced.

    Returns
    -------
    list of dict
        One row per point (see :func:`~spslidar.experiments.sweep.run_sweep`).
    """
    points = list(points)
    from spslidar.experiments.sweep.grid import MAX_RUNS

    if len(points) > MAX_RUNS:
        raise ConfigError(f"this experiment has {len(points)} runs, more than the {MAX_RUNS} "
                          f"one batch takes; use fewer --trials")
    if (func is None or price is not None) and ctx.max_time is not None:
        _check_batch_time(ctx, points, price)
    if func is not None:
        rows = run_sweep(func, list(points), ctx.cache, seed=ctx.seed, jobs=ctx.jobs,
                         scheduler=ctx.scheduler, progress=ctx.progress, code=ctx.code)
        ctx.failed += sum(ERROR_KEY in row for row in rows)
        return rows
    ctx.maps.mkdir(parents=True, exist_ok=True)
    from spslidar.pipeline.measurement import processing_keys

    func = functools.partial(reproduce_point, maps_dir=str(ctx.maps))
    points = list(points)
    # paired comparisons: points that differ only in processing share their measurement (a
    # plugin solver's or estimator's options too, as sweep reads them)
    processing = processing_keys()
    rows = run_sweep(
        func,
        points,
        ctx.cache,
        seed=ctx.seed,
        jobs=ctx.jobs,
        scheduler=ctx.scheduler,
        progress=ctx.progress,
        seed_ignore=processing,
        code=ctx.code,
    )
    # A cached run whose map is gone (deleted, or written on a remote worker's disk) or cannot
    # be read (cut short: a traceback on every later run, an audit of 2026-11-29): run it
    # again here.
    missing = [
        i
        for i, row in enumerate(rows)
        if ERROR_KEY not in row and _read_map(ctx.maps / f"{row['map_key']}.npy") is None
    ]
    if missing:
        for i in missing:
            (ctx.cache / "runs" / f"{rows[i]['map_key']}.json").unlink(missing_ok=True)
        again = run_sweep(
            func,
            [points[i] for i in missing],
            ctx.cache,
            seed=ctx.seed,
            progress=ctx.progress,
            seed_ignore=processing,
            code=ctx.code,
        )
        for i, row in zip(missing, again, strict=True):
            rows[i] = row
    ctx.failed += sum(ERROR_KEY in row for row in rows)
    return rows


def load_map(ctx: Context, row: dict[str, Any] | None) -> np.ndarray | None:
    """The depth map of a run's row (None for a failed run or a lost map)."""
    if row is None or ERROR_KEY in row:
        return None
    return _read_map(ctx.maps / f"{row['map_key']}.npy")


def _read_map(path: Path) -> np.ndarray | None:
    """A depth map file, or None where it is missing or cannot be read."""
    try:
        return np.load(path) if path.is_file() else None
    except (OSError, ValueError, EOFError):
        return None


def write_rows(ctx: Context, name: str, rows: Sequence[dict[str, Any]], stem: str = "") -> Path:
    """``DIR/<name>/<stem or name>.csv``: the rows with an ``experiment`` column first."""
    path = ctx.folder(name) / f"{stem or name}.csv"
    return write_csv([{"experiment": name, **row} for row in rows], path)


def run_and_write(
    ctx: Context, name: str, points: Sequence[dict[str, Any]]
) -> tuple[list[dict[str, Any]], Path]:
    """Run an experiment's points (:func:`run_points`) and write them as ``DIR/<name>/<name>.csv``.

    Returns
    -------
    rows : list of dict
        One row per point.
    csv : Path
        The CSV file.
    """
    rows = run_points(ctx, points)
    return rows, write_rows(ctx, name, rows)


def write_text(path: Path, text: str) -> None:
    """Write a text output (e.g. a Markdown table) atomically."""
    atomic_write_text(path, text)


def cached_runs(ctx: Context, params: dict[str, Any] | None = None) -> list[dict[str, Any]]:
    """The cached runs of this report folder as rows (params + results), those of the code
    that runs now only (:attr:`Context.code`).

    Parameters
    ----------
    ctx : Context
        Gives the cache folder.
    params : dict, optional
        Only the runs of exactly this configuration (e.g. from :func:`base_params`), whatever
        their seed and trial; a run with any other key (a range gate, an iteration cap...)
        is another configuration. Default: every cached run.

    Returns
    -------
    list of dict
        In the order of the cache keys.
    """
    from ...outwrite import read_json_record

    out = []
    for path in sorted((ctx.cache / "runs").glob("*.json")):
        try:
            # (a FIFO, a huge or a too deeply nested file is no run: as the sweep's cache)
            rec = read_json_record(path)
            if rec.get("code") != ctx.code:
                continue
            config = {k: v for k, v in rec["params"].items() if k not in (SEED_KEY, TRIAL_KEY)}
            if params is None or config == params:
                out.append({**rec["params"], **rec["result"]})
        except (OSError, ValueError, KeyError, TypeError, AttributeError):
            continue
    return out


def n_cached(ctx: Context) -> int:
    """Number of runs in the cache (``DIR/cache/runs/*.json``) made by the code that runs now
    (a run of other code, run again, counts as new)."""
    return len(cached_runs(ctx))
