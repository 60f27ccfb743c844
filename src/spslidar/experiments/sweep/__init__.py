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
  (failed points are not cached: a rerun retries them), a ``SystemExit`` included;
* raises :class:`WorkerLost`, one line naming the runs cached, where a local worker process
  is killed under it (a Dask cluster runs a lost worker's points again), and
  :class:`SweepIncomplete` where ``results.csv`` cannot be written (a full disk).

Sweep configurations are TOML files (:func:`load_sweep_config`)::

    seed = 1
    trials = 3
    [base]          # any `spslidar run` config keys
    size = 32
    [grid]          # each key a list of values
    noise = [1, 5, 10]
    code_length = [1023, 4095]

and :func:`sweep_main` runs one and writes ``out_dir/results.csv`` (one row per run).

The package follows the engine's seams, and re-exports everything public:

* :mod:`spslidar.experiments.sweep.grid`: points, seeds, cache keys, TOML definitions (no run
  is started there);
* :mod:`spslidar.experiments.sweep.store`: atomic files, cache records, the tidy CSV;
* :mod:`spslidar.experiments.sweep.engine`: executors, :func:`run_sweep`;
* :mod:`spslidar.experiments.sweep.command`: the ``spslidar sweep`` command,
  :func:`run_point`, :func:`sweep_main`.

Notes
-----
The cache key covers the point's parameters (including its seed). ``run_sweep(..., code=...)``
also records the code's fingerprint and reads a cached run only under the same one: ``sweep``
and ``reproduce`` pass :func:`spslidar.plugins.code_fingerprint`, so an edited plugin or
spslidar runs its points again; a call without ``code`` keys on the parameters alone (after
changing ``func``, use a fresh ``out_dir`` or pass ``code``).
"""

from spslidar.experiments.sweep.command import SweepIncomplete, run_point, sweep_main
from spslidar.experiments.sweep.engine import WorkerLost, run_sweep
from spslidar.experiments.sweep.grid import (
    ERROR_KEY,
    KEY_LENGTH,
    SEED_BOUND,
    SEED_KEY,
    TRIAL_KEY,
    SweepSpec,
    derive_seed,
    expand_grid,
    load_sweep_config,
    point_key,
)
from spslidar.experiments.sweep.store import atomic_write_bytes, atomic_write_text, write_csv

__all__ = [
    "ERROR_KEY",
    "KEY_LENGTH",
    "SEED_BOUND",
    "SEED_KEY",
    "TRIAL_KEY",
    "SweepIncomplete",
    "SweepSpec",
    "WorkerLost",
    "atomic_write_bytes",
    "atomic_write_text",
    "derive_seed",
    "expand_grid",
    "load_sweep_config",
    "point_key",
    "run_point",
    "run_sweep",
    "sweep_main",
    "write_csv",
]
