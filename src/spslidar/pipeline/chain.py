"""One acquisition and its reconstruction: ``measure`` -> ``reconstruct`` -> :class:`Result`.

scene -> code + patterns -> expected counts (forward) -> detector -> matched filter over the
range gate (correlate) -> QCR -> compressive reconstruction of all range slices at once
(solvers) -> depth estimator -> metrics.

Random streams: one ``np.random.SeedSequence(seed)`` is split into independent children for the
code, the patterns, the photon counts and the noise probe of the regularisation default, so
changing e.g. the noise level does not change the patterns.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from ..config import Config
from ..constants import SPEED_OF_LIGHT
from ..correlate import gate_lags
from ..depth import ESTIMATORS, DepthContext
from ..detector import NoiseModel
from ..detectors import build_detector
from ..errors import ConfigError
from ..metrics import depth_errors, edge_agreement, sobel_edges
from ..patterns import PATTERNS, PatternOperator, build_patterns, n_patterns_for
from ..products import reflectivity_image
from ..qcr import MeanEliminated, centre, plain_problem, qcr_problem
from ..scenes import load_scene
from ..version import __version__
from .acquisition import GATE_PAD_BINS, Acquisition, default_gate, make_acquisition
from .budget import check_budget, estimate_budget
from .gate import AUTO_GATE_MIN_SLICES, occupied_lags, unique_lags
from .results import Result
from .simulate import simulate_correlations, simulation_threads

#: inner (dual) iterations of the warm-started TV prox per outer iteration: the prox's dual is
#: carried over between outer iterations, so a few suffice (measured: the same depth RMSE
#: with 3, 5, 10 or 20 on the default problem, and on the motorcycle with FISTA and TwIST)
TV_INNER = 3


def build_regulariser(cfg: Config, shape: tuple[int, int]):
    """The regulariser of eq. (18) the config asks for (``auto``: the solver's default)."""
    from ..operators import Wavelet2D
    from ..solvers.regularisers import L1, TV

    kind = cfg.regulariser
    if kind == "auto":
        kind = solver_default(cfg.solver, "regulariser")
    if kind == "tv":
        return TV(shape, nonneg=cfg.nonneg, max_inner=TV_INNER)
    if kind == "l1":
        return L1(None, nonneg=cfg.nonneg)
    # the prox of a wavelet l1 norm under a non-negativity constraint has no closed form:
    # --nonneg applies to the TV and pixel-l1 regularisers only
    return L1(Wavelet2D(shape, "haar"))


def load_solver(name: str):
    """The solver class registered under ``name``."""
    from ..solvers import SOLVERS

    return SOLVERS.load(name)


def solver_default(name: str, key: str):
    """A registered solver's default ``key`` (``iterations``, ``lam_scale``, ``regulariser``):
    its registry entry's, else the solver class's ``default_<key>``."""
    from ..solvers import SOLVERS

    defaults = SOLVERS.get(name).defaults
    if key in defaults:
        return defaults[key]
    return getattr(load_solver(name), f"default_{key}")


def noise_level(A, patterns: PatternOperator, sigma: np.ndarray, cfg: Config, rng) -> float:
    """RMS of ``A^H e_y`` for measurement noise ``e`` of the estimated per-pattern level,
    pushed through the same data preparation (centring / covariance) as the data.

    This is the noise that reaches the regulariser's prox in a gradient step; the default
    regularisation weight is a fixed multiple of it. It uses the measurements only (through
    ``sigma``), never the truth.
    """
    m = patterns.shape[0]
    e = rng.standard_normal((m, 4)) * sigma[:, None]
    if cfg.qcr and cfg.qcr_form == "centred":
        ey = centre(e) / np.sqrt(m)
    elif cfg.qcr:
        # Phi_c^T e_c = Phi^T e_c: the centred noise sums to zero over the patterns
        ey = np.asarray(patterns.rmatvec(centre(e).astype(patterns.dtype)), np.float64) / m
    else:
        ey = e
    z = A.rmatvec(ey.astype(A.dtype))
    return float(np.sqrt(np.mean(np.asarray(z, dtype=np.float64) ** 2)))


#: the default weight is at least this share of ``lam_max = max |A^H y|``
LAM_FLOOR = 3e-3


def default_weight(cfg: Config, sigma_eff: float, lam_max: float) -> tuple[float, float, bool]:
    """The regularisation weight: ``cfg.lam`` if given, else
    ``max(lam_scale * sigma_eff, LAM_FLOOR * lam_max)``.

    The first term follows the noise that reaches the prox (:func:`noise_level`); it goes to
    zero as the photon count grows, but a compressive problem (``M < Q``) needs its prior even
    without noise: with a vanishing weight the solver returns a minimum-norm-like estimate
    (measured: the conventional lidar at 25 %, noiseless, 0.11-0.14 m whatever the flux). The
    floor is a fixed share of ``lam_max = ||A^H y||_inf`` (the weight at which an l1 estimate
    is zero), a scale read from the data; at the paper's settings the noise term is 4 to 6
    times larger (camera m_n = 10: ``lam = 0.012 lam_max``, m_n = 1: ``0.005 lam_max``), so
    the floor binds only at high signal-to-noise ratios (e.g. a dwell of many code periods).

    Returns
    -------
    lam : float
    lam_scale : float
        The multiple of ``sigma_eff`` (the solver's default unless the config sets it).
    floored : bool
        Whether the floor set the weight.
    """
    lam_scale = (cfg.lam_scale if cfg.lam_scale is not None
                 else solver_default(cfg.solver, "lam_scale"))
    if cfg.lam is not None:
        return float(cfg.lam), lam_scale, False
    noise_term, floor = lam_scale * sigma_eff, LAM_FLOOR * lam_max
    return max(noise_term, floor), lam_scale, bool(floor > noise_term)


#: config keys that change only the processing, not the simulated measurement
PROCESSING_KEYS = frozenset({
    "auto_gate", "qcr", "qcr_form", "solver", "regulariser", "lam", "lam_scale", "iterations",
    "tol", "subbin", "nonneg", "depth", "max_memory",
})


@dataclass
class Measurement:
    """A simulated acquisition: the matched-filter outputs of every pattern over the gate,
    and everything needed to reconstruct them (see :func:`measure`, :func:`reconstruct`)."""

    config: Config
    scene: Any
    acq: Acquisition
    gate: tuple[float, float]
    lags: np.ndarray  # absolute gated delays (bins)
    ulags: np.ndarray  # distinct delays modulo the code period
    inverse: np.ndarray  # lags -> index into ulags
    patterns: PatternOperator
    sim: dict[str, np.ndarray]
    probe_seed: np.random.SeedSequence
    warnings: list[str]
    timing: dict[str, float]


def _resolve(config, overrides) -> Config:
    if config is None:
        cfg = Config.from_dict(overrides)
    elif isinstance(config, Config):
        cfg = config.replace(**overrides) if overrides else config
    else:
        cfg = Config.from_dict({**dict(config), **overrides})
    return cfg


@dataclass
class _Plan:
    """What a run needs before its first large array: seeds, acquisition, gate and budget."""

    seq_pat: np.random.SeedSequence
    seq_counts: np.random.SeedSequence
    seq_probe: np.random.SeedSequence
    acq: Acquisition
    gate: tuple[float, float]
    lags: np.ndarray
    ulags: np.ndarray
    inverse: np.ndarray
    m: int
    dtype: Any
    budget: Any


def timeline(cfg: Config, scene, warns: list[str]):
    """The run's random streams, code and range gate, shared by every backend's ``measure``.

    Returns ``(seq_pat, seq_counts, seq_probe, acq, gate, lags, ulags, inverse)``: the seed
    sequences of the patterns, the counts and the noise probe (the code's is used here), the
    :class:`~spslidar.pipeline.acquisition.Acquisition`, the gate (m), its delays (bins) and
    their distinct values modulo the code period. Appends the range-ambiguity and
    outside-the-gate warnings to ``warns``.
    """
    seq_code, seq_pat, seq_counts, seq_probe = np.random.SeedSequence(cfg.seed).spawn(4)
    bin_width = 1.0 / cfg.bit_rate
    gate = cfg.range_gate if cfg.range_gate is not None else default_gate(scene, bin_width)
    acq = make_acquisition(cfg, gate, np.random.default_rng(seq_code))
    lags = gate_lags(gate, bin_width)
    ulags, inverse = unique_lags(lags, acq.period)
    if lags.size > acq.period:
        warns.append(
            f"range gate {gate[0]:g}-{gate[1]:g} m is longer than the "
            f"{acq.unambiguous_range:.3g} m unambiguous range of the {acq.description}: returns "
            f"at d and d + {acq.unambiguous_range:.3g} m are indistinguishable and the estimate "
            f"takes the nearest alias inside the gate")
    outside = (scene.depth < gate[0]) | (scene.depth > gate[1])
    if np.any(outside & scene.valid):
        warns.append(f"{int((outside & scene.valid).sum())} pixels lie outside the range gate "
                     f"{gate[0]:g}-{gate[1]:g} m: their returns alias into the gate or are lost")
    return seq_pat, seq_counts, seq_probe, acq, gate, lags, ulags, inverse


def _plan(cfg: Config, scene, warns: list[str]) -> _Plan:
    """The cheap part of :func:`measure`: code, range gate and the memory check (refused in
    one line before any large array exists)."""
    seq_pat, seq_counts, seq_probe, acq, gate, lags, ulags, inverse = timeline(cfg, scene,
                                                                                warns)
    bin_width = 1.0 / cfg.bit_rate
    q = cfg.size * cfg.size
    m = n_patterns_for(cfg.compression, q)
    dtype = np.float32 if cfg.dtype == "float32" else np.float64
    bin_depth = SPEED_OF_LIGHT * bin_width / 2.0
    budget = estimate_budget(
        cfg, n_patterns=m, period=acq.period, n_lags=lags.size, n_ulags=ulags.size,
        window_bins=int((scene.depth_max - scene.depth_min) / bin_depth) + 2 * GATE_PAD_BINS,
        pattern_bytes_per_entry=(np.dtype(dtype).itemsize
                                 if PATTERNS.get(cfg.patterns).defaults.get("dense") else None),
        threads=simulation_threads())
    check_budget(budget, cfg.max_memory, cfg.patterns)
    return _Plan(seq_pat, seq_counts, seq_probe, acq, gate, lags, ulags, inverse, m, dtype,
                 budget)


def preflight(config: Config | dict | None = None, **overrides):
    """Check that a configuration can run here, without running it: its scene loads and its
    estimated memory fits (:func:`~spslidar.pipeline.budget.check_budget`). Sweeps call it for
    every point before the first run. Returns the :class:`~spslidar.pipeline.budget.Budget`."""
    cfg = _resolve(config, overrides)
    _check_pattern_floor(cfg)
    scene = load_scene(cfg.scene, cfg.size, cfg.depth_min, cfg.depth_max)
    return _plan(cfg, scene, []).budget


def _check_pattern_floor(cfg: Config) -> None:
    """Refuse at once a run whose dense pattern matrix alone cannot fit (the full estimate
    needs the scene, whose loading takes a while at large sizes)."""
    if not PATTERNS.get(cfg.patterns).defaults.get("dense"):
        return
    from .budget import BASE_BYTES, DENSE_PATTERN_COPIES, Budget

    q = cfg.size * cfg.size
    m = n_patterns_for(cfg.compression, q)
    floor = DENSE_PATTERN_COPIES * m * q * (4 if cfg.dtype == "float32" else 8)
    check_budget(Budget(BASE_BYTES + floor, 0.0, {"patterns": floor}), cfg.max_memory,
                 cfg.patterns)


def measure(config: Config | dict | None = None, **overrides) -> Measurement:
    """Simulate one acquisition: scene, code, patterns, photon counts and matched filter.

    The result can be reconstructed several times (other solvers, weights, with and without
    QCR) by :func:`reconstruct` without simulating again.
    """
    cfg = _resolve(config, overrides)
    if cfg.backend != "numpy":  # the array-API chain on another backend (spslidar.backends)
        from ..backends.chain import measure as measure_on_backend

        return measure_on_backend(cfg)
    timing: dict[str, float] = {}
    warns: list[str] = []

    t0 = time.perf_counter()
    _check_pattern_floor(cfg)
    scene = load_scene(cfg.scene, cfg.size, cfg.depth_min, cfg.depth_max)
    warns.extend(scene.notes)
    timing["scene"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    plan = _plan(cfg, scene, warns)
    seq_pat, seq_counts, seq_probe = plan.seq_pat, plan.seq_counts, plan.seq_probe
    acq, gate, lags, ulags, inverse = plan.acq, plan.gate, plan.lags, plan.ulags, plan.inverse
    m, dtype, budget = plan.m, plan.dtype, plan.budget
    bin_width = 1.0 / cfg.bit_rate
    patterns = build_patterns(cfg.patterns, m, cfg.size, np.random.default_rng(seq_pat),
                              dtype=dtype, sigma=cfg.pattern_sigma, order=cfg.hadamard_order,
                              realisation=cfg.hadamard_realisation)
    timing["setup"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    noise = NoiseModel(cfg.noise, tuple(cfg.noise_split), cfg.ambient, cfg.background_rate,
                       cfg.dark_count_rate)
    detector = build_detector(cfg.detector, **detector_options(cfg))
    # differential patterns: the DMD shows two frames per pattern, each for its share of the
    # acquisition time, and the patterns combine the frames' outputs into one per pattern
    shown, share = patterns.exposures() if hasattr(patterns, "exposures") else (patterns, 1.0)
    acq_shown = acq if share == 1.0 else replace(acq, n_periods=acq.n_periods * share)
    sim = simulate_correlations(shown, scene, acq_shown, ulags, noise, detector, cfg.pulse_width,
                                np.random.default_rng(seq_counts), noiseless=cfg.noiseless)
    if shown is not patterns:
        sim = patterns.combine(sim)
    pile = detector.report(float(np.mean(sim["counts"])) / acq.n_periods,
                           acq.period * bin_width)
    sim["pileup"] = pile
    sim["estimate"] = {"memory_gb": budget.bytes / 1e9, "time_s": budget.seconds}
    timing["simulate"] = time.perf_counter() - t0
    return Measurement(cfg, scene, acq, gate, lags, ulags, inverse, patterns, sim, seq_probe,
                       warns, timing)


def reconstruct(meas: Measurement, **processing) -> Result:
    """Range gate, QCR, compressive reconstruction, ML depth and metrics of a measurement.

    Parameters
    ----------
    meas : Measurement
    **processing
        Processing keys to change from the measurement's config (``solver``, ``lam``,
        ``lam_scale``, ``qcr``, ``qcr_form``, ``regulariser``, ``iterations``, ``tol``,
        ``subbin``, ``nonneg``, ``auto_gate``); anything else would need a new simulation and
        is an error.
    """
    if meas.config.backend != "numpy":
        from ..backends.chain import reconstruct as reconstruct_on_backend

        return reconstruct_on_backend(meas, **processing)
    bad = set(k.replace("-", "_") for k in processing) - PROCESSING_KEYS
    if bad:
        raise ConfigError(f"reconstruct() cannot change {', '.join(sorted(bad))}: "
                          f"simulate again with measure()")
    cfg = meas.config.replace(**processing) if processing else meas.config
    timing = dict(meas.timing)
    warns = list(meas.warnings)
    acq, sim, patterns = meas.acq, meas.sim, meas.patterns
    ulags, lags = meas.ulags, meas.lags
    bin_width = acq.bin_width
    q = cfg.size * cfg.size
    dtype = np.float32 if cfg.dtype == "float32" else np.float64

    t0 = time.perf_counter()
    corr = sim["corr"]
    auto = cfg.auto_gate if cfg.auto_gate is not None else ulags.size > AUTO_GATE_MIN_SLICES
    keep = occupied_lags(corr, sim["sigma"]) if auto else np.ones(ulags.size, dtype=bool)
    corr = corr[:, keep]
    if cfg.qcr:
        A, y = qcr_problem(patterns, corr, cfg.qcr_form, dtype=dtype)
    else:
        A, y = plain_problem(patterns, corr, dtype=dtype)
    sigma_eff = noise_level(A, patterns, sim["sigma"], cfg, np.random.default_rng(meas.probe_seed))
    reg_kind = (solver_default(cfg.solver, "regulariser") if cfg.regulariser == "auto"
                else cfg.regulariser)
    eliminated = None
    if not cfg.qcr and reg_kind == "tv":
        # TV ignores a constant per slice: eliminate the patterns' mean direction exactly, so
        # the plain problem converges within the default budget (MeanEliminated)
        eliminated, y_plain = MeanEliminated(A), y
        A, y = eliminated, eliminated.data(y)
    # the floor of the default weight (a given --lam needs no extra product)
    lam_max = (float(np.abs(np.asarray(A.rmatvec(y))).max(initial=0.0)) if cfg.lam is None
               else float("nan"))
    lam, lam_scale, floored = default_weight(cfg, sigma_eff, lam_max)
    timing["qcr"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    from ..solvers import StopRule

    reg = build_regulariser(cfg.replace(nonneg=False) if eliminated is not None else cfg,
                            (cfg.size, cfg.size))
    solver_cls = load_solver(cfg.solver)
    iterations = cfg.iterations or solver_default(cfg.solver, "iterations")
    stop = StopRule(max_iter=iterations, rtol=cfg.tol)
    x, info = solver_cls(stop=stop).solve(A, y, reg, lam)
    if eliminated is not None:
        x = eliminated.recover(x, y_plain)
    timing["solve"] = time.perf_counter() - t0
    if not cfg.qcr and eliminated is None and info.stop_reason == "max_iter":
        warns.append(
            f"without QCR the problem is ill-conditioned (the patterns' mean dominates its "
            f"operator) and {cfg.solver} stopped at its cap of {stop.max_iter} iterations: the "
            f"estimate is not converged (FISTA needs ~1000-2000 at 64x64; --iterations)")

    t0 = time.perf_counter()
    full = np.zeros((q, ulags.size), dtype=np.asarray(x).dtype)
    full[:, keep] = x
    slices = full[:, meas.inverse]
    shape = (cfg.size, cfg.size)
    est = ESTIMATORS.load(cfg.depth)().estimate(
        slices, DepthContext(lags, bin_width, cfg.pulse_width, shape, cfg.subbin))
    depth = est.depth.reshape(shape)
    timing["depth"] = time.perf_counter() - t0

    return finish_result(
        meas, cfg, depth=depth, slices=slices, corr=corr, keep=keep, auto=auto,
        confidence=est.confidence, low_confidence=est.low_confidence, depth_info=est.info,
        lam=lam, lam_scale=lam_scale, sigma_eff=sigma_eff, info=info, iterations=iterations,
        timing=timing, warns=warns, lam_floored=floored)


def finish_result(meas: Measurement, cfg: Config, *, depth: np.ndarray, slices: np.ndarray,
                  corr: np.ndarray, keep: np.ndarray, auto: bool, confidence: np.ndarray,
                  low_confidence: np.ndarray, depth_info: dict | None, lam: float,
                  lam_scale: float, sigma_eff: float, info: Any, iterations: int,
                  timing: dict[str, float], warns: list[str],
                  lam_floored: bool = False) -> Result:
    """Score a reconstruction (eq. 19, Sobel edges) and assemble its :class:`Result` and
    ``metrics.json``: the last step of :func:`reconstruct`, shared by the other backends'
    reconstruction (:mod:`spslidar.backends.chain`) so both report the same keys."""
    scene, acq, sim = meas.scene, meas.acq, meas.sim
    bin_depth = SPEED_OF_LIGHT * acq.bin_width / 2.0
    shape = (cfg.size, cfg.size)
    t0 = time.perf_counter()
    if getattr(scene, "has_truth", True):
        err = depth_errors(depth, scene.depth, scene.valid)
        edge_corr = edge_agreement(sobel_edges(depth), sobel_edges(scene.depth))
    else:  # a measured acquisition: only what needs no truth
        found = np.isfinite(depth)
        err = {key: None for key in ("depth_rmse_m", "depth_mae_m", "depth_bias_m",
                                     "depth_max_abs_error_m")}
        err.update(n_valid=0, missing_fraction=float(1.0 - found.mean()),
                   coverage=float(found.mean()))
        edge_corr = None
    reflectivity = reflectivity_image(slices, depth, meas.lags, acq.bin_width)
    timing["metrics"] = time.perf_counter() - t0
    timing["total"] = sum(timing.values())

    metrics: dict[str, Any] = {
        **err,
        "depth_rmse_bins": (err["depth_rmse_m"] / bin_depth if err["depth_rmse_m"] is not None
                            else None),
        "has_truth": bool(getattr(scene, "has_truth", True)),
        "edge_correlation": edge_corr,
        "bin_depth_m": bin_depth,
        "unambiguous_range_m": acq.unambiguous_range,
        "range_gate_m": list(meas.gate),
        "n_slices": int(meas.lags.size),
        "n_slices_solved": int(keep.sum()),
        "auto_gate": bool(auto),
        "n_patterns": int(meas.patterns.shape[0]),
        "code_description": acq.description,
        "code_period_bins": acq.period,
        "code_ones": int(acq.code.sum()),
        "n_periods": acq.n_periods,
        "acquisition_time_per_pattern_s": acq.acquisition_time,
        "signal_per_pulse": acq.signal_per_pulse,
        "replica": acq.replica,
        "mean_signal_counts_per_pattern": float(np.mean(sim["signal_counts"])),
        "mean_noise_counts_per_pattern": float(np.mean(sim["noise_per_bin"]) * acq.period
                                               * acq.n_periods),
        "correlation_noise_sigma": float(np.sqrt(np.mean(sim["sigma"] ** 2))),
        "depth_estimator": cfg.depth,
        "low_confidence_fraction": float(np.mean(low_confidence)),
        "mean_reflectivity": (float(np.nanmean(reflectivity)) if np.isfinite(reflectivity).any()
                              else None),
        **({"depth_info": depth_info} if depth_info else {}),
        "lam": lam,
        "lam_scale": lam_scale if cfg.lam is None else None,
        "lam_floored": bool(lam_floored),
        "noise_level": sigma_eff,
        "solver_info": dict(info.as_dict()),
        "detector": sim["pileup"],
        "estimate": sim.get("estimate", {}),
        "warnings": warns,
        "timing_s": dict(timing),
        "config": resolved_config(cfg, acq, meas.gate, auto, iterations, lam_scale),
        "seed": cfg.seed,
        "version": __version__,
    }
    return Result(cfg, scene, depth, slices, meas.lags, corr, metrics, timing, warns,
                  confidence=np.asarray(confidence).reshape(shape),
                  low_confidence=np.asarray(low_confidence).reshape(shape),
                  reflectivity=reflectivity)


def detector_options(cfg: Config) -> dict[str, Any]:
    """The detector model's options from the config (dark counts are in the noise model)."""
    if cfg.detector == "gmapd":
        return {"dead_time": cfg.dead_time, "bin_width": 1.0 / cfg.bit_rate,
                "jitter": cfg.jitter, "jitter_tail": cfg.jitter_tail,
                "jitter_tail_weight": cfg.jitter_tail_weight,
                "afterpulse_prob": cfg.afterpulse_prob, "afterpulse_delay": cfg.afterpulse_delay,
                "correction": cfg.pileup_correction}
    return {"dead_time": cfg.dead_time}


def resolved_config(cfg: Config, acq: Acquisition, gate, auto_gate: bool, iterations: int,
                    lam_scale: float) -> dict[str, Any]:
    """The config with every ``auto``/unset key replaced by the value the run used, so a
    score can be recomputed from ``metrics.json`` alone."""
    d = cfg.to_dict()
    d["iterations"] = int(iterations)
    d["lam_scale"] = float(lam_scale)
    d["code_index"] = acq.code_index
    d["replica"] = acq.replica
    d["regulariser"] = (solver_default(cfg.solver, "regulariser") if cfg.regulariser == "auto"
                        else cfg.regulariser)
    d["range_gate"] = [float(gate[0]), float(gate[1])]
    d["auto_gate"] = bool(auto_gate)
    if not cfg.qcr and d["regulariser"] == "tv":
        d["nonneg"] = False  # the mean-eliminated plain problem has no sign constraint
    return d


def run(config: Config | dict | None = None, **overrides) -> Result:
    """Simulate one acquisition and reconstruct it: ``reconstruct(measure(config))``.

    Parameters
    ----------
    config : Config or dict, optional
        The run's configuration (defaults: the paper's default experiment).
    **overrides
        Config keys to change, e.g. ``run(noise=5, solver='twist')``.

    Returns
    -------
    Result
    """
    return reconstruct(measure(config, **overrides))
