"""Running sweep points: the executors (in-process, joblib, Dask) and :func:`run_sweep`.

:func:`run_sweep` seeds every point (:func:`~spslidar.experiments.sweep.grid.derive_seed`),
loads the points already cached, runs the others through one executor and caches each as it
finishes (:mod:`spslidar.experiments.sweep.store`). The ``spslidar sweep`` command's TOML sweep
of pipeline runs is :mod:`spslidar.experiments.sweep.command`.
"""

from __future__ import annotations

import copy
import json
import math
import os
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from concurrent.futures.process import BrokenProcessPool  # loky's are subclasses
from pathlib import Path
from typing import Any

from spslidar.errors import ConfigError
from spslidar.experiments.sweep.grid import (
    ERROR_KEY,
    canonical,
    canonical_json,
    check_int,
    one_line,
    text_key,
    with_seed,
)
from spslidar.experiments.sweep.store import cached_state, store_run

#: the table a sweep writes into its folder (known by its SHA-256 in the folder's marker)
RESULTS_CSV = "results.csv"

__all__ = ["WorkerLost", "run_sweep"]


class WorkerLost(RuntimeError):
    """A local worker process ended under the sweep (killed by the OS, its memory guard or a
    user): the runs that finished are cached, the others were not run. Its message is one line
    that says so (:func:`run_sweep` adds how many are cached and where); the command line
    gives it with exit status 1, the work did not complete."""

# --------------------------------------------------------------------------------------------
# Running the points
# --------------------------------------------------------------------------------------------


def _error_message(exc: BaseException) -> str:
    message = one_line(str(exc))
    name = type(exc).__name__
    text = f"{name}: {message}" if message else name
    return text if len(text) <= 500 else text[:497] + "..."


def _call(func: Callable[[dict[str, Any]], Any], params: dict[str, Any],
          plugins: tuple[str, ...] = ()) -> tuple[str, Any, float]:
    """Run one point, catching its exception: ``("ok", result, s)`` or ``("error", message, s)``.
    ``plugins`` (the parent's :mod:`spslidar.plugins`) are imported first: a pool worker
    started before they were loaded, or on another machine, has not (a sweep's every point
    was "unknown config key" in the workers, an audit).

    Top-level so that joblib and Dask can pickle it.
    """
    start = time.perf_counter()
    try:
        if plugins:
            from spslidar.plugins import load_plugins

            load_plugins(list(plugins))
        # (a copy: a function that changed its params changed the row's, an audit)
        result = func(copy.deepcopy(params))
    except KeyboardInterrupt:  # Ctrl-C, SIGTERM, SIGHUP (Terminated): the command stops
        raise
    except BaseException as exc:  # noqa: BLE001 - a point's SystemExit is the point's failure
        # (a plugin stage's SystemExit("bad boom") at one point ended the sweep with "bad
        # boom", exit 1, no results.csv and the other points never run: an audit of
        # 2026-11-29)
        return "error", _error_message(exc), time.perf_counter() - start
    return "ok", result, time.perf_counter() - start


def _normalize_result(result: Any) -> dict[str, Any]:
    """Round-trip a point's result through JSON, so fresh and cached rows are identical."""
    if not isinstance(result, Mapping):
        raise TypeError(f"func returned {type(result).__name__}, expected a dict")
    try:
        text = json.dumps(canonical(result, "result"), allow_nan=True)
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

    import warnings

    from spslidar.plugins import plugin_specs

    # loky replaces a worker that stopped (its memory guard, or its idle timeout) and runs the
    # queued jobs on the new one, saying so as a UserWarning: every `reproduce all` printed it
    # (stop 52's code too), with every result in place
    said = "A worker stopped while some jobs were given to the executor"
    with _FILTER_LOCK:  # (one filter for the sweeps running at once, taken out by the last)
        if not _FILTER["users"]:
            before = list(getattr(warnings, "filters", None) or [])
            warnings.filterwarnings("ignore", message=said, category=UserWarning)
            # (ours only: where filters are kept per context, as Python 3.14's free-threaded
            # build does, the global list's first filter is someone else's, and one the
            # caller had already set is the caller's: both were taken out for good, an audit
            # and a review of 2026-11-30)
            filters = getattr(warnings, "filters", None)
            first = filters[0] if isinstance(filters, list) and filters else None
            ours = (first is not None and first[0] == "ignore" and first[2] is UserWarning
                    and getattr(first[1], "pattern", None) == said and first not in before)
            _FILTER["added"] = first if ours else None
        _FILTER["users"] += 1
    try:
        yield from _run_pool(func, tasks, jobs, tuple(plugin_specs()))
    finally:
        # (the filter stayed in the process for good after a sweep: an audit of 2026-11-30;
        # taken out as a plain list edit, as spslidar.capture takes out its own)
        with _FILTER_LOCK:
            _FILTER["users"] -= 1
            added = _FILTER["added"]
            if not _FILTER["users"] and added is not None and added in warnings.filters:
                warnings.filters.remove(added)


