"""Measurements shared between runs that differ only in processing (paired sweeps)."""

from __future__ import annotations

import json
import os
import threading
from collections import OrderedDict

import numpy as np

from ..config import Config
from ..registry import registrations
from . import chain as _chain
from .measurement import Measurement, _resolve, processing_keys
from .results import Result

#: measurements kept per process by :func:`run_shared` (most recently used first out last)
SHARED_MEASUREMENTS = 2
#: a measurement larger than this (patterns and correlations) is not kept
SHARED_MAX_BYTES = 256 * 2**20

_shared: OrderedDict[str, Measurement] = OrderedDict()
_shared_lock = threading.Lock()


def simulation_key(cfg: Config) -> str:
    """What identifies a simulated measurement: the config without its processing keys, and
    where the scene is a file, the file's size and modification time (a scene file edited
    between two runs in one process gave the earlier file's measurement), and how many times
    the process's registries changed (:func:`~spslidar.registry.registrations`)."""
    d = cfg.to_dict()
    for k in processing_keys():
        d.pop(k, None)
    scene = str(cfg.scene)
    if os.path.isfile(scene):
        st = os.stat(scene)
        d["scene_file"] = [st.st_size, st.st_mtime_ns]
    # a stage registered again under its name (a notebook cell re-run) is another stage: its
    # measurement is simulated anew (an audit of 2026-12-01)
    d["registrations"] = registrations()
    return json.dumps(d, sort_keys=True, default=repr)


def _measurement_bytes(meas: Measurement) -> int:
    arrays = [meas.patterns, *(v for v in meas.sim.values() if isinstance(v, np.ndarray))]
    return int(sum(a.nbytes for a in arrays))


def run_shared(config: Config | dict | None = None, **overrides) -> Result:
    """:func:`run`, reusing this process's last measurements when only processing differs.

    Sweeps and reproductions compare solvers, weights or QCR on the same simulated data (a
    paired comparison: points that differ only in :data:`PROCESSING_KEYS` get the same seed
    there). The last :data:`SHARED_MEASUREMENTS` measurements are kept (thread-safe), so such
    points simulate once. The result is identical to ``run(config)``; its ``timing`` keeps the
    simulation time measured when the data were simulated, and ``metrics['measurement_reused']``
    says whether they were.
    """
    cfg = _resolve(config, overrides)
    key = simulation_key(cfg)
    with _shared_lock:
        meas = _shared.get(key)
        if meas is not None:
            _shared.move_to_end(key)
    reused = meas is not None
    if meas is None:
        meas = _chain.measure(cfg)
        if _measurement_bytes(meas) <= SHARED_MAX_BYTES:
            with _shared_lock:
                _shared[key] = meas
                while len(_shared) > SHARED_MEASUREMENTS:
                    _shared.popitem(last=False)
    from .measurement import asked_keys

    # (every processing key is passed, so what the point asked is said: the default
    # nonneg of a qcr=false point was said to be "asked for", a review)
    result = _chain.reconstruct(meas, _asked=asked_keys(config, overrides),
                                **{k: getattr(cfg, k) for k in processing_keys()})
    result.metrics["measurement_reused"] = reused
    return result


def clear_shared() -> None:
    """Forget the measurements kept by :func:`run_shared`."""
    with _shared_lock:
        _shared.clear()


#: the settings :func:`run_metrics` writes beside the metrics where a sweep's point leaves
#: them at their defaults (the weight factor ``lam_scale`` too, resolved for the solver)
SWEEP_SETTINGS = ("scene", "size", "signal", "noise", "compression", "lidar", "code",
                  "code_length", "bit_rate", "patterns", "detector", "solver", "depth")


def run_metrics(params: dict) -> dict:
    """``run`` for sweeps (through :func:`run_shared`): a flat dict of the main metrics (no
    arrays)."""
    r = run_shared(params)
    m = r.metrics
    # the settings a result depends on that the point left at their defaults (a curve over
    # the signal said nothing of the m_n = 10 it was run at, nor of the solver's weight
    # factor that made one solver look worse than another: an audit)
    given = {str(k).replace("-", "_") for k in params}  # (code-length is code_length)
    out = {k: getattr(r.config, k) for k in SWEEP_SETTINGS if k not in given}
    if "lam_scale" not in given:  # (as the run resolved it; none where --lam was given)
        out["lam_scale"] = m["lam_scale"]
    # the RMSE with the share of pixels it is over and what run would have said of the map
    # (a pure-noise point or a gate without the scene looked like an ordinary result)
    keep = ("depth_rmse_m", "chance_rmse_m", "depth_mae_m", "depth_bias_m", "missing_fraction",
            "coverage",
            "edge_correlation", "low_confidence_fraction", "peak_to_noise_p90",
            "peak_to_noise_floor", "n_patterns", "n_slices", "lam", "noise_level")
    out.update({k: m[k] for k in keep})
    out["time_total_s"] = r.timing["total"]
    out["time_solve_s"] = r.timing["solve"]
    out["iterations"] = m["solver_info"]["iterations"]
    out["n_warnings"] = len(r.warnings)
    out["warnings"] = " | ".join(r.warnings)
    return out
