"""The ``spslidar sweep`` command: a TOML grid of pipeline runs, checked and priced before any
runs, run through :func:`~spslidar.experiments.sweep.engine.run_sweep` and written as
``results.csv``. :func:`run_point` is the one adapter from a sweep point to the pipeline's flat
metrics.
"""

from __future__ import annotations

import functools
import os
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from spslidar.errors import ConfigError, SpslidarError
from spslidar.experiments.sweep import engine
from spslidar.experiments.sweep.engine import RESULTS_CSV
from spslidar.experiments.sweep.grid import (
    IRF_HASH_KEY,
    SCENE_HASH_KEY,
    SEED_KEY,
    TRIAL_KEY,
    canonical_json,
    derive_seed,
    load_sweep_config,
    one_line,
    resolve_point_files,
    same_value,
    sha256_hex,
    with_scene_hashes,
)
from spslidar.experiments.sweep.store import cached_point_state, say_outcome, write_csv

__all__ = ["SweepIncomplete", "run_point", "sweep_main"]



def run_point(params: dict[str, Any]) -> dict[str, Any]:
    """Run the pipeline on one sweep point and return its flat metrics.

    The ``trial`` index is dropped (its effect is already in the point's ``seed``); every other
    key is passed to :func:`spslidar.pipeline.run_metrics` as a run config. Points that differ
    only in processing keys (solver, weights, QCR...) share their seed (see
    :func:`sweep_main`) and, in one process, their simulated measurement
    (:func:`spslidar.pipeline.run_shared`).

    Parameters
    ----------
    params : dict[str, Any]
        A sweep point: run-config keys, ``seed`` and ``trial``.

    Returns
    -------
    dict[str, Any]
        The metrics (e.g. ``depth_rmse_m``).
    """
    from spslidar.pipeline import run_metrics

    config = {key: value for key, value in params.items()
              if key not in (TRIAL_KEY, SCENE_HASH_KEY, IRF_HASH_KEY)}
    return run_metrics(config)


def _run_opened(folder: str | None, func: Callable[[dict[str, Any]], Any],
                params: dict[str, Any]) -> Any:
    """``func`` of a sweep point whose scene and IRF files are read from the TOML's folder
    (``folder``); top-level so that joblib and Dask can pickle it."""
    return func(resolve_point_files(params, folder))


def _config_defaults() -> dict[str, Any]:
    """Each run key's default (:class:`~spslidar.config.Config`'s fields and the options the
    stages declare), as :func:`~spslidar.experiments.sweep.grid.same_value` compares them; a
    key whose default is resolved at run time (None) is left out."""
    import dataclasses

    from spslidar.config import Config, stage_options

    out: dict[str, Any] = {}
    for f in dataclasses.fields(Config):
        if f.default is not dataclasses.MISSING and f.default is not None:
            out[f.name] = same_value(f.default)
    for name, (_reg, opt) in stage_options().items():
        if opt.default is not None:
            out.setdefault(name, same_value(opt.default))
    return out


def paired_keys() -> frozenset[str]:
    """The keys a run's points may differ in and still share their seed (the same photons,
    a paired comparison): the processing keys, an edited scene or IRF file, another array
    library or device (a grid over backend compared NumPy and array-api-strict on different
    noise), and ``dtype``, since the patterns are drawn in float32 whatever it is (a grid
    over dtype gave its points other seeds, and its RMSE gap, 0.154 against 0.101 m, was
    noise: an outside audit of 2026-12-01)."""
    from spslidar.pipeline.measurement import processing_keys

    return processing_keys() | {SCENE_HASH_KEY, IRF_HASH_KEY, "backend", "device", "dtype"}


