"""Monte-Carlo parameter sweeps: a grid of parameters x trials, run locally or on a Dask cluster.

Every point of a sweep is one call of a pure function ``func(params) -> dict`` (by default
:func:`run_point`, which runs the simulation/reconstruction pipeline and returns its metrics).
The engine

* expands a grid into points in a deterministic order (:func:`expand_grid`);
* gives every point a seed derived from the sweep seed and the point's parameters
  (:func:`derive_seed`), so results never depend on scheduling or on the order of the points;
* runs the points in-process (``jobs=1``), in a joblib process pool (``jobs > 1`` or ``-1``), or
  on a Dask cluster (``scheduler='tcp://HOST:PORT'`` or a ``distributed.Client``/cluster);
* caches every finished point in ``out_dir/runs/<key>.json`` (written atomically, by the
  calling process, as points finish), so an interrupted sweep resumes where it stopped;
* records a point whose function raises as a row with an ``error`` column and carries on
  (failed points are not cached: a rerun retries them).

Sweep configurations are TOML files (:func:`load_sweep_config`)::

    seed = 1
    trials = 3
    [base]          # any `spslidar run` config keys
    size = 32
    [grid]          # each key a list of values
    noise = [1, 5, 10]
    code_length = [1023, 4095]

and :func:`sweep_main` runs one and writes ``out_dir/results.csv`` (one row per run).

Notes
-----
The cache key covers the point's parameters (including its seed) but not the code of ``func``:
after changing the simulation code, use a fresh ``out_dir`` (or delete ``out_dir/runs``).
"""

from __future__ import annotations

import copy
import csv
import hashlib
import io
import itertools
import json
import math
import os
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from spslidar.errors import ConfigError

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised only on Python 3.10
    import tomli as tomllib

__all__ = [
    "SweepSpec",
    "derive_seed",
    "expand_grid",
    "load_sweep_config",
    "point_key",
    "run_point",
    "run_sweep",
    "sweep_main",
    "write_csv",
]

#: Parameter added to every point by :func:`expand_grid` (the Monte-Carlo trial index).
TRIAL_KEY = "trial"
#: Parameter holding a point's random seed (set by :func:`run_sweep` unless the point has one).
SEED_KEY = "seed"
#: Column holding the one-line error of a failed point.
ERROR_KEY = "error"
#: Seeds from :func:`derive_seed` lie in ``[0, SEED_BOUND)`` (valid for every numpy RNG API).
SEED_BOUND = 2**32
#: Length (hex digits) of the cache key of a point.
KEY_LENGTH = 16

_TOP_LEVEL_KEYS = ("seed", "trials", "base", "grid")
_CACHE_FORMAT = 1


# --------------------------------------------------------------------------------------------
# Canonical JSON and seeds
# --------------------------------------------------------------------------------------------


def _canonical(obj: Any, where: str = "params") -> Any:
    """Return a JSON-ready copy of ``obj`` (numpy scalars/arrays and tuples become plain values).

    Parameters
    ----------
    obj : Any
        A JSON-like value: dict with string keys, list/tuple, str, int, float, bool, None,
        numpy scalar or array, or an ``os.PathLike`` (stored as a string).
    where : str
        Dotted location of ``obj``, for error messages.

    Returns
    -------
    Any
        The same value built only from dict, list, str, int, float, bool and None.

    Raises
    ------
    ConfigError
        If ``obj`` holds a value of another type or a dict key that is not a string.
    """
    if obj is None or isinstance(obj, (bool, str)):
        return obj
    if isinstance(obj, int):
        return int(obj)
    if isinstance(obj, float):
        return float(obj)
    if isinstance(obj, np.generic):
        return _canonical(obj.item(), where)
    if isinstance(obj, np.ndarray):
        return _canonical(obj.tolist(), where)
    if isinstance(obj, Mapping):
        out = {}
        for key, value in obj.items():
            if not isinstance(key, str):
                raise ConfigError(f"{where}: key {key!r} is not a string")
            out[key] = _canonical(value, f"{where}.{key}")
        return out
    if isinstance(obj, (list, tuple)):
        return [_canonical(value, f"{where}[{i}]") for i, value in enumerate(obj)]
    if isinstance(obj, os.PathLike):
        return os.fspath(obj)
    raise ConfigError(
        f"{where} has unsupported type {type(obj).__name__} (use JSON-like values: "
        "numbers, strings, booleans, lists, dicts)"
    )


