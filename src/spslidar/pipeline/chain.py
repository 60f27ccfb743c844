"""One acquisition and its reconstruction: ``measure`` -> ``reconstruct`` -> :class:`Result`.

scene -> code + patterns -> expected counts (forward) -> detector -> matched filter over the
range gate (correlate) -> QCR -> compressive reconstruction of all range slices at once
(solvers) -> depth estimator -> metrics.

Random streams: one ``np.random.SeedSequence(seed)`` is split into independent children for the
code, the patterns, the photon counts and the noise probe of the regularisation default, so
changing e.g. the noise level does not change the patterns.
"""

from __future__ import annotations

import functools
import os
import time
import warnings
from dataclasses import replace

import numpy as np

from ..backends.device import reconstructs_on_device, simulates_on_device
from ..backends.patterns import host_patterns
from ..capture import captured_warnings
from ..config import Config, chosen_stage_options
from ..correlate import PLATEAU_SHARE, make_replica, remove_plateau, replica_plateau
from ..depth import ESTIMATORS, DepthContext
from ..detectors import build_detector
from ..detectors.counting import NoiseModel
from ..errors import ConfigError, library_notice, numbers_blanked, warning_origin
from ..operators.parallel import one_blas_thread
from ..patterns import build_patterns
from ..patterns.dense import check_pattern_set
from ..qcr import MeanEliminated, plain_problem, qcr_problem
from ..scenes import load_scene
from ..solvers.entries import TV_REGULARISERS
from .gate import (
    AUTO_GATE_MIN_SLICES,
    AUTO_GATE_SIGMAS,
    code_sidelobes,
    gate_text,
    occupied_lags,
    with_reference,
)
from .measurement import (
    PROCESSING_KEYS,
    Measurement,
    _resolve,
    check_processing_keys,
    unchanged_keys,
)
from .plan import _check_pattern_floor, _plan, detector_options, plateau_notes, preflight, timeline
from .results import Result
from .score import finish_result, resolved_config
from .simulate import BLOCK, simulate_correlations
from .weights import (
    FLOORED_ITERATIONS,
    LAM_FLOOR,
    TV_INNER,
    build_regulariser,
    default_weight,
    noise_level,
    regulariser_kind,
    solver_default,
    weight_warnings,
)

__all__ = ["LAM_FLOOR", "PROCESSING_KEYS", "TV_INNER", "Measurement", "build_regulariser",
           "default_weight", "detector_options", "finish_result", "measure",
           "noise_level", "preflight", "reconstruct", "resolved_config", "run",
           "solver_default", "timeline"]


def _zero_operator(A, be=None) -> bool:
    """Whether ``A`` maps a random vector to zero: patterns that do not vary (QCR centres them
    to nothing), not a measurement without photons. ``be``: the array backend ``A`` lives on
    (None: NumPy)."""
    v = np.random.default_rng(0).standard_normal(A.shape[1])
    if be is None:
        return not bool(np.any(np.asarray(A.matvec(v.astype(A.dtype)))))
    return not bool(be.xp.any(A.matvec(be.xp.astype(be.asarray(v), A.dtype)) != 0))