def _seeded(points: Sequence[Mapping[str, Any]], ignored: list[dict[str, str]],
            ignore: frozenset[str], seed: int) -> list[dict[str, Any]]:
    """Each point with its seed (unless the grid sets one): :func:`derive_seed` of the point
    without ``ignore`` and without the options its configuration ignores, each number a whole
    float written as an int (:func:`~spslidar.experiments.sweep.grid.same_value`). A grid over
    ``rep_rate`` of a PSST lidar, or ``noise = 1`` beside ``noise = 1.0``, gave points that
    are one configuration different noise, an effect that was not there (RMSE 0.31 against
    0.25 m). Options that some points ignore are said once each, on stderr."""
    from spslidar.scenes import scene_spec

    defaults = _config_defaults()
    out, said = [], {}
    for point, skip in zip(points, ignored, strict=True):
        point = dict(point)
        if "scene" in point:  # one scene spelled two ways is one point (procedural:007 / :7)
            point["scene"] = scene_spec(point["scene"])
        if SEED_KEY not in point:
            # (a default written out, signal = 5.0 in [base], drew other noise for every
            # point than the same sweep without it: an audit of 2026-11-29)
            point[SEED_KEY] = derive_seed(seed, {
                k: same_value(v) for k, v in point.items()
                if k not in ignore and k not in skip
                and not (k in defaults and same_value(v) == defaults[k])})
        for text in skip.values():
            said[text] = said.get(text, 0) + 1
        out.append(point)
    for text, count in list(said.items())[:5]:
        print(f"sweep: warning: {text} (at {count} of {len(out)} points, which share their "
              f"seeds with the points that differ from them only there)", file=sys.stderr)
    if len(said) > 5:
        print(f"sweep: warning: ... and {len(said) - 5} more ignored options", file=sys.stderr)
    return out


#: the run keys that set the photon flux alone (the noise model's and the pulses' photon
#: number): a point's plan (scene, code, range gate, memory and time estimate) does not
#: depend on them, so it is made once for all their values (a grid of 90 noise by 100
#: signal values planned each of its 9 000 points, 6 min 44 s before its --max-time
#: refusal: an outside audit of 2026-12-03)
FLUX_KEYS = frozenset({"signal", "noise", "noise_split", "ambient", "background_rate",
                       "dark_count_rate"})


def _preflight(cfg: Any, scenes: dict[str, Any]) -> Any:
    """:func:`spslidar.pipeline.preflight` of ``cfg``, with the scene read once per distinct
    scene, size and depth window (``scenes`` holds them: loading it was nearly all of the
    check's time), and the instrument checked as a run checks it once the plan is known: the
    IRF through :func:`~spslidar.instrument.irf_kernel` at the code's period (a ``.npy`` of
    NaN or a file that is no array passed the check and failed every run, exit 1 with a
    folder written, where ``run --irf`` refuses it: an outside audit of 2026-12-03) and the
    detector model built with its options.

    Parameters
    ----------
    cfg : Config
        One point's configuration.
    scenes : dict[str, Any]
        The scenes loaded so far, by their arguments' canonical JSON; filled here.

    Returns
    -------
    Budget
        The run's memory and time estimate.

    Raises
    ------
    ConfigError
        Where the run would refuse the configuration.
    """
    from spslidar.detectors import build_detector
    from spslidar.instrument import irf_kernel, parse_irf
    from spslidar.pipeline.plan import detector_options, preflight_plan
    from spslidar.scenes import load_scene

    where = canonical_json([cfg.scene, cfg.size, cfg.depth_min, cfg.depth_max], "scene")
    if where not in scenes:
        scenes[where] = load_scene(cfg.scene, cfg.size, cfg.depth_min, cfg.depth_max)
    plan = preflight_plan(cfg, scenes[where])
    irf_kernel(parse_irf(cfg.irf), plan.acq.bin_width, plan.acq.period)
    build_detector(cfg.detector, **detector_options(cfg))
    return plan.budget


