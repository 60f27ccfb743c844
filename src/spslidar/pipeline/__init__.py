"""One simulated acquisition and reconstruction, end to end: ``run(config) -> Result``.

The package follows the chain: :mod:`.acquisition` (code, timing, photon scaling, default
gate) -> :mod:`.simulate` (forward model -> detector model -> matched filter, streamed over
pattern blocks) -> :mod:`.gate` (automatic range gate) -> :mod:`.chain` (``measure`` and
``reconstruct``: QCR, solver, depth estimator, metrics) -> :mod:`.results` (``Result`` and
its files); :mod:`.shared` keeps measurements for runs that differ only in processing. The
command-line tool is a thin layer over :func:`run`.
"""

from .acquisition import GATE_PAD_BINS, Acquisition, default_gate, make_acquisition
from .chain import (
    PROCESSING_KEYS,
    TV_INNER,
    Measurement,
    build_regulariser,
    measure,
    noise_level,
    preflight,
    reconstruct,
    run,
    solver_default,
)
from .gate import AUTO_GATE_MIN_SLICES, occupied_lags, unique_lags
from .results import Result
from .shared import clear_shared, run_metrics, run_shared, simulation_key
from .simulate import BLOCK, simulate_correlations

__all__ = [
    "AUTO_GATE_MIN_SLICES", "BLOCK", "GATE_PAD_BINS", "PROCESSING_KEYS", "TV_INNER",
    "Acquisition", "Measurement", "Result", "build_regulariser", "clear_shared",
    "default_gate", "make_acquisition", "measure", "noise_level",
    "occupied_lags", "preflight", "reconstruct", "run", "run_metrics", "run_shared",
    "simulate_correlations", "simulation_key", "solver_default", "unique_lags",
]