#: the loky-restart filter the sweeps running in this process share
_FILTER_LOCK = threading.Lock()
_FILTER: dict[str, Any] = {"users": 0, "added": None}


def _run_pool(func: Callable[[dict[str, Any]], Any], tasks: list[tuple[int, dict[str, Any]]],
              jobs: int, plugins: tuple) -> Iterator[tuple[int, tuple[str, Any, float]]]:
    """:func:`_run_local`'s joblib pool (``jobs`` workers, the ``plugins`` loaded in each)."""
    from joblib import Parallel, delayed

    cpus = os.environ.get("LOKY_MAX_CPU_COUNT")
    if cpus is not None:
        try:
            int(cpus)
        except ValueError:  # (joblib's int() traceback, an audit of 2026-11-30)
            raise ConfigError(f"LOKY_MAX_CPU_COUNT={cpus!r} in the environment is not a "
                              f"number of CPUs, which joblib's workers read: unset it or give "
                              f"a whole number") from None

    def calls(chunk: list[tuple[int, dict[str, Any]]]) -> Iterator[Any]:
        return (delayed(_call_indexed)(func, index, params, plugins) for index, params in chunk)

    # (joblib >= 1.4, the floor: a batched fallback for older ones took 61 s to see a killed
    # worker and named no run it finished; a portability audit)
    parallel = Parallel(n_jobs=jobs, return_as="generator_unordered")
    try:
        outputs = parallel(calls(tasks))
    except (RuntimeError, OSError) as exc:
        _stop_workers()
        if _out_of_processes(exc):
            raise ConfigError(f"cannot start {jobs} worker processes: {exc} (the process "
                              f"limit, ulimit -u, is reached): use --jobs 1") from None
        raise
    try:
        yield from outputs
    except BrokenProcessPool as exc:
        # (a worker killed by the OS, kill -KILL, ended the sweep in a 30-line traceback of
        # joblib's TerminatedWorkerError, exit 1, no word of the runs cached: an audit of
        # 2026-11-29)
        _stop_workers()
        raise WorkerLost(_worker_lost(exc)) from None
    except BaseException:
        _stop_workers()
        raise
    finally:
        close = getattr(outputs, "close", None)
        if close is not None:
            close()


def cluster_threads(scheduler: Any) -> int:
    """The threads of a Dask cluster's workers (``distributed.Client.nthreads``), at least 1
    (a cluster whose workers have not joined yet: they run the points as they come); what a
    sweep's or a reproduction's time estimate is shared among with a scheduler."""
    client, owned = _dask_client(scheduler)
    try:
        return max(1, sum(client.nthreads().values()))
    finally:
        if owned:
            client.close()


def _worker_lost(exc: BaseException) -> str:
    """What ended a pool worker, from loky's message: ``"a worker process was killed (signal 9:
    out of memory?)"``, or its exit code where it exited."""
    import re

    text = str(exc)
    signal_match = re.search(r"SIG\w*\((-?\d+)\)", text)
    if signal_match:
        number = abs(int(signal_match.group(1)))
        why = ": out of memory?" if number == 9 else ""
        return f"a worker process was killed (signal {number}{why})"
    exit_match = re.search(r"EXIT\((-?\d+)\)", text)
    if exit_match:
        return f"a worker process ended (exit status {exit_match.group(1)})"
    return f"the worker pool broke ({_error_message(exc)})"