def _validate_run_points(points: Sequence[Mapping[str, Any]], where: Any,
                         ignored: list[dict[str, str]] | None = None,
                         unpriced: dict[str, int] | None = None,
                         memory: list[tuple[float, float | None]] | None = None,
                         costs: list[float] | None = None) -> float:
    """Check every point's run config before anything runs: a bad grid is bad input (one
    ConfigError naming the file), not a sweep of failed runs. Returns the estimated total
    time of the runs (seconds, from each configuration's budget); ``ignored`` receives each
    point's options that its configuration ignores
    (:func:`~spslidar.pipeline.plan.ignored_keys`), ``unpriced`` the number of points per
    detector model whose cost depends on the flux (not ``linear``: the GMAPD's dead-time
    model, which a run prices from its first block of patterns as it runs, not before),
    ``memory`` each point's estimated bytes with its ``max_memory`` (GB, or None), ``costs``
    each point's estimated seconds.

    Each point's configuration is validated (:class:`~spslidar.config.Config`, its noise
    model); the plan, the instrument and the estimate (:func:`_preflight`) once per distinct
    configuration but its seed and :data:`FLUX_KEYS`, processing keys included (they were
    left out, and a grid over solvers was priced, and its memory checked, at its first
    solver's).
    """
    from spslidar.config import Config
    from spslidar.detectors import DETECTORS
    from spslidar.detectors.counting import NoiseModel
    from spslidar.pipeline.plan import ignored_keys, report_only_keys

    seconds: dict[str, float] = {}
    peak: dict[str, float] = {}
    scenes: dict[str, Any] = {}
    linear: dict[str, bool] = {}
    noises: set[str] = set()
    #: each distinct point's (ignored options, plan key, max_memory, detector): a sweep's
    #: trials are one configuration, checked once
    done: dict[str, tuple[dict[str, str], str, Any, str]] = {}
    total = 0.0
    for params in points:
        config = {key: value for key, value in params.items()
                  if key not in (TRIAL_KEY, SCENE_HASH_KEY, IRF_HASH_KEY)}
        try:
            text = canonical_json(config)
            if text not in done:
                cfg = Config.from_dict(config)
                # the noise model as the run builds it, once per split, ambient model and
                # rates (its check of m_n is Config's, and building it was a sixth of the
                # check's time)
                noise = canonical_json([list(cfg.noise_split), cfg.ambient,
                                        cfg.background_rate, cfg.dark_count_rate])
                if noise not in noises:
                    NoiseModel(cfg.noise, tuple(cfg.noise_split), cfg.ambient,
                               cfg.background_rate, cfg.dark_count_rate)
                    noises.add(noise)
                # (of the point as given, a function of which its Config is: to_dict's deep
                # copy was a third of the check's time)
                key = canonical_json({k: v for k, v in config.items()
                                      if k.replace("-", "_") not in FLUX_KEYS and k != "seed"})
                if key not in seconds:
                    budget = _preflight(cfg, scenes)
                    seconds[key], peak[key] = budget.seconds, budget.bytes
                if cfg.detector not in linear:
                    linear[cfg.detector] = getattr(DETECTORS.load(cfg.detector), "linear", True)
                done[text] = ({**ignored_keys(cfg), **report_only_keys(cfg)}, key,
                              cfg.max_memory, cfg.detector)
        except (ConfigError, SpslidarError) as exc:
            raise ConfigError(f"{where}: {exc}") from None
        skip, key, max_memory, detector = done[text]
        if ignored is not None:
            ignored.append(dict(skip))
        total += seconds[key]
        if costs is not None:
            costs.append(seconds[key])
        if memory is not None:
            memory.append((peak[key], max_memory))
        if unpriced is not None and not linear[detector]:
            unpriced[detector] = unpriced.get(detector, 0) + 1
    return total