def _canonical_json(obj: Any, where: str = "params") -> str:
    """Serialize ``obj`` as canonical JSON: sorted keys, no spaces, floats as shortest repr."""
    return json.dumps(
        _canonical(obj, where),
        sort_keys=True,
        separators=(",", ":"),
        ensure_ascii=True,
        allow_nan=True,
    )


def _sha256(text: str) -> str:
    return hashlib.sha256(text.encode("ascii")).hexdigest()


def _check_int(value: Any, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise ConfigError(f"{name} must be an integer, got {value!r}")
    return int(value)


def derive_seed(seed: int, params: Mapping[str, Any]) -> int:
    """Derive the random seed of one sweep point from the sweep seed and its parameters.

    The seed is a stable hash (sha256 of the canonical JSON of ``{"seed": seed, "params":
    params}``, keys sorted, floats written as their shortest round-trip ``repr``): it is the
    same on every machine, in every process and whatever the order of the dict keys, and it
    changes with any parameter (``trial`` included), so results do not depend on scheduling.
    ``1`` and ``1.0`` are different values here.

    Parameters
    ----------
    seed : int
        The sweep seed.
    params : Mapping[str, Any]
        The point's parameters (JSON-like values; numpy scalars/arrays are accepted).

    Returns
    -------
    int
        A seed in ``[0, 2**32)``, valid for ``numpy.random.default_rng`` and ``RandomState``.

    Raises
    ------
    ConfigError
        If ``seed`` is not an integer or ``params`` holds a non-JSON-like value.
    """
    seed = _check_int(seed, "seed")
    if not isinstance(params, Mapping):
        raise ConfigError(f"params must be a dict, got {type(params).__name__}")
    digest = _sha256(_canonical_json({"seed": seed, "params": _canonical(params, "params")}))
    return int(digest[:16], 16) % SEED_BOUND


def point_key(params: Mapping[str, Any]) -> str:
    """Return the cache key of a point: the first 16 hex digits of the sha256 of its params.

    Parameters
    ----------
    params : Mapping[str, Any]
        The point's full parameters (seed included).

    Returns
    -------
    str
        The key; the point is cached in ``out_dir/runs/<key>.json``.
    """
    return _sha256(_canonical_json(params))[:KEY_LENGTH]


# --------------------------------------------------------------------------------------------
# Grids and TOML sweep configurations
# --------------------------------------------------------------------------------------------


def _check_grid(grid: Mapping[str, Any], where: str = "grid") -> None:
    if not isinstance(grid, Mapping):
        raise ConfigError(f"{where} must be a table of lists, got {type(grid).__name__}")
    for name, values in grid.items():
        if not isinstance(name, str):
            raise ConfigError(f"{where}: key {name!r} is not a string")
        if name == TRIAL_KEY:
            raise ConfigError(f"{where}.{TRIAL_KEY} is reserved; set the number of trials instead")
        if not isinstance(values, (list, tuple)) or len(values) == 0:
            raise ConfigError(f"{where}.{name} must be a non-empty list of values, got {values!r}")


def expand_grid(
    base: Mapping[str, Any], grid: Mapping[str, Sequence[Any]], trials: int = 1
) -> list[dict[str, Any]]:
    """Expand a parameter grid into sweep points (cartesian product x trials).

    Points come in a deterministic order: the grid keys in their insertion order, the first key
    varying slowest, and the trials of one combination adjacent (``trial`` varies fastest).

    Parameters
    ----------
    base : Mapping[str, Any]
        Parameters shared by every point (deep-copied into each one).
    grid : Mapping[str, Sequence[Any]]
        For each swept parameter, the non-empty list of its values; overrides ``base``.
    trials : int, default 1
        Monte-Carlo trials per grid combination; each point gets ``trial`` in
        ``0 .. trials - 1``.

    Returns
    -------
    list[dict[str, Any]]
        ``trials * prod(len(values))`` points; an empty grid gives ``trials`` copies of ``base``.

    Raises
    ------
    ConfigError
        If a grid value is not a non-empty list, ``trials < 1``, or ``trial`` is set in
        ``base`` or ``grid``.
    """
    if not isinstance(base, Mapping):
        raise ConfigError(f"base must be a table, got {type(base).__name__}")
    if TRIAL_KEY in base:
        raise ConfigError(f"base.{TRIAL_KEY} is reserved; set the number of trials instead")
    _check_grid(grid)
    trials = _check_int(trials, "trials")
    if trials < 1:
        raise ConfigError(f"trials must be >= 1, got {trials}")
    names = list(grid)
    points = []
    for combo in itertools.product(*(grid[name] for name in names)):
        for trial in range(trials):
            point = copy.deepcopy(dict(base))
            point.update(copy.deepcopy(dict(zip(names, combo, strict=True))))
            point[TRIAL_KEY] = trial
            points.append(point)
    return points


@dataclass(frozen=True)
class SweepSpec:
    """A sweep read from a TOML file by :func:`load_sweep_config`.

    Attributes
    ----------
    seed : int
        The sweep seed (point seeds are derived from it, see :func:`derive_seed`).
    trials : int
        Monte-Carlo trials per grid combination.
    base : dict[str, Any]
        Parameters shared by every point.
    grid : dict[str, list[Any]]
        Swept parameters and their values.
    path : Path or None
        The file it was read from.
    """

    seed: int = 0
    trials: int = 1
    base: dict[str, Any] = field(default_factory=dict)
    grid: dict[str, list[Any]] = field(default_factory=dict)
    path: Path | None = None

    def points(self) -> list[dict[str, Any]]:
        """Return the sweep points, ``expand_grid(base, grid, trials)``.

        Returns
        -------
        list[dict[str, Any]]
            The points, in the deterministic order of :func:`expand_grid`.
        """
        return expand_grid(self.base, self.grid, self.trials)


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


def load_sweep_config(path: str | os.PathLike[str]) -> SweepSpec:
    """Read a sweep configuration from a TOML file.

    The file has optional top-level ``seed`` (int, default 0) and ``trials`` (int >= 1,
    default 1), a ``[base]`` table of shared run-config keys, and a ``[grid]`` table whose every
    value is a non-empty list. ``seed`` inside ``[grid]`` sets explicit point seeds;
    ``seed`` inside ``[base]`` is refused when ``trials > 1`` (every trial would be identical).

    Parameters
    ----------
    path : str or os.PathLike
        The TOML file.

    Returns
    -------
    SweepSpec
        The validated sweep.

    Raises
    ------
    ConfigError
        If the file is missing or unreadable, is not valid TOML (the message names the file and
        line), has unknown top-level keys or tables, or holds invalid values.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"sweep config not found: {path}") from None
    except IsADirectoryError:
        raise ConfigError(f"sweep config is a directory, not a file: {path}") from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read sweep config {path}: {_one_line(exc)}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"{path}: invalid TOML: {_one_line(exc)}") from None

    unknown = [key for key in data if key not in _TOP_LEVEL_KEYS]
    if unknown:
        kinds = ["table" if isinstance(data[key], dict) else "key" for key in unknown]
        listed = ", ".join(f"{kind} '{key}'" for kind, key in zip(kinds, unknown, strict=True))
        raise ConfigError(
            f"{path}: unknown top-level {listed} (allowed: seed, trials, [base], [grid])"
        )
    seed = _check_int(data.get("seed", 0), f"{path}: seed")
    trials = _check_int(data.get("trials", 1), f"{path}: trials")
    if trials < 1:
        raise ConfigError(f"{path}: trials must be >= 1, got {trials}")
    base = data.get("base", {})
    if not isinstance(base, dict):
        raise ConfigError(f"{path}: base must be a table ([base]), got {base!r}")
    grid = data.get("grid", {})
    if not isinstance(grid, dict):
        raise ConfigError(f"{path}: grid must be a table ([grid]), got {grid!r}")
    try:
        _check_grid(grid)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None
    if TRIAL_KEY in base:
        raise ConfigError(f"{path}: base.{TRIAL_KEY} is reserved; set trials instead")
    if SEED_KEY in base and trials > 1 and SEED_KEY not in grid:
        raise ConfigError(
            f"{path}: base.seed gives every trial the same noise; set the top-level seed instead"
        )
    return SweepSpec(
        seed=seed,
        trials=trials,
        base=base,
        grid={name: list(values) for name, values in grid.items()},
        path=path,
    )


# --------------------------------------------------------------------------------------------
# Atomic files and the run cache
# --------------------------------------------------------------------------------------------


def atomic_write_text(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically (temporary file in the same folder + os.replace)."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8", newline="") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise


def _load_cached(path: Path, params_json: str) -> dict[str, Any] | None:
    """Return the cached result at ``path`` if it exists and was computed for these params."""
    try:
        with open(path, encoding="utf-8") as fh:
            record = json.load(fh)
    except (OSError, ValueError):
        return None
    if not isinstance(record, dict) or not isinstance(record.get("result"), dict):
        return None
    try:
        if _canonical_json(record.get("params")) != params_json:
            return None
    except ConfigError:
        return None
    return record["result"]


def _store(path: Path, key: str, params: Any, result: dict[str, Any], elapsed: float) -> None:
    record = {
        "format": _CACHE_FORMAT,
        "key": key,
        "params": params,
        "result": result,
        "elapsed_s": round(elapsed, 6),
    }
    # keys in insertion order (not sorted): a cached result then gives the same columns, in
    # the same order, as a fresh one
    atomic_write_text(path, json.dumps(record, indent=1, allow_nan=True) + "\n")


# --------------------------------------------------------------------------------------------
# Running the points
# --------------------------------------------------------------------------------------------


def _error_message(exc: BaseException) -> str:
    message = _one_line(str(exc))
    name = type(exc).__name__
    text = f"{name}: {message}" if message else name
    return text if len(text) <= 500 else text[:497] + "..."


def _call(func: Callable[[dict[str, Any]], Any], params: dict[str, Any]) -> tuple[str, Any, float]:
    """Run one point, catching its exception: ``("ok", result, s)`` or ``("error", message, s)``.

    Top-level so that joblib and Dask can pickle it.
    """
    start = time.perf_counter()
    try:
        result = func(params)
    except Exception as exc:
        return "error", _error_message(exc), time.perf_counter() - start
    return "ok", result, time.perf_counter() - start


def _normalize_result(result: Any) -> dict[str, Any]:
    """Round-trip a point's result through JSON, so fresh and cached rows are identical."""
    if not isinstance(result, Mapping):
        raise TypeError(f"func returned {type(result).__name__}, expected a dict")
    try:
        text = json.dumps(_canonical(result, "result"), allow_nan=True)
    except ConfigError as exc:
        raise TypeError(str(exc)) from None
    return json.loads(text)


def _run_local(
    func: Callable[[dict[str, Any]], Any], tasks: list[tuple[int, dict[str, Any]]], jobs: int
) -> Iterator[tuple[int, tuple[str, Any, float]]]:
    """Yield ``(task index, outcome)`` as tasks finish, in-process or in a joblib pool."""
    if jobs == 1 or len(tasks) == 1:
        for index, params in tasks:
            yield index, _call(func, params)
        return

    from joblib import Parallel, delayed

    def calls(chunk: list[tuple[int, dict[str, Any]]]) -> Iterator[Any]:
        return (delayed(_call_indexed)(func, index, params) for index, params in chunk)

    try:
        parallel = Parallel(n_jobs=jobs, return_as="generator_unordered")
    except (TypeError, ValueError):  # joblib < 1.4: run in batches, caching after each
        parallel = Parallel(n_jobs=jobs)
        batch = 4 * max(1, parallel.n_jobs if parallel.n_jobs > 0 else os.cpu_count() or 1)
        for start in range(0, len(tasks), batch):
            yield from parallel(calls(tasks[start : start + batch]))
        return
    outputs = parallel(calls(tasks))
    try:
        yield from outputs
    finally:
        close = getattr(outputs, "close", None)
        if close is not None:
            close()


def _call_indexed(
    func: Callable[[dict[str, Any]], Any], index: int, params: dict[str, Any]
) -> tuple[int, tuple[str, Any, float]]:
    return index, _call(func, params)


def _dask_client(scheduler: Any) -> tuple[Any, bool]:
    """Return ``(client, owned)`` for a scheduler address, Client or cluster object."""
    try:
        import distributed
    except ImportError:
        raise ConfigError(
            "scheduler= needs dask.distributed, which is not installed: install spslidar[dask]"
        ) from None
    if isinstance(scheduler, distributed.Client):
        return scheduler, False
    if isinstance(scheduler, str):
        if not scheduler.strip():
            raise ConfigError("scheduler must be an address like 'tcp://HOST:PORT', got ''")
        try:
            return distributed.Client(scheduler), True
        except (OSError, TimeoutError, ValueError) as exc:
            raise ConfigError(
                f"cannot connect to dask scheduler {scheduler}: {_error_message(exc)}"
            ) from None
    if isinstance(scheduler, distributed.deploy.Cluster):
        return distributed.Client(scheduler), True
    raise ConfigError(
        "scheduler must be an address like 'tcp://HOST:PORT', a distributed.Client or a cluster, "
        f"got {type(scheduler).__name__}"
    )


def _run_dask(
    func: Callable[[dict[str, Any]], Any], tasks: list[tuple[int, dict[str, Any]]], scheduler: Any
) -> Iterator[tuple[int, tuple[str, Any, float]]]:
    """Yield ``(task index, outcome)`` as tasks finish on a Dask cluster."""
    client, owned = _dask_client(scheduler)
    import distributed

    futures = {}
    try:
        for index, params in tasks:
            futures[client.submit(_call, func, params, pure=False)] = index
        for future in distributed.as_completed(list(futures)):
            index = futures[future]
            try:
                outcome = future.result()
            except Exception as exc:  # worker died, lost data...: a failed point
                outcome = ("error", _error_message(exc), math.nan)
            yield index, outcome
    finally:
        pending = [f for f in futures if not f.done()]
        if pending:
            client.cancel(pending)
        if owned:
            client.close()


def _check_jobs(jobs: Any) -> int:
    jobs = _check_int(jobs, "jobs")
    if jobs == 0:
        raise ConfigError("jobs must be >= 1 or negative (-1: all cores), got 0")
    return jobs


def run_sweep(
    func: Callable[[dict[str, Any]], Mapping[str, Any]],
    points: Iterable[Mapping[str, Any]],
    out_dir: str | os.PathLike[str],
    *,
    seed: int = 0,
    jobs: int = 1,
    scheduler: Any = None,
    progress: bool = True,
    seed_ignore: Iterable[str] = (),
) -> list[dict[str, Any]]:
    """Run ``func`` on every point, caching each finished point, and return one row per point.

    Each point's params get a ``seed`` key, ``derive_seed(seed, point)`` of the point without
    its ``seed_ignore`` keys, unless the point already has one. A point whose result is cached
    in ``out_dir/runs/<key>.json`` (for the same params) is loaded, not recomputed; every other
    point is run and, on success, cached at once (atomically), so an interrupted sweep resumes
    where it stopped. A point whose ``func``
    raises becomes a row with an ``error`` column (``"Type: message"``) and is not cached.

    Parameters
    ----------
    func : Callable[[dict], Mapping]
        A pure function of the params returning a dict of JSON-like results (numpy scalars and
        arrays are converted). Must be picklable for ``jobs != 1`` or ``scheduler``.
    points : Iterable[Mapping[str, Any]]
        The points, e.g. from :func:`expand_grid`; values must be JSON-like.
    out_dir : str or os.PathLike
        Output folder (created if missing); runs are cached in ``out_dir/runs``.
    seed : int, default 0
        The sweep seed.
    jobs : int, default 1
        Local worker processes (joblib ``n_jobs``: ``-1`` for all cores); ``1`` runs
        in-process with no pool. Ignored when ``scheduler`` is given.
    scheduler : str, distributed.Client or cluster, optional
        Run on a Dask cluster instead: a scheduler address (``'tcp://HOST:PORT'``), a
        ``distributed.Client``, or a cluster object such as ``distributed.LocalCluster``.
        ``func`` must be importable on the workers.
    progress : bool, default True
        Show a tqdm progress bar on stderr (only when stderr is a terminal).
    seed_ignore : Iterable[str], optional
        Parameters left out of the seed: points that differ only in them get the same seed,
        i.e. the same random draws (a paired comparison; e.g. solvers or regularisation
        weights on the same simulated measurement). They still have their own cache keys.

    Returns
    -------
    list[dict[str, Any]]
        One row per point, in the order of ``points``: the params (with ``seed``) merged with
        the results (a result key equal to a param name overrides it), or with ``error``.

    Raises
    ------
    ConfigError
        On invalid arguments, non-JSON-like params, an out_dir that is not a folder, or a
        missing dask installation when ``scheduler`` is given.
    """
    seed = _check_int(seed, "seed")
    jobs = _check_jobs(jobs)
    out_dir = Path(out_dir)
    if isinstance(seed_ignore, str):
        raise ConfigError("seed_ignore must be a collection of parameter names, not a string")
    ignore = frozenset(seed_ignore)
    if out_dir.exists() and not out_dir.is_dir():
        raise ConfigError(f"out_dir is not a folder: {out_dir}")
    runs_dir = out_dir / "runs"
    runs_dir.mkdir(parents=True, exist_ok=True)

    full_params: list[dict[str, Any]] = []
    keys: list[str] = []
    params_json: dict[str, str] = {}
    for i, point in enumerate(points):
        if not isinstance(point, Mapping):
            raise ConfigError(f"point {i} must be a dict, got {type(point).__name__}")
        params = dict(point)
        _canonical(params, f"point {i}")  # validate first, for a clear message
        if SEED_KEY not in params:
            seeded = {k: v for k, v in params.items() if k not in ignore}
            params[SEED_KEY] = derive_seed(seed, seeded)
        text = _canonical_json(params, f"point {i}")
        key = _sha256(text)[:KEY_LENGTH]
        full_params.append(params)
        keys.append(key)
        params_json.setdefault(key, text)

    results: dict[str, dict[str, Any]] = {}
    errors: dict[str, str] = {}
    tasks: list[tuple[int, dict[str, Any]]] = []
    task_keys: list[str] = []
    seen: set[str] = set()
    for i, key in enumerate(keys):
        if key in seen:
            continue
        seen.add(key)
        cached = _load_cached(runs_dir / f"{key}.json", params_json[key])
        if cached is not None:
            results[key] = cached
        else:
            tasks.append((len(tasks), full_params[i]))
            task_keys.append(key)

    n_unique = len(results) + len(tasks)
    from tqdm import tqdm

    bar = tqdm(
        total=n_unique,
        initial=len(results),
        desc="sweep",
        unit="run",
        disable=None if progress else True,
        file=sys.stderr,
    )
    try:
        if tasks:
            if scheduler is not None:
                outcomes = _run_dask(func, tasks, scheduler)
            else:
                outcomes = _run_local(func, tasks, jobs)
            for index, (status, payload, elapsed) in outcomes:
                key = task_keys[index]
                if status == "ok":
                    try:
                        result = _normalize_result(payload)
                    except TypeError as exc:
                        status, payload = "error", _error_message(exc)
                    else:
                        results[key] = result
                        stored_params = json.loads(params_json[key])
                        _store(runs_dir / f"{key}.json", key, stored_params, result, elapsed)
                if status != "ok":
                    errors[key] = str(payload)
                    bar.set_postfix(failed=len(errors), refresh=False)
                bar.update(1)
    finally:
        bar.close()

    rows = []
    for params, key in zip(full_params, keys, strict=True):
        if key in results:
            rows.append({**params, **copy.deepcopy(results[key])})
        else:
            rows.append({**params, ERROR_KEY: errors[key]})
    return rows


# --------------------------------------------------------------------------------------------
# Tidy CSV output
# --------------------------------------------------------------------------------------------


def _flatten(row: Mapping[str, Any], prefix: str = "") -> dict[str, Any]:
    out: dict[str, Any] = {}
    for key, value in row.items():
        name = f"{prefix}{key}"
        if isinstance(value, Mapping) and value:
            items = _flatten(value, f"{name}.")
        else:
            items = {name: value}
        for column, item in items.items():
            if column in out:
                raise ConfigError(f"column {column!r} appears twice after flattening nested dicts")
            out[column] = item
    return out


def _cell(value: Any) -> Any:
    value = _canonical(value, "value")
    if value is None:
        return ""
    if isinstance(value, (list, dict)):
        return json.dumps(value, allow_nan=True)
    return value


def write_csv(rows: Iterable[Mapping[str, Any]], path: str | os.PathLike[str]) -> Path:
    """Write sweep rows as a tidy CSV (one row per run, one column per parameter or metric).

    Columns are the union of the rows' keys in first-seen order (``error`` last); nested
    dicts are flattened as ``a.b``, lists are written as JSON, missing values and None as empty
    cells. The file is written atomically.

    Parameters
    ----------
    rows : Iterable[Mapping[str, Any]]
        The rows, e.g. from :func:`run_sweep`.
    path : str or os.PathLike
        The CSV file; its folder must exist.

    Returns
    -------
    Path
        ``path``.

    Raises
    ------
    ConfigError
        If a row is not a dict, a value is not JSON-like, or two keys flatten to one column.
    """
    path = Path(path)
    flat = []
    for i, row in enumerate(rows):
        if not isinstance(row, Mapping):
            raise ConfigError(f"row {i} must be a dict, got {type(row).__name__}")
        flat.append(_flatten(row))
    columns: dict[str, None] = {}
    for row in flat:
        columns.update(dict.fromkeys(row))
    if ERROR_KEY in columns:
        del columns[ERROR_KEY]
        columns[ERROR_KEY] = None
    buffer = io.StringIO()
    writer = csv.DictWriter(buffer, fieldnames=list(columns), restval="", lineterminator="\n")
    writer.writeheader()
    for row in flat:
        writer.writerow({name: _cell(value) for name, value in row.items()})
    atomic_write_text(path, buffer.getvalue())
    return path


# --------------------------------------------------------------------------------------------
# Pipeline entry points
# --------------------------------------------------------------------------------------------


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

    config = {key: value for key, value in params.items() if key != TRIAL_KEY}
    return run_metrics(config)


def _validate_run_points(points: Sequence[Mapping[str, Any]], where: Any) -> None:
    """Check every point's run config before anything runs: a bad grid is bad input (one
    ConfigError naming the file), not a sweep of failed runs."""
    from spslidar.config import Config

    for params in points:
        config = {key: value for key, value in params.items() if key != TRIAL_KEY}
        try:
            Config.from_dict(config).validate()
        except ConfigError as exc:
            raise ConfigError(f"{where}: {exc}") from None


def sweep_main(
    config_path: str | os.PathLike[str],
    out_dir: str | os.PathLike[str],
    jobs: int = 1,
    scheduler: Any = None,
    progress: bool = True,
    *,
    func: Callable[[dict[str, Any]], Mapping[str, Any]] | None = None,
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
        Local worker processes (see :func:`run_sweep`).
    scheduler : str, distributed.Client or cluster, optional
        Dask scheduler (see :func:`run_sweep`).
    progress : bool, default True
        Show a progress bar on stderr.
    func : Callable, optional
        The function of a point; default :func:`run_point`.

    Returns
    -------
    int
        The number of failed points (0 when all succeeded). A one-line summary, and the first
        few errors, are printed on stderr.
    """
    spec = load_sweep_config(config_path)
    points = spec.points()
    ignore: frozenset[str] = frozenset()
    if func is None:
        from spslidar.pipeline import PROCESSING_KEYS

        _validate_run_points(points, config_path)
        ignore = PROCESSING_KEYS
    rows = run_sweep(
        run_point if func is None else func,
        points,
        out_dir,
        seed=spec.seed,
        jobs=jobs,
        scheduler=scheduler,
        progress=progress,
        seed_ignore=ignore,
    )
    csv_path = write_csv(rows, Path(out_dir) / "results.csv")
    failed = [row for row in rows if ERROR_KEY in row]
    print(
        f"sweep: {len(rows)} runs, {len(rows) - len(failed)} ok, {len(failed)} failed; "
        f"results in {csv_path}",
        file=sys.stderr,
    )
    for row in failed[:3]:
        where = ", ".join(f"{name}={row.get(name)!r}" for name in [*spec.grid, TRIAL_KEY])
        print(f"sweep: failed ({where}): {row[ERROR_KEY]}", file=sys.stderr)
    if len(failed) > 3:
        print(f"sweep: ... and {len(failed) - 3} more failures (see results.csv)", file=sys.stderr)
    return len(failed)