def _out_of_processes(exc: BaseException) -> bool:
    """Whether starting the pool failed for want of processes or threads (``ulimit -u``)."""
    import errno

    if isinstance(exc, OSError):
        return exc.errno in (errno.EAGAIN, errno.ENOMEM)
    return "can't start new thread" in str(exc)


def _call_indexed(
    func: Callable[[dict[str, Any]], Any], index: int, params: dict[str, Any],
    plugins: tuple[str, ...] = (),
) -> tuple[int, tuple[str, Any, float]]:
    # in a pool worker: Ctrl-C reaches the whole process group, but only the parent acts on
    # it (it stops the pool); a worker's own KeyboardInterrupt traceback would be noise
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    return index, _call(func, params, plugins)


def _stop_workers() -> None:
    """Kill the pool's worker processes now (after Ctrl-C or SIGTERM): none may outlive the
    command (SIGTERM to 'sweep --jobs 2' left four processes running)."""
    try:
        from joblib.externals.loky import get_reusable_executor

        get_reusable_executor().shutdown(wait=True, kill_workers=True)
    except Exception:  # pragma: no cover - best effort on the way out
        pass


#: seconds to wait for a TCP connection to a Dask scheduler before saying it is not there
SCHEDULER_PROBE_S = 3.0


def _probe_scheduler(address: str) -> None:
    """A plain TCP connection to a ``tcp://HOST:PORT`` scheduler first, with a short timeout,
    so that nothing listening is said within seconds (``distributed.Client`` retried for
    31 s). Other protocols are left to the client."""
    import socket
    from urllib.parse import urlsplit

    if "://" not in address:  # dask reads HOST:PORT as tcp://HOST:PORT
        if ":" not in address:
            raise ConfigError(f"scheduler address {address!r} is not PROTOCOL://HOST:PORT "
                              f"or HOST:PORT (e.g. tcp://127.0.0.1:8786)")
        address = f"tcp://{address}"
    if not address.startswith("tcp://"):
        return
    try:
        parts = urlsplit(address)
        host, port = parts.hostname, parts.port
    except ValueError:
        host = port = None
    if not host or not port:
        raise ConfigError(f"scheduler address {address!r} is not tcp://HOST:PORT")
    try:
        with socket.create_connection((host, port), timeout=SCHEDULER_PROBE_S):
            pass
    except OSError as exc:
        reason = "timed out" if isinstance(exc, TimeoutError) else (exc.strerror or str(exc))
        raise ConfigError(f"cannot connect to dask scheduler {address}: {reason} (is a "
                          f"scheduler running there?)") from None


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
        _probe_scheduler(scheduler)
        try:
            return distributed.Client(scheduler, timeout=10), True
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

    from spslidar.plugins import plugin_specs

    plugins = tuple(plugin_specs())
    futures = {}
    try:
        for index, params in tasks:
            futures[client.submit(_call, func, params, plugins, pure=False)] = index
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
    """``jobs`` as given: a positive number of workers or -1 (all cores); anything else is a
    one-line ConfigError (``--jobs -5`` was passed on to joblib as given)."""
    jobs = check_int(jobs, "jobs")
    if jobs == 0 or jobs < -1:
        raise ConfigError(f"--jobs must be a positive number of worker processes or -1 (all "
                          f"cores), got {jobs}")
    return jobs


#: seconds between the plain progress lines written when stderr is not a terminal
PLAIN_PROGRESS_S = 5.0


def _is_tty(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError):
        return False


#: tasks (processes and threads: Linux counts both against ``ulimit -u``) a pool adds to the
#: parent: the executor's manager and queue threads and the two resource trackers (6 measured
#: with loky 3.4, rounded up)
POOL_PARENT_TASKS = 8


