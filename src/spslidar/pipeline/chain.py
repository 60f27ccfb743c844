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
from dataclasses import replace

import numpy as np

from ..config import Config
from ..depth import ESTIMATORS, DepthContext
from ..detectors import build_detector
from ..detectors.counting import NoiseModel
from ..errors import ConfigError
from ..patterns import build_patterns
from ..qcr import MeanEliminated, plain_problem, qcr_problem
from ..scenes import load_scene
from .gate import AUTO_GATE_MIN_SLICES, occupied_lags
from .measurement import PROCESSING_KEYS, Measurement, _resolve
from .plan import _check_pattern_floor, _plan, detector_options, preflight, timeline
from .results import Result
from .score import finish_result, resolved_config
from .simulate import simulate_correlations
from .weights import (
    LAM_FLOOR,
    TV_INNER,
    build_regulariser,
    default_weight,
    noise_level,
    solver_default,
    weight_warnings,
)

__all__ = ["LAM_FLOOR", "PROCESSING_KEYS", "TV_INNER", "Measurement", "build_regulariser",
           "default_weight", "detector_options", "finish_result", "measure",
           "noise_level", "preflight", "reconstruct", "resolved_config", "run",
           "solver_default", "timeline"]


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
    warns.extend(detector.notes())
    # differential patterns: the DMD shows two frames per pattern, each for its share of the
    # acquisition time, and the patterns combine the frames' outputs into one per pattern
    shown, share = patterns.exposures() if hasattr(patterns, "exposures") else (patterns, 1.0)
    acq_shown = acq if share == 1.0 else replace(acq, n_periods=acq.n_periods * share)
    sim = simulate_correlations(shown, scene, acq_shown, ulags, noise, detector, cfg.pulse_width,
                                np.random.default_rng(seq_counts), noiseless=cfg.noiseless,
                                instrument=cfg)
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
    # the floor of the default weight, and the scale a given --lam is checked against
    lam_max = float(np.abs(np.asarray(A.rmatvec(y))).max(initial=0.0))
    lam, lam_scale, floored = default_weight(cfg, sigma_eff, lam_max)
    warns.extend(weight_warnings(cfg, lam, lam_max))
    timing["qcr"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    from ..solvers import StopRule, get_solver

    reg = build_regulariser(cfg.replace(nonneg=False) if eliminated is not None else cfg,
                            (cfg.size, cfg.size))
    solver_cls = get_solver(cfg.solver)
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
    seen = slices
    if sim.get("delay_response") is not None:  # a calibrated instrument's spread returns
        from .calibration import delay_filter

        seen = delay_filter(slices, lags, sim["delay_response"])
    est = ESTIMATORS.load(cfg.depth)().estimate(
        seen, DepthContext(lags, bin_width, cfg.pulse_width, shape, cfg.subbin))
    depth = est.depth.reshape(shape)
    timing["depth"] = time.perf_counter() - t0

    return finish_result(
        meas, cfg, depth=depth, slices=slices, corr=corr, keep=keep, auto=auto,
        confidence=est.confidence, low_confidence=est.low_confidence, depth_info=est.info,
        lam=lam, lam_scale=lam_scale, sigma_eff=sigma_eff, info=info, iterations=iterations,
        timing=timing, warns=warns, lam_floored=floored, depth2=est.depth2)


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