def _jobs_that_fit(memory: list[tuple[float, float | None]], workers: int) -> int:
    """The local workers whose runs fit at once: ``max_memory`` (or, where no point sets it,
    the memory available) holds each point's limit alone, so ``workers`` of the largest
    points at once must fit under it; fewer are run, and said, where they do not (a sweep of
    128x128 points at ``max_memory = 1.5`` peaked at 2.17 GB on two workers, an audit)."""
    from spslidar.machine import _gb, available_memory

    if not memory:
        return workers
    largest = max(b for b, _ in memory)
    caps = [c for _, c in memory if c is not None]
    limit = min(caps) * 1e9 if caps else available_memory()
    fit = max(1, int(limit // max(largest, 1.0)))
    if fit < workers:
        src = "max_memory" if caps else "memory available"
        print(f"sweep: note: {fit} run{'s' if fit > 1 else ''} at a time, not {workers}: "
              f"{workers} of its largest points at once need about {_gb(workers * largest)}, "
              f"more than the {_gb(limit)} {src} (each run is checked against it alone)",
              file=sys.stderr)
    return min(fit, workers)


def sweep_main(
    config_path: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    jobs: int = 1,
    scheduler: Any = None,
    progress: bool = True,
    *,
    func: Callable[[dict[str, Any]], Mapping[str, Any]] | None = None,
    max_time: float | None = None,
    overwrite: bool = False,
) -> int:
    """Run the sweep of a TOML config and write ``out_dir/results.csv``.

    Parameters
    ----------
    config_path : str or os.PathLike
        The sweep TOML file (see :func:`load_sweep_config`).
    out_dir : str or os.PathLike
        Output folder: ``runs/`` (cache, filled as points finish) and ``results.csv``
        (written atomically once every point has been attempted).
    jobs : int, default 1
        Local worker processes (see :func:`run_sweep`), at most the cores (a clamp is said on
        stderr); ignored, and said, with ``scheduler``.
    scheduler : str, distributed.Client or cluster, optional
        Dask scheduler (see :func:`run_sweep`); the estimate is shared among its workers'
        threads.
    progress : bool, default True
        Show a progress bar on stderr.
    func : Callable, optional
        The function of a point; default :func:`run_point`.
    max_time : float, optional
        Refuse a sweep whose estimated total time (the sum of the estimates of its runs not
        yet cached, before any runs, shared among the workers) exceeds this many seconds;
        one over 30 s says its estimate first.
    overwrite : bool, default False
        Replace the ``results.csv`` of another sweep (other points) in ``out_dir``; without
        it that is refused, while the same sweep again resumes (its points are recorded in
        the folder's marker as ``sweep_points``, a SHA-256).

    Returns
    -------
    int
        The number of failed points (0 when all succeeded). A one-line summary, and the first
        few errors, are printed on stderr.

    Raises
    ------
    ConfigError
        On bad input (a bad point, a folder that is not a sweep's, an estimate over
        ``max_time``...), before any run.
    WorkerLost
        Where a local worker process was killed under the sweep: the finished runs are
        cached, and the same call again resumes.
    SweepIncomplete
        Where the runs ran but ``results.csv`` could not be written (a full disk): the
        finished runs stay cached in ``out_dir/runs``, and the same call again writes it.
    """
    from spslidar.plugins import code_fingerprint

    spec = load_sweep_config(config_path)
    points = spec.points()  # files named as the TOML names them: seeds and keys follow those
    jobs = engine._check_jobs(jobs)  # before the estimate and the folder
    ignore: frozenset[str] = frozenset()
    if func is None:
        ignored: list[dict[str, str]] = []
        opened = [spec.resolve(point) for point in points]
        unpriced: dict[str, int] = {}
        memory: list[tuple[float, float | None]] = []
        costs: list[float] = []
        _validate_run_points(opened, config_path, ignored, unpriced, memory, costs)
        points = [{**point, **{k: hashed[k] for k in (SCENE_HASH_KEY, IRF_HASH_KEY)
                               if k in hashed}}
                  for point, hashed in zip(points, with_scene_hashes(opened), strict=True)]
        ignore = paired_keys()
        points = _seeded(points, ignored, ignore, spec.seed)
        from spslidar.pipeline.budget import check_time

        # only the runs not cached are priced (a complete 40-run sweep run again under
        # --max-time 1s was refused as "would take ~14 s", so a 90 %-done 6 h sweep could not
        # be resumed under the default 1 h: an audit of 2026-11-29)
        code = code_fingerprint()
        total, cached, stale, keys = 0.0, 0, 0, set()
        for point, cost in zip(points, costs, strict=True):
            key, result, old = cached_point_state(Path(out_dir) / "runs", point, spec.seed,
                                                  ignore, code)
            if key in keys:  # (run once, and cached once)
                continue
            keys.add(key)
            if result is not None:
                cached += 1
            else:
                total += cost
                # (a run cached by other code is priced, and the refusal said only "16 runs
                # would take ~2.1 s" of a sweep whose 16 runs were all cached: an audit)
                stale += old
        to_run = len(keys) - cached
        if scheduler is not None:
            # the cluster's threads run the points (the estimate was divided by --jobs, 1 by
            # default, and --jobs 64 on a 2-worker cluster divided it by 64: an audit of
            # 2026-11-29); --jobs is the local processes' and is ignored here, as run_sweep
            # ignores it
            workers = engine.cluster_threads(scheduler)
            if jobs != 1:
                print(f"sweep: note: --jobs {jobs} is ignored with --scheduler: the cluster's "
                      f"{workers} thread{'s' if workers != 1 else ''} run the points",
                      file=sys.stderr)
        else:
            # local workers are at most the cores (--jobs 1000 divided a 9 h sweep into 31 s),
            # said as run_sweep says it (--jobs 8 on 2 cores was clamped to 2 without a word
            # here: an audit of 2026-11-29), as a warning of the sweep's (an outside audit
            # of 2026-12-03)
            workers = (engine.clamp_jobs(jobs, to_run, prefix="spslidar sweep: warning")
                       if to_run else 1)
            if workers > 1:
                workers = _jobs_that_fit(memory, workers)
            if to_run:
                jobs = workers
        what = f"this sweep of {len(points)} runs"
        if cached or stale:
            what = (f"this sweep of {len(points)} runs ({cached} cached, not counted; "
                    f"{to_run} to run"
                    + (f", {stale} of them cached by other code (spslidar or its plugins "
                       f"changed)" if stale else "") + ")")
        check_time(total / max(1, min(max(to_run, 1), workers)), max_time, what)
        if unpriced:  # (a 3-point GMAPD sweep ran 70 s with nothing said, an audit)
            said = ", ".join(f"the {n} point{'s' if n > 1 else ''} through --detector {name}"
                             for name, n in unpriced.items())
            print(f"sweep: note: the estimate leaves out the detector model of {said}: its "
                  f"time depends on the flux (the camera at 16x16: 3.6 s a run at 0.03 photons "
                  f"per bin, 13 s at 0.8), so time one point with spslidar run first",
                  file=sys.stderr)
    from spslidar.outdir import (
        claim_folder,
        journal,
        record_outputs,
        release_folder,
    )
    if func is not None:
        code = code_fingerprint()

    if isinstance(scheduler, str):
        engine._probe_scheduler(scheduler)  # before the folder is made
    existed = Path(out_dir).exists()
    folder = claim_folder(out_dir, "sweep")  # new, empty or an earlier sweep's: never a user's
    # the sweep's identity: its points with their seeds, as the TOML gives them (a second
    # sweep of another grid replaced the first one's table without a word, an audit of
    # 2026-11-29; an edited scene or IRF file is the same sweep, run again)
    hashes = (SCENE_HASH_KEY, IRF_HASH_KEY)
    counts: dict[str, int] = {}
    try:  # (from the claim on: an interrupt left a folder of a marker, "nothing written")
        identity = sha256_hex(canonical_json(
            {"seed": spec.seed,
             "points": [{k: v for k, v in p.items() if k not in hashes} for p in points]},
            "points"))
        _check_replaceable(folder, out_dir, identity, overwrite)
        rows = engine.run_sweep(
            functools.partial(_run_opened, None if spec.path is None else str(spec.path.parent),
                              run_point if func is None else func),
            points,
            out_dir,
            seed=spec.seed,
            jobs=jobs,
            scheduler=scheduler,
            progress=progress,
            seed_ignore=ignore,
            code=code,  # an edited plugin or spslidar: its points run again
            counts=counts,
        )
    except Exception:  # refused before any point ran: leave no folder behind (a folder of
        # nothing but a marker was left by a pool that could not start: an audit of
        # 2026-11-30; where runs are cached, they stay)
        release_folder(folder, existed)
        raise
    except (KeyboardInterrupt, engine.WorkerLost):  # before any run finished: no folder of
        # nothing but a marker (a killed worker's line named a cache of no run)
        release_folder(folder, existed)
        raise
    from spslidar.outlock import folder_lock

    with folder_lock(folder):  # (two sweeps into one folder: checked again as it is written)
        _check_replaceable(folder, out_dir, identity, overwrite, after=True)
        csv_path = None
        try:
            with journal(folder, [RESULTS_CSV]):  # its SHA-256 in the marker before in place
                csv_path = write_csv(rows, Path(out_dir) / RESULTS_CSV)
            record_outputs(folder, [RESULTS_CSV], extra={"sweep_points": identity})
        except OSError as exc:
            # the runs ran: a full disk here is work that did not complete, not bad input
            # (it exited 2 and said nothing of the runs it left cached: an outside audit of
            # 2026-12-03)
            raise SweepIncomplete(_unwritten(out_dir, rows, exc, csv_path is not None)) \
                from None
    return say_outcome(rows, [*spec.grid, TRIAL_KEY], csv_path, counts)


class SweepIncomplete(RuntimeError):
    """The sweep's runs ran but its ``results.csv`` could not be written (a full disk): one
    line naming the folder left and what it holds; the command line gives it with exit
    status 1, the work did not complete."""


def _unwritten(out_dir: str | os.PathLike[str], rows: Sequence[Mapping[str, Any]],
               exc: OSError, written: bool = False) -> str:
    """:class:`SweepIncomplete`'s line: why ``results.csv`` was not written, the folder left
    and the cached runs in it that the same command reuses.

    Parameters
    ----------
    out_dir : str or os.PathLike
        The sweep's ``--out``.
    rows : Sequence[Mapping[str, Any]]
        Its rows, from :func:`~spslidar.experiments.sweep.engine.run_sweep`.
    exc : OSError
        What the write raised.
    written : bool, default False
        Whether ``results.csv`` was in place, and the marker's record of it failed.

    Returns
    -------
    str
        One line.
    """
    from spslidar.experiments.sweep.grid import ERROR_KEY

    why = exc.strerror or one_line(exc) or type(exc).__name__
    runs = Path(out_dir) / "runs"
    try:
        cached = sum(1 for p in runs.glob("*.json") if p.is_file())
    except OSError:
        cached = 0
    failed = sum(1 for row in rows if ERROR_KEY in row)
    held = (f"{cached} finished run{'s' if cached != 1 else ''} cached in {runs}" if cached
            else f"no finished run ({runs} is empty)")
    if failed:
        held += (f" ({failed} failed run{'s are' if failed != 1 else ' is'} not cached: "
                 f"{'they run' if failed != 1 else 'it runs'} again)")
    what = (f"{RESULTS_CSV} was written into {out_dir} but the folder's marker could not "
            f"record it" if written else f"{RESULTS_CSV} could not be written into {out_dir}")
    return (f"{what} ({why}): the folder is left holding {held}; free some space and run the "
            f"same command with --out {out_dir} again: it reads the cached runs instead of "
            f"running them and writes {RESULTS_CSV}")


def _check_replaceable(folder: Path, out_dir, identity: str, overwrite: bool,
                       after: bool = False) -> None:
    """Refuse, in one line, to replace a ``results.csv`` a user wrote or edited, or another
    sweep's without ``overwrite``; ``after``: checked again once the runs are done, where
    another command may have written there meanwhile (two sweeps into one folder: both said
    "results in", and the file held the second's points only, an outside audit of
    2026-11-29)."""
    from spslidar.outdir import foreign_outputs, read_marker

    late = (" while this sweep ran; its rows were not written (its runs are cached: run it "
            "again into another folder)") if after else ""
    if foreign_outputs(folder, [RESULTS_CSV]):  # a user's edit was replaced without a word
        raise SpslidarError(
            f"--out {out_dir}: {RESULTS_CSV} was not written by spslidar sweep (or changed "
            f"since){late or '; refusing to replace it (move it away, or choose another folder)'}")
    before = (read_marker(folder) or {}).get("sweep_points")
    if ((folder / RESULTS_CSV).is_file() and isinstance(before, str) and before != identity
            and not overwrite):
        raise SpslidarError(
            f"--out {out_dir}: holds the {RESULTS_CSV} of another sweep (other points)"
            + (late or "; pass --overwrite to replace it (its finished runs stay cached), or "
                       "choose another folder"))