def _tasks_per_worker(cores: int) -> int:
    """Tasks one pool worker may hold: itself and the thread pools of NumPy's and SciPy's
    BLAS (one thread per core each; 3 measured at start-up on 2 cores, before SciPy loads)."""
    return 2 + 2 * cores


def _process_headroom() -> tuple[int, int] | None:
    """``(limit, in use)`` of the tasks this user may run (``ulimit -u``, RLIMIT_NPROC, which
    Linux counts in threads), or None where there is no such limit (none set, root, or no
    ``/proc`` to count them)."""
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_NPROC)
    except (ImportError, AttributeError, OSError, ValueError):
        return None
    if soft == resource.RLIM_INFINITY or soft <= 0 or os.getuid() == 0:
        return None  # root is not held to RLIMIT_NPROC
    uid, used = os.getuid(), 0
    try:
        pids = [d for d in os.listdir("/proc") if d.isdigit()]
    except OSError:
        return None
    for pid in pids:
        try:
            with open(f"/proc/{pid}/status", encoding="utf-8", errors="replace") as fh:
                fields = dict(line.split(":", 1) for line in fh if ":" in line)
            if int(fields["Uid"].split()[0]) == uid:
                used += int(fields.get("Threads", "1"))
        except (OSError, KeyError, ValueError, IndexError):
            continue  # a process that ended while we looked, or one we may not read
    return int(soft), used


def _cores() -> int:
    """The cores this process may run on."""
    return len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (
        os.cpu_count() or 1)