def keeping_warnings(fn):
    """``fn`` (returning a :class:`Result` or a :class:`Measurement`) with the Python
    warnings raised while it works (a stage's or a library's ``warnings.warn``: the wavelet
    regulariser's odd image side, the dead-time model's fixed point) kept in its result's
    warnings, and so in ``metrics.json``, beside the run's own; one line per warning, a
    repeat with other numbers counted. They were shown on stderr and missing from
    ``metrics.json`` and sweeps' rows (an audit of 2026-11-28). Where ``fn`` raises they
    are given back as warnings."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        caught: list = []
        try:
            # (this thread's own: runs in a thread pool each keep theirs)
            with captured_warnings() as caught:
                result = fn(*args, **kwargs)
        except BaseException:
            for w in caught:
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
            raise
        kept: dict[str, list] = {}
        for w in caught:  # (a library's with where it came from, as the command line says it)
            if library_notice(w.category):  # (said as Python says it, not kept)
                warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
                continue
            text = (" ".join(str(w.message).split())
                    + warning_origin(w.category, w.filename, w.lineno))
            key = numbers_blanked(text)
            kept.setdefault(key, [text, 0])[1] += 1
        for text, n in kept.values():
            if text not in result.warnings:
                result.warnings.append(text if n == 1 else
                                       f"{text} (and {n - 1} more time{'s' if n > 2 else ''} "
                                       f"with other numbers)")
        return result

    return wrapper


@keeping_warnings
@one_blas_thread
def measure(config: Config | dict | str | os.PathLike | None = None,
            **overrides) -> Measurement:
    """Simulate one acquisition: scene, code, patterns, photon counts and matched filter.

    The result can be reconstructed several times (other solvers, weights, with and without
    QCR) by :func:`reconstruct` without simulating again. On another array backend
    (``backend='torch'``, ...) the patterns live on its device and the simulation runs there
    when it has a device kernel (:mod:`spslidar.backends.device`), else on the host with the
    NumPy kernel, through this same function.

    Parameters
    ----------
    config : Config, dict, str or path, optional
        The acquisition's configuration (defaults: the paper's default experiment), as
        :func:`run` takes it (a run's TOML file, or a scene's name or path, too).
    **overrides
        Config keys to change, e.g. ``measure(scene="motorcycle", noise=5)``.

    Returns
    -------
    Measurement
        The scene, acquisition (code, bin width, periods), range gate and lags, the patterns
        and the simulation record: per pattern the matched-filter outputs at the distinct
        gated delays modulo the code period (``sim["corr"]``, one column per ``ulags``, eq.
        5-6; ``lags % L == ulags[inverse]``, L the code period: more lags than ulags where the
        gate is longer than the unambiguous range), their noise levels and the photon counts.

    Raises
    ------
    ConfigError
        A configuration that cannot run here (one line; its memory or time estimate too).

    Examples
    --------
    >>> import spslidar
    >>> m = spslidar.measure(scene="camera", size=16, code_length=2047, noise=1)
    >>> m.sim["corr"].shape[0]  # one row of matched-filter outputs per DMD pattern (25 %)
    64
    >>> m.sim["corr"].shape[1] == m.ulags.size  # one column per distinct gated delay
    True
    """
    cfg = _resolve(config, overrides)
    be = None
    if cfg.backend != "numpy":
        from ..backends import get_backend

        be = get_backend(cfg.backend, cfg.device)
    timing: dict[str, float] = {}
    warns: list[str] = []

    t0 = time.perf_counter()
    if be is None:  # a device holds its own patterns: the host's memory floor is NumPy's
        _check_pattern_floor(cfg)
    scene = load_scene(cfg.scene, cfg.size, cfg.depth_min, cfg.depth_max)
    warns.extend(scene.notes)  # (its description is no warning: metrics' scene_note)
    timing["scene"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    # the same plan on every backend: its warnings (options the configuration ignores), and
    # its memory and time limits where the arrays live in this machine's memory (a backend on
    # the CPU ran past --max-memory and --max-time, then into a MemoryError's traceback)
    plan = _plan(cfg, scene, warns, check=be is None or cfg.device == "cpu")
    seq_pat, seq_counts, seq_probe = plan.seq_pat, plan.seq_counts, plan.seq_probe
    acq, gate, lags, ulags, inverse = (plan.acq, plan.gate, plan.lags, plan.ulags,
                                       plan.inverse)
    m, dtype, budget = plan.m, plan.dtype, plan.budget
    if be is None:
        patterns = build_patterns(cfg.patterns, m, cfg.size, np.random.default_rng(seq_pat),
                                  dtype=dtype, sigma=cfg.pattern_sigma,
                                  order=cfg.hadamard_order,
                                  realisation=cfg.hadamard_realisation,
                                  **chosen_stage_options(cfg, "patterns"))
        check_pattern_set(patterns, cfg.patterns, m, cfg.size)  # (a plugin's: an audit)
    else:
        from ..backends.patterns import device_patterns
        from ..backends.rng import Stream

        patterns = device_patterns(be, Stream(be, seq_pat), cfg, m)
        be.sync()
    bin_width = 1.0 / cfg.bit_rate
    timing["setup"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    noise = NoiseModel(cfg.noise, tuple(cfg.noise_split), cfg.ambient, cfg.background_rate,
                       cfg.dark_count_rate)
    detector = build_detector(cfg.detector, **detector_options(cfg))
    warns.extend(detector.notes())
    if be is not None and simulates_on_device(cfg, patterns):
        from ..backends.device import simulate
        from ..instrument import instrument_weights

        shifts, weights = instrument_weights(scene, acq, cfg)
        # (a copy: the scene's arrays are read-only, and torch.from_numpy warns on one)
        sim = simulate(be, patterns, acq, ulags, noise, detector, shifts, weights,
                       np.array(scene.reflectivity.ravel()), seq_counts, cfg.noiseless, BLOCK)
        be.sync()
    else:  # the NumPy kernel (on the host patterns of a device pattern set)
        host = patterns if be is None else host_patterns(patterns)
        # differential patterns: the DMD shows two frames per pattern, each for its share of
        # the acquisition time, and the patterns combine the frames' outputs into one each
        shown, share = host.exposures() if hasattr(host, "exposures") else (host, 1.0)
        acq_shown = acq if share == 1.0 else replace(acq, n_periods=acq.n_periods * share)
        if share != 1.0 and (acq.n_periods * share) % 1:
            # (half a code period per frame was simulated as a whole period at half the
            # rate, without a word: a real frame that short breaks the periodic correlation,
            # an outside audit of 2026-11-29)
            what = ("pulses" if acq.lidar == "conventional" else "code periods")
            had = what if acq.n_periods != 1 else what[:-1]
            warns.append(
                f"--hadamard-realisation differential shows each pattern as two frames, each "
                f"for half of its {acq.n_periods:g} {had}: the simulation takes each frame as "
                f"whole {what} at half the rate, which a DMD cannot show (a frame must last "
                f"whole {what} for the matched filter's periodic correlation); give an even "
                f"--periods" + (" (an even number of pulses)" if acq.lidar == "conventional"
                                else ""))
        sim = simulate_correlations(shown, scene, acq_shown, ulags, noise, detector,
                                    cfg.pulse_width, np.random.default_rng(seq_counts),
                                    noiseless=cfg.noiseless, instrument=cfg,
                                    max_time=cfg.max_time, max_memory=cfg.max_memory)
        if shown is not host:
            sim = host.combine(sim)
    import inspect

    known = {}
    if ("incident_counts" in sim
            and "incident_per_period" in inspect.signature(detector.report).parameters):
        known["incident_per_period"] = float(np.mean(sim["incident_counts"])) / acq.n_periods
    pile = detector.report(float(np.mean(sim["counts"])) / acq.n_periods,
                           acq.period * bin_width, pulsed=acq.lidar == "conventional",
                           **known)
    sim["pileup"] = pile
    warns.extend(detector.notes_after(pile, noiseless=cfg.noiseless))
    sim["estimate"] = {"memory_gb": budget.bytes / 1e9, "time_s": budget.seconds}
    timing["simulate"] = time.perf_counter() - t0
    from .measurement import PROCESSING_KEYS, asked_keys

    return Measurement(cfg, scene, acq, gate, lags, ulags, inverse, patterns, sim, seq_probe,
                       warns, timing,
                       {k: v for k, v in asked_keys(config, overrides).items()
                        if k in PROCESSING_KEYS})


@keeping_warnings
@one_blas_thread
def reconstruct(meas: Measurement, *, _asked: dict | None = None, **processing) -> Result:
    """Range gate, QCR, compressive reconstruction, ML depth and metrics of a measurement.

    Parameters
    ----------
    meas : Measurement
    **processing
        Processing keys to change from the measurement's config: those of
        :func:`~spslidar.pipeline.measurement.processing_keys` (``solver``, ``lam``,
        ``lam_scale``, ``qcr``, ``qcr_form``, ``regulariser``, ``iterations``, ``tol``,
        ``subbin``, ``nonneg``, ``auto_gate``, ``depth``, ``max_memory``, ``max_time``, and
        the options the registered solvers and depth estimators declare, such as FISTA's
        ``monotone`` and ``restart``). Any other key is taken only at the value the
        measurement used (``noise=5`` after ``measure(noise=5)``); another value would need a
        new simulation and is an error.

    Notes
    -----
    The weight is ``lam`` where given, else ``lam_scale`` times the noise level with a floor
    (:func:`~spslidar.pipeline.weights.default_weight`); where the floor sets it (always
    for a ``noiseless`` measurement) and ``iterations`` is unset, the solve runs
    ``FLOORED_ITERATIONS`` (5) times the solver's iterations (``metrics['lam_floored']``).

    A measurement made on another array backend is reconstructed here too: the QCR problem,
    the solve and the argmax run on its device where they have device kernels
    (:func:`spslidar.backends.device.reconstructs_on_device`), and every other stage choice
    runs its NumPy implementation on the arrays brought back to the host.

    Examples
    --------
    Simulate once, then reconstruct with two depth estimators:

    >>> import spslidar
    >>> m = spslidar.measure(scene="camera", size=16, code_length=2047, noise=1)
    >>> for depth in ("argmax", "mrf"):
    ...     r = spslidar.reconstruct(m, depth=depth)
    ...     print(depth, r.depth.shape, r.depth_rmse < 0.1)
    argmax (16, 16) True
    mrf (16, 16) True
    >>> spslidar.reconstruct(m, noise=5)  # a measurement key needs a new measure()
    Traceback (most recent call last):
    ...
    spslidar.errors.ConfigError: reconstruct() cannot change noise: simulate again with measure()
    """
    if not isinstance(meas, Measurement):
        raise ConfigError(f"reconstruct() takes a Measurement (from spslidar.measure()), got "
                          f"{type(meas).__name__}")
    meas.check_unchanged()
    # a measurement key given at the value the measurement used changes nothing: taken
    same = unchanged_keys(meas.config, processing)
    processing = {k: v for k, v in processing.items() if k not in same}
    check_processing_keys(processing, "reconstruct()",
                          "reconstruct() cannot change {keys}: simulate again with measure()")
    # (a copy even without changes: the result's config was the measurement's own object, so
    # `r.config.solver = "twist"` changed every later reconstruct(meas): an audit of 2026-11-30)
    cfg = meas.config.replace(**processing)
    timing = dict(meas.timing)
    warns = list(meas.warnings)
    from .plan import asked_notes

    # (what it ignores of what was asked: run_shared says what its point asked, as it
    # passes every processing key; a review)
    asked = _asked if _asked is not None else {**meas.asked, **processing}
    warns += asked_notes(cfg, asked, warns)
    acq, sim, patterns = meas.acq, meas.sim, meas.patterns
    ulags, lags = meas.ulags, meas.lags
    bin_width = acq.bin_width
    q = cfg.size * cfg.size
    dtype = np.float32 if cfg.dtype == "float32" else np.float64
    be = getattr(patterns, "backend", None)  # None: NumPy arrays
    device = be is not None and reconstructs_on_device(cfg)
    reg_kind = regulariser_kind(cfg)

    t0 = time.perf_counter()
    corr = sim["corr"]
    if be is not None and not device:  # stages without a device kernel: on the host
        corr, patterns = _host(be, corr), host_patterns(patterns)
    auto = cfg.auto_gate if cfg.auto_gate is not None else ulags.size > AUTO_GATE_MIN_SLICES
    if auto:
        keep = occupied_lags(_host(be, corr), sim["sigma"], lags=ulags,
                             sidelobes=code_sidelobes(acq.code,
                                                      make_replica(acq.code, acq.replica)))
    else:
        keep = np.ones(ulags.size, dtype=bool)
    occupied = keep
    if auto:
        if not keep.any():
            warns.append(
                f"the automatic range gate found no delay of {gate_text(meas.gate)} m whose "
                f"pattern-averaged return rises {AUTO_GATE_SIGMAS:g} noise standard deviations "
                f"above the background: nothing in the gate returns light this acquisition "
                f"tells from it (a dark or distant scene, too little signal, or a gate that "
                f"misses the scene); only a sample of the noise was solved (--no-auto-gate "
                f"solves every delay)")
        keep = with_reference(keep)
    rebuilt = None  # (the reconstruction priced again: metrics' estimate.time_s_reconstruct)
    if not sim.get("estimate") and not device:  # a measured acquisition: no config priced it
        _price_measured(cfg, patterns.shape[0], q, int(keep.sum()), int(meas.lags.size))
    elif processing and not device:
        # a simulation reconstructed otherwise than measure() priced it: its solve and depth
        # stage priced again against the limits now given (reconstruct(m, iterations=20000,
        # max_time=0.5) ran 21 s unchecked, and metrics kept measure()'s estimate: an audit
        # of 2026-12-01)
        rebuilt = _price_simulated(cfg, patterns.shape[0], q, int(keep.sum()),
                                   int(meas.lags.size))
    eliminated = None
    if device:
        from ..backends import device as dev

        xp = be.xp
        corr = be.asarray(corr)
        if not keep.all():
            corr = xp.take(corr, be.asarray(np.flatnonzero(keep)), axis=1)
        A, y, sigma_eff, lam_max = dev.problem(
            be, patterns, corr, sim["sigma"], meas.probe_seed,
            xp.float32 if cfg.dtype == "float32" else xp.float64)
    else:
        corr = corr[:, keep]
        if cfg.qcr:
            A, y = qcr_problem(patterns, corr, cfg.qcr_form, dtype=dtype)
        else:
            A, y = plain_problem(patterns, corr, dtype=dtype)
        sigma_eff = noise_level(A, patterns, sim["sigma"], cfg,
                                np.random.default_rng(meas.probe_seed))
        if not cfg.qcr and reg_kind in TV_REGULARISERS:
            # TV ignores a constant per slice: eliminate the patterns' mean direction
            # exactly, so the plain problem converges within the default budget
            eliminated, y_plain = MeanEliminated(A), y
            A, y = eliminated, eliminated.data(y)
        # the floor of the default weight, and the scale a given --lam is checked against
        lam_max = float(np.abs(np.asarray(A.rmatvec(y))).max(initial=0.0))
    if not lam_max > 0 and _zero_operator(A, be if device else None):
        # (patterns without contrast: a Lipschitz traceback from the solver, an audit; no
        # photons at all, with patterns that vary, is an empty depth map, not an error)
        hint = (f" (--pattern-sigma {cfg.pattern_sigma:g} is below what {cfg.dtype} patterns "
                f"resolve)" if cfg.patterns == "gaussian" and cfg.pattern_sigma < 1e-4 else "")
        raise ConfigError(f"nothing to reconstruct: the patterns do not vary from one to the "
                          f"next, so the {'centred ' if cfg.qcr else ''}operator is zero{hint}")
    lam, lam_scale, floored = default_weight(cfg, sigma_eff, lam_max)
    warns.extend(weight_warnings(cfg, lam, lam_max, floored))
    if not lam * 1e6 < float(np.finfo(cfg.dtype).max):  # its steps would overflow: NaN slices
        # (the option given: reconstruct, which has no --lam, was told to lower it)
        given = "--lam" if cfg.lam is not None else "--lam-scale"
        raise ConfigError(f"the weight {lam:.3g} is beyond what {cfg.dtype} can hold through "
                          f"the solve: lower {given} (the default is about 0.01 max |A^T y|, "
                          f"{lam_max:.3g} here)")
    if be is not None:
        be.sync()
    timing["qcr"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    from ..solvers import SolveInfo, StopRule, get_solver

    iterations = cfg.iterations or solver_default(cfg.solver, "iterations")
    estimate: dict[str, float] = {}
    if rebuilt is not None:
        estimate["time_s_reconstruct"] = rebuilt
    if floored and not cfg.iterations:
        iterations *= FLOORED_ITERATIONS
        # the run was priced at the solver's cap before the weight was known: price the
        # floored solve again, against --max-time, and say a long one (a 512x512 Hadamard
        # run announced at 47 s took 145 s, a 256x256 motorcycle 106 s unannounced)
        # (on a device too, priced as the plan priced it, the host's model: a device run at
        # the floor went 10 s past a --max-time of 2.5 s unchecked, an audit of 2026-11-29)
        from .budget import ANNOUNCE_SECONDS, check_time, config_solve_seconds
        from .plan import _dense_patterns

        solve_s = config_solve_seconds(cfg, patterns.shape[0], q, int(keep.sum()),
                                       _dense_patterns(cfg), iterations)
        spent = sum(t for key, t in timing.items() if key != "total")
        estimate = {"time_s_at_floor": spent + solve_s}
        check_time(spent + solve_s, cfg.max_time, f"this run at the weight's floor "
                   f"({iterations} iterations)", announce=False, basis="its first stages' "
                   "time and the floored weight's iteration cap", reduce="--size or "
                   "--compression, or set --iterations or --lam")
        if not device and solve_s > ANNOUNCE_SECONDS:  # (the host's seconds, not a device's)
            import sys

            print(f"spslidar: the weight met its floor, so the solve runs up to "
                  f"{iterations} iterations: about {solve_s:.0f} s more (an estimate; "
                  f"--iterations to cap it)", file=sys.stderr, flush=True)
    if not (bool(xp.all(xp.isfinite(y))) if device else bool(np.isfinite(np.asarray(y)).all())):
        # (a noiseless run at 1e-300 photons: its normalised correlations overflow; the
        # solvers now refuse such data, which the command line said as a traceback)
        raise ConfigError(f"the measurements are not finite in {cfg.dtype} (normalised to a "
                          f"signal of {cfg.signal:g} photons per pulse): raise --signal")
    on_device = device  # (the refit below reads the host's problem)
    if device:
        x, finfo = dev.solve(be, A, y, (cfg.size, cfg.size), cfg.nonneg, lam, iterations,
                             cfg.tol, TV_INNER, isotropic=reg_kind == "tv")
        be.sync()
        info = SolveInfo("fista", finfo.iterations, finfo.objective, finfo.stop_reason,
                         time.perf_counter() - t0,
                         {"L": finfo.L, "restarts": 0, "rejected": 0, "backend": cfg.backend,
                          "device": cfg.device})
        stop_cap = iterations
    else:
        reg = build_regulariser(cfg.replace(nonneg=False) if eliminated is not None else cfg,
                                (cfg.size, cfg.size))
        stop = StopRule(max_iter=iterations, rtol=cfg.tol)
        x, info = get_solver(cfg.solver)(stop=stop, **chosen_stage_options(cfg, "solver")
                                         ).solve(A, y, reg, lam)
        if info.solver != cfg.solver:
            # the solver as registered, not its class's inherited name (a plugin's subclass of
            # FISTA was recorded as "fista": an outside audit of 2026-12-01)
            info.solver = cfg.solver
        if eliminated is not None:
            x = eliminated.recover(x, y_plain)
        stop_cap = stop.max_iter
    timing["solve"] = time.perf_counter() - t0
    if not (bool(xp.all(xp.isfinite(x))) if device else bool(np.isfinite(x).all())):
        # (a weight that overflows float32, 1e39, gave NaN slices scored as a depth map)
        # (it said "or use --dtype float64" to a float64 run, an audit)
        given = "--lam" if cfg.lam is not None else "--lam-scale"
        # (TVAL3 weighs the data by 1/(2 lam): a tiny weight overflows it, and "lower --lam"
        # was said to a --lam of 1e-45, an outside audit)
        tiny = cfg.solver == "tval3" and lam < TVAL3_TINY_WEIGHT * max(lam_max, 1e-300)
        cure = ("raise --signal: measurements this small underflow" if not lam > 0 else
                f"raise {given} (TVAL3 weighs the data by 1/(2 lam))" if tiny else
                f"lower {given}"
                + (", or use --dtype float64" if cfg.dtype == "float32" else ""))
        raise ConfigError(f"the {cfg.solver} solve diverged (its estimate is not finite) at "
                          f"the weight {lam:.3g} in {cfg.dtype}: {cure}")
    if not cfg.qcr and eliminated is None and info.stop_reason == "max_iter":
        warns.append(
            f"without QCR the problem is ill-conditioned (the patterns' mean dominates its "
            f"operator) and {cfg.solver} stopped at its cap of {stop_cap} iterations: the "
            f"estimate is not converged (FISTA needs ~1000-2000 at 64x64; --iterations)")

    t0 = time.perf_counter()
    shape = (cfg.size, cfg.size)
    noise_sample = None
    plateau = replica_plateau(meas.acq.code, meas.acq.replica)
    unipolar = PLATEAU_SHARE <= plateau < 1.0  # (--replica unipolar: profiles ride on q x peak)
    warns.extend(plateau_notes(meas.acq, plateau, unipolar, reg_kind))
    if unipolar and auto:
        # an automatic gate's plateau is read over the delays solved, before its noise
        # sample is taken (the delays not solved are zeros, no plateau: read over the whole
        # gate, and after the sample, the verdict called a 2.8 cm map noise and the
        # reflectivity read 3.61 for 0.83, a review)
        x = remove_plateau(_host(be, x), plateau)
        device = False  # (the depth stage on the host from here on)
    if auto and not keep.all():
        # the automatic gate's solved delays, for the noise verdict in delay order (the rest
        # are zeros, no noise); its noise sample is then left out (zeros, as every delay not
        # solved), so that the depth stage reads the occupied delays alone, as it did before
        # the sample was solved
        cols = (np.cumsum(keep) - 1)[np.asarray(meas.inverse)[keep[meas.inverse]]]
        noise_sample = _host(be, xp.take(x, be.asarray(cols), axis=1) if device
                             else np.asarray(x)[:, cols])
        if bool((keep & ~occupied).any()):
            occ = occupied[keep].astype(np.asarray(noise_sample).dtype)
            x = x * (be.asarray(occ) if device else occ)
    if device:
        full = x
        if not keep.all():
            full = xp.zeros((x.shape[0], ulags.size), dtype=x.dtype, device=x.device)
            full = dev.scatter_columns(be, full, x, np.flatnonzero(keep))
        slices = xp.take(full, be.asarray(np.asarray(meas.inverse, dtype=np.int64)), axis=1)
    else:
        full = np.zeros((q, ulags.size), dtype=np.asarray(x).dtype)
        full[:, keep] = x
        slices = full[:, meas.inverse]
    depth2 = depth_info = None
    if unipolar and not auto:
        slices = remove_plateau(_host(be, slices), plateau)
        device = False  # (the depth stage on the host from here on)
    if device and cfg.depth == "argmax" and sim.get("delay_response") is None:
        from ..depth.argmax import ArgmaxDepth, depth_from_peaks, peak_confidence

        idx, peak, below, above = dev.argmax_depth(be, slices)  # only the peaks come back
        depth = depth_from_peaks(idx, peak, below, above, lags, slices.shape[1], bin_width,
                                 cfg.pulse_width, cfg.subbin)
        confidence = peak_confidence(peak)
        confidence[~np.isfinite(depth)] = 0.0
        flagger = ArgmaxDepth()
        low, threshold = flagger._flag(depth, confidence), flagger.low_confidence
    else:
        slices = _host(be, slices)
        seen = slices
        if sim.get("delay_response") is not None:  # a calibrated instrument's spread returns
            from .calibrated import delay_filter, refine_depth

            seen = delay_filter(slices, lags, sim["delay_response"])
        estimator = ESTIMATORS.load(cfg.depth)(**chosen_stage_options(cfg, "depth"))
        threshold = estimator.low_confidence
        est = estimator.estimate(
            seen, DepthContext(lags, bin_width, cfg.pulse_width, shape,
                               cfg.subbin and seen is slices))  # (calibrated: refine_depth)
        depth, confidence, low = est.depth, est.confidence, est.low_confidence
        depth_info, depth2 = est.info, est.depth2
        if seen is not slices:
            depth = refine_depth(depth, seen, lags, bin_width, cfg.pulse_width)
            if depth2 is not None:  # (left on the lags' grid, +9.6 mm: an audit)
                depth2 = refine_depth(depth2, seen, lags, bin_width, cfg.pulse_width)
    depth = np.asarray(depth).reshape(shape)
    timing["depth"] = time.perf_counter() - t0
    refit = None
    # (a calibrated instrument too: its filter's gain puts a unit return's response at 1
    # over the three delays the refit reads, and the window's sum of its regularised slices
    # read a uniform stepped scene 0.52-0.99 by depth level, an outside audit of 2026-12-03)
    if not on_device and not unipolar:
        t0 = time.perf_counter()
        refit = _refit(meas, cfg, A, y, x, keep, depth, slices, sigma_eff, info,
                       reg_kind in TV_REGULARISERS)
        timing["reflectivity"] = time.perf_counter() - t0
    if be is not None:
        t0 = time.perf_counter()
        slices, corr = _host(be, slices), _host(be, corr)
        timing["to_host"] = time.perf_counter() - t0

    return finish_result(
        meas, cfg, depth=depth, slices=slices, corr=corr, keep=keep, auto=auto,
        confidence=confidence, low_confidence=low, depth_info=depth_info,
        lam=lam, lam_scale=lam_scale, sigma_eff=sigma_eff, info=info, iterations=iterations,
        timing=timing, warns=warns, lam_floored=floored, depth2=depth2,
        low_confidence_threshold=threshold, estimate=estimate, noise_sample=noise_sample,
        refit=refit)


def _refit(meas: Measurement, cfg: Config, A, y, x, keep: np.ndarray, depth: np.ndarray,
           slices: np.ndarray, sigma_eff: float, info, tv: bool) -> tuple:
    """The reflectivity refitted with the depth held (:func:`spslidar.refit.refit_reflectivity`)
    on the solve's own problem ``A``, ``y`` and solution ``x`` (its ``keep`` delays of the
    gate's unique ones), the shapes read off the gate's ``slices``, warm-started from the
    window's sum; ``(r, info)``. ``tv``: the solve's regulariser is a TV (the other
    surfaces' returns are then taken out of the data first). Pixels no pattern lights have
    no return here, as the result says."""
    from ..forward import depth_to_delay
    from ..products import reflectivity_image
    from ..refit import refit_reflectivity

    lags = np.asarray(meas.lags, dtype=np.float64)
    d = np.asarray(depth, dtype=np.float64).ravel()
    have = np.isfinite(d)
    unlit = meas.sim.get("unlit_pixels")
    if unlit is not None:  # (finish_result clears them: not in the refit's TV either)
        have &= ~np.asarray(unlit, dtype=bool).ravel()
    centre = np.full(d.size, -1, dtype=np.int64)  # (the gate's delays are consecutive bins)
    centre[have] = np.rint(depth_to_delay(d[have], meas.acq.bin_width) - lags[0])
    column = np.cumsum(keep) - 1  # each unique delay's column among the solved ones
    inverse = np.asarray(meas.inverse, dtype=np.int64)
    columns = np.where(keep[inverse], column[inverse], -1)
    start = reflectivity_image(slices, depth, meas.lags, meas.acq.bin_width)
    op_norm_sq = info.extra.get("L") if cfg.solver == "fista" else None
    return refit_reflectivity(A, np.asarray(y), np.asarray(x), slices, centre, have,
                              (cfg.size, cfg.size), columns=columns,
                              sigma_eff=0.0 if cfg.noiseless else sigma_eff,
                              op_norm_sq=op_norm_sq, start=start, take_apart=tv,
                              floor_share=LAM_FLOOR, floored_factor=FLOORED_ITERATIONS)


def _price_measured(cfg: Config, m: int, q: int, k: int, n_lags: int) -> None:
    """Price a measured acquisition's reconstruction (``reconstruct``, which no configuration
    priced) once its gate has kept the ``k`` slices that hold returns: the solve over them and
    the depth stage over the ``n_lags`` gated slices (:mod:`.budget`), refused beyond
    ``--max-time`` and said when long. Priced before the file was read over every gated slice,
    a 64x64 file through a 0-100 m gate was announced at 67 s and took 15.5 s (an audit)."""
    from .budget import check_time, reconstruction_seconds

    check_time(reconstruction_seconds(cfg, m, q, k, n_lags), cfg.max_time,
               "this reconstruction", basis=f"its {k} slices with returns of {n_lags} gated",
               reduce="--iterations or the range gate")


def _price_simulated(cfg: Config, m: int, q: int, k: int, n_lags: int) -> float:
    """Price a simulated measurement's reconstruction with other processing than its
    ``measure()`` was priced for (:func:`reconstruct` with ``iterations``, ``solver``,
    ``depth``, ``max_time`` or ``max_memory``): the solve over the ``k`` solved slices and the
    depth stage over the ``n_lags`` gated ones, against ``max_time`` (said when long), and
    their arrays against ``max_memory``. Returns the seconds priced."""
    from .budget import (
        BASE_BYTES,
        Budget,
        check_budget,
        check_time,
        reconstruction_parts,
        reconstruction_seconds,
    )
    from .plan import _dense_patterns

    seconds = reconstruction_seconds(cfg, m, q, k, n_lags, dense=_dense_patterns(cfg))
    check_time(seconds, cfg.max_time, "this reconstruction",
               basis=f"its {k} solved slices of {n_lags} gated",
               reduce="iterations or the range gate")
    parts = {"interpreter": BASE_BYTES, **reconstruction_parts(cfg, q, k, n_lags)}
    check_budget(Budget(sum(parts.values()), seconds, parts), cfg.max_memory, cfg.patterns)
    return seconds


#: a TVAL3 weight this share of max |A^T y| or less is named too small where its solve
#: diverges (its data term is 1/(2 lam) ||A x - y||^2)
TVAL3_TINY_WEIGHT = 1e-6


def _host(be, a):
    """``a`` as a NumPy array on the host (``be`` None: it is one already)."""
    return a if be is None or isinstance(a, np.ndarray) else be.to_numpy(a)


def run(config: Config | dict | str | os.PathLike | None = None, **overrides) -> Result:
    """Simulate one acquisition and reconstruct it: ``reconstruct(measure(config))``.

    Parameters
    ----------
    config : Config, dict, str or path, optional
        The run's configuration (defaults: the paper's default experiment): a
        :class:`~spslidar.config.Config`, a dict of its keys, a run's TOML file
        (``run('myrun.toml')``, as ``spslidar run --config``) or a scene
        (``run('camera')``).
    **overrides
        Config keys to change, e.g. ``run(noise=5, solver='twist')``.

    Returns
    -------
    Result

    Examples
    --------
    A 16x16 run of the built-in camera scene (a 2047-bit m-sequence, little noise):

    >>> import spslidar
    >>> r = spslidar.run(scene="camera", size=16, code_length=2047, noise=1, seed=0)
    >>> r.depth.shape
    (16, 16)
    >>> r.depth_rmse < 0.1  # metres, against the scene's ground truth
    True
    >>> r.config.solver, r.config.depth
    ('fista', 'mrf')
    """
    return reconstruct(measure(config, **overrides))