def clamp_jobs(jobs: int, n_tasks: int, prefix: str = "spslidar") -> int:
    """The worker processes worth starting: at most one per task, per core and per what the
    process limit (``ulimit -u``) leaves room for (``-1``: the cores); a clamp is said on
    stderr after ``prefix`` (``--jobs 1000`` for 3 runs started a 1000-process pool, and where
    the process limit was low it ended in a traceback). 1 means run in this process, without
    a pool. The ``spslidar sweep`` command passes ``"spslidar sweep: warning"``, the prefix
    of its other warnings (it said "spslidar: --jobs 999 clamped to 2": an outside audit of
    2026-12-03)."""
    cores = _cores()
    want = cores if jobs == -1 else jobs
    use = max(1, min(want, cores, max(1, n_tasks)))
    why = f"{n_tasks} runs to do, {cores} cores"
    room = _process_headroom() if use > 1 else None
    if room is not None:
        limit, used = room
        fit = (limit - used - POOL_PARENT_TASKS) // _tasks_per_worker(cores)
        if fit < use:
            use = max(1, fit)
            why = (f"the process limit, ulimit -u {limit} with {used} in use, leaves room for "
                   f"{'no worker pool' if fit < 2 else f'{fit} workers'}")
    if use < want:
        print(f"{prefix}: --jobs {jobs} clamped to {use} ({why})", file=sys.stderr)
    return use


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
    code: str | None = None,
    counts: dict[str, int] | None = None,
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
    code : str, optional
        The fingerprint of the code ``func`` runs (``sweep`` and ``reproduce`` pass
        :func:`spslidar.plugins.code_fingerprint`): a cached point is read only when it was
        computed under the same one, and is run again (same seed) otherwise. Default: the
        cache is keyed on the params alone.
    counts : dict, optional
        Filled with ``cached`` (distinct points read from the cache) and ``run`` (those run
        now), for the caller to say.

    Returns
    -------
    list[dict[str, Any]]
        One row per point, in the order of ``points``: the params (with ``seed``) merged with
        the results, or with ``error`` (also where a result gives a param another value: it
        would replace the parameter in the row). ``func`` gets a copy of the params.

    Raises
    ------
    ConfigError
        On invalid arguments, non-JSON-like params, an out_dir that is not a folder, or a
        missing dask installation when ``scheduler`` is given.
    WorkerLost
        Where a local worker process is killed under the sweep (the OS out of memory, a
        user): the message says how many finished runs are cached, and where.
    """
    seed = check_int(seed, "seed")
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
        canonical(dict(point), f"point {i}")  # validate first, for a clear message
        params = with_seed(point, seed, ignore)
        text = canonical_json(params, f"point {i}")
        key = text_key(text)
        full_params.append(params)
        keys.append(key)
        params_json.setdefault(key, text)

    results: dict[str, dict[str, Any]] = {}
    errors: dict[str, str] = {}
    tasks: list[tuple[int, dict[str, Any]]] = []
    task_keys: list[str] = []
    seen: set[str] = set()
    stale = 0
    for i, key in enumerate(keys):
        if key in seen:
            continue
        seen.add(key)
        cached, old = cached_state(runs_dir / f"{key}.json", params_json[key], code)
        if cached is not None:
            results[key] = cached
        else:
            tasks.append((len(tasks), full_params[i]))
            task_keys.append(key)
            stale += old

    n_unique = len(results) + len(tasks)
    if counts is not None:
        counts.update(cached=len(results), run=len(tasks), stale=stale)
    if stale:
        # (a plugin loaded but used by no point changed the fingerprint, and every cached run
        # was run again without a word: an audit of 2026-11-29)
        print(f"spslidar: note: {stale} cached run{'s were' if stale > 1 else ' was'} made by "
              f"other code (spslidar or its plugins changed) and {'are' if stale > 1 else 'is'} "
              f"run again", file=sys.stderr)
    from tqdm import tqdm

    bar = tqdm(
        total=n_unique,
        initial=len(results),
        desc="sweep",
        unit="run",
        disable=None if progress else True,
        file=sys.stderr,
    )
    # without a terminal (a log, CI, nohup) tqdm is silent: a plain line every few seconds
    plain = progress and not _is_tty(sys.stderr) and bool(tasks)
    t_start = t_last = time.monotonic()
    try:
        if tasks:
            if scheduler is not None:
                outcomes = _run_dask(func, tasks, scheduler)
            else:
                outcomes = _run_local(func, tasks, clamp_jobs(jobs, len(tasks)))
            for index, (status, payload, elapsed) in outcomes:
                key = task_keys[index]
                if status == "ok":
                    try:
                        result = _normalize_result(payload)
                        given = json.loads(params_json[key])
                        clash = sorted(k for k in set(result) & set(given)
                                       if result[k] != given[k])
                        if clash:  # (it replaced the parameter in the row: results.csv then
                            # credited each RMSE to another noise, an audit of 2026-11-29)
                            raise TypeError(f"func returned {clash[0]!r} = "
                                            f"{result[clash[0]]!r}, a parameter of the point "
                                            f"(there {given[clash[0]]!r}): name results apart "
                                            f"from params")
                    except TypeError as exc:
                        status, payload = "error", _error_message(exc)
                    else:
                        results[key] = result
                        store_run(runs_dir / f"{key}.json", key, given, result, elapsed,
                                  code)
                if status != "ok":
                    errors[key] = str(payload)
                    bar.set_postfix(failed=len(errors), refresh=False)
                bar.update(1)
                now = time.monotonic()
                done = len(results) + len(errors)
                if plain and (now - t_last >= PLAIN_PROGRESS_S or done == n_unique):
                    t_last = now
                    print(f"sweep: {done}/{n_unique} runs done"
                          + (f" ({len(errors)} failed)" if errors else "")
                          + f", {now - t_start:.0f} s", file=sys.stderr, flush=True)
    except WorkerLost as exc:
        n = len(results)
        if not n:
            raise WorkerLost(f"{exc} before any run finished: run the same command again (with "
                             f"fewer --jobs where memory ran out)") from None
        raise WorkerLost(f"{exc}; {n} finished run{' is' if n == 1 else 's are'} cached in "
                         f"{runs_dir}: run the same command again to resume") from None
    finally:
        bar.close()

    rows = []
    for params, key in zip(full_params, keys, strict=True):
        if key in results:
            rows.append({**params, **copy.deepcopy(results[key])})
        else:
            rows.append({**params, ERROR_KEY: errors[key]})
    return rows
