"""``measure`` and ``reconstruct`` on an array backend (``--backend torch|cupy|...``).

The same chain as :mod:`spslidar.pipeline.chain` (scene -> code + patterns -> Poisson counts
per pattern over the code period -> matched filter on the gated lags -> centred QCR -> FISTA +
TV -> argmax depth -> metrics), with the patterns, the counts, the correlations, the QCR
problem and the solver's iterates on the backend's device. The scene, the code, the replica
bank and the small per-pattern and per-pixel vectors are prepared on the host with the NumPy
path's own functions; the metrics are computed on the host from the depth map.

:func:`spslidar.pipeline.chain.measure` and ``reconstruct`` hand a config whose ``backend`` is
not ``numpy`` to the functions here. Stage timings wait for the device (``Backend.sync``).
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from . import check_supported, get_backend
from .kernels import (
    TVProx,
    argmax_peaks,
    centre,
    fista_tv,
    scalars,
    simulate_block,
)
from .patterns import device_patterns
from .rng import Stream

#: most TDC bins (patterns x code period) per simulated block on a device stream (fixed, so the
#: counts depend only on the seed and the shape): 2^27 float32 bins = 512 MB
DEVICE_BLOCK_BINS = 1 << 27


def measure(cfg: Any):
    """:func:`spslidar.pipeline.chain.measure` on ``cfg.backend`` / ``cfg.device``."""
    from ..correlate import (
        correlation_gain,
        make_replica,
        noise_sigma_from_totals,
        replica_matrix,
    )
    from ..detectors import build_detector
    from ..detectors.counting import NoiseModel
    from ..forward import shifted_codes
    from ..instrument import instrument_weights
    from ..patterns import n_patterns_for
    from ..pipeline.measurement import Measurement
    from ..pipeline.plan import detector_options, timeline
    from ..pipeline.simulate import BLOCK
    check_supported(cfg)
    be = get_backend(cfg.backend, cfg.device)
    xp = be.xp
    timing: dict[str, float] = {}
    warns: list[str] = []

    t0 = time.perf_counter()
    scene = _load_scene(cfg.scene, cfg.size, cfg.depth_min, cfg.depth_max)
    warns.extend(scene.notes)  # as the NumPy path: e.g. the crop of a non-square scene
    timing["scene"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    seq_pat, seq_counts, seq_probe, acq, gate, lags, ulags, inverse = timeline(cfg, scene,
                                                                                warns)
    bin_width = acq.bin_width
    m = n_patterns_for(cfg.compression, cfg.size * cfg.size)
    patterns = device_patterns(be, Stream(be, seq_pat), cfg, m)
    be.sync()
    timing["setup"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    noise = NoiseModel(cfg.noise, tuple(cfg.noise_split), cfg.ambient, cfg.background_rate,
                       cfg.dark_count_rate)
    detector = build_detector(cfg.detector, **detector_options(cfg))
    refl = scene.reflectivity.ravel()
    shifts, weights = instrument_weights(scene, acq, cfg)  # as the NumPy path (host-side)
    noise_bin = _noise_per_bin(be, noise, patterns, refl, acq.bin_width)
    replica = make_replica(acq.code, acq.replica)
    gain = correlation_gain(acq.code, replica) * acq.n_periods * acq.signal_per_pulse
    w_dev = be.asarray(weights)
    codes = be.asarray(shifted_codes(acq.code, shifts))
    bank = be.asarray(replica_matrix(replica, ulags))
    noise_dev = be.asarray(noise_bin)
    counts_stream = Stream(be, seq_counts)
    if counts_stream.host:  # the NumPy path's blocks and streams
        n_blocks = max(1, int(np.ceil(m / BLOCK)))
    else:
        n_blocks = max(1, int(np.ceil(m * acq.period / DEVICE_BLOCK_BINS)))
    edges = np.linspace(0, m, n_blocks + 1).astype(int)
    children = counts_stream.children(n_blocks)
    corr_parts, tot_parts, amp_parts = [], [], []
    for b in range(n_blocks):
        a, e = int(edges[b]), int(edges[b + 1])
        amp, lam = simulate_block(xp, patterns.rows_apply(a, e, w_dev), codes, noise_dev[a:e],
                                  acq.signal_per_pulse, acq.n_periods)
        if cfg.noiseless:
            counts, totals = lam, xp.sum(lam, axis=1, dtype=xp.float64)
        else:
            counts, totals = counts_stream.poisson(lam, children[b], detector, acq.n_periods)
        del lam
        corr_parts.append((counts @ bank) / float(gain))
        tot_parts.append(totals)
        amp_parts.append(xp.sum(amp, axis=1))
    corr = corr_parts[0] if n_blocks == 1 else xp.concat(corr_parts, axis=0)
    totals = be.to_numpy(xp.concat(tot_parts) if n_blocks > 1 else tot_parts[0])
    amp_sum = be.to_numpy(xp.concat(amp_parts) if n_blocks > 1 else amp_parts[0])
    n_pulses = float(acq.code.sum()) * acq.n_periods
    sim = {"corr": corr, "sigma": noise_sigma_from_totals(totals, replica, gain),
           "counts": totals, "signal_counts": acq.signal_per_pulse * n_pulses * amp_sum,
           "noise_per_bin": noise_bin}
    pile = detector.report(float(np.mean(totals)) / acq.n_periods, acq.period * bin_width)
    sim["pileup"] = pile
    sim["estimate"] = {}
    be.sync()
    timing["simulate"] = time.perf_counter() - t0
    return Measurement(cfg, scene, acq, gate, lags, ulags, inverse, patterns, sim, seq_probe,
                       warns, timing)


#: built-in scenes already made, by (name, size, depth_min, depth_max): sweeps load the same
#: scene for every point (17 ms at 64x64, as long as a GPU run's simulation)
_SCENES: dict[tuple, Any] = {}
#: replay FISTA's iterations from a CUDA graph with PyTorch on CUDA (``torch_graph``)
USE_CUDA_GRAPHS = True


def _load_scene(name: str, size: int, depth_min: Any, depth_max: Any) -> Any:
    """:func:`spslidar.scenes.load_scene`, built-in scenes cached (a copy each time)."""
    import copy

    from ..scenes import BUILTIN_SCENES, load_scene

    if str(name).lower() not in BUILTIN_SCENES:
        return load_scene(name, size, depth_min, depth_max)
    key = (str(name).lower(), size, depth_min, depth_max)
    if key not in _SCENES:
        if len(_SCENES) >= 8:
            _SCENES.clear()
        _SCENES[key] = load_scene(name, size, depth_min, depth_max)
    return copy.deepcopy(_SCENES[key])


def _noise_per_bin(be: Any, noise: Any, patterns: Any, refl: np.ndarray,
                   bin_width: float) -> np.ndarray:
    """:meth:`spslidar.detectors.counting.NoiseModel.per_bin` with the patterns on the device."""
    m, q = patterns.shape
    f1, f2, f3 = (float(v) for v in noise.split)
    base = q * noise.m_n * (f2 + f3) + (noise.background_rate + noise.dark_count_rate) * bin_width
    if noise.ambient == "paper":
        return np.full(m, base + q * noise.m_n * f1)
    a = be.asarray(np.asarray(refl, dtype=np.float64).reshape(-1, 1))
    mod = be.to_numpy(patterns.rows_apply(0, m, a))[:, 0]
    return base + noise.m_n * f1 * mod


def reconstruct(meas: Any, **processing):
    """:func:`spslidar.pipeline.chain.reconstruct` of a measurement made on a backend."""
    from ..depth.argmax import ArgmaxDepth, depth_from_peaks, peak_confidence
    from ..errors import ConfigError
    from ..pipeline.gate import AUTO_GATE_MIN_SLICES, occupied_lags
    from ..pipeline.measurement import PROCESSING_KEYS
    from ..pipeline.score import finish_result
    from ..pipeline.weights import TV_INNER, default_weight, solver_default, weight_warnings
    from ..solvers import SolveInfo

    bad = set(k.replace("-", "_") for k in processing) - PROCESSING_KEYS
    if bad:
        raise ConfigError(f"reconstruct() cannot change {', '.join(sorted(bad))}: "
                          f"simulate again with measure()")
    cfg = meas.config.replace(**processing) if processing else meas.config
    check_supported(cfg)
    be = meas.patterns.backend
    xp = be.xp
    timing = dict(meas.timing)
    warns = list(meas.warnings)
    acq, sim, patterns = meas.acq, meas.sim, meas.patterns
    ulags, lags = meas.ulags, meas.lags
    bin_width = acq.bin_width
    dtype = xp.float32 if cfg.dtype == "float32" else xp.float64
    m = patterns.shape[0]

    t0 = time.perf_counter()
    corr = sim["corr"]
    auto = cfg.auto_gate if cfg.auto_gate is not None else ulags.size > AUTO_GATE_MIN_SLICES
    if auto:
        keep = occupied_lags(be.to_numpy(corr), sim["sigma"])
        corr = xp.take(corr, be.asarray(np.flatnonzero(keep)), axis=1)
    else:
        keep = np.ones(ulags.size, dtype=bool)
    norm = float(np.sqrt(m))
    if cfg.qcr:
        A = patterns.centred(norm, dtype)
        y = xp.astype(centre(xp, xp.astype(corr, xp.float64)) / norm, dtype)
    else:  # refused by check_supported (the NumPy path's mean elimination is not ported)
        raise ConfigError("--no-qcr runs on --backend numpy only")
    # the noise probe of the regularisation default, on the host stream of the NumPy path
    e = np.random.default_rng(meas.probe_seed).standard_normal((m, 4)) * sim["sigma"][:, None]
    ey = (e - e.mean(axis=0, keepdims=True)) / np.sqrt(m) if cfg.qcr else e
    z = A.rmatvec(xp.astype(be.asarray(ey), dtype))
    sigma_eff = float(np.sqrt(scalars(be, xp.mean(xp.astype(z, xp.float64) ** 2))[0]))
    lam_max = float(scalars(be, xp.max(xp.abs(xp.astype(A.rmatvec(y), xp.float64))))[0])
    lam, lam_scale, floored = default_weight(cfg, sigma_eff, lam_max)
    warns.extend(weight_warnings(cfg, lam, lam_max))
    be.sync()
    timing["qcr"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    iterations = cfg.iterations or solver_default(cfg.solver, "iterations")
    reg = TVProx(xp, (cfg.size, cfg.size), nonneg=cfg.nonneg, max_inner=TV_INNER, be=be)
    solve = fista_tv
    if USE_CUDA_GRAPHS and be.name == "torch" and be.device.type == "cuda":
        from .torch_graph import fista_tv_graphed as solve
    x, finfo = solve(be, A, y, reg, lam, iterations, cfg.tol)
    be.sync()
    timing["solve"] = time.perf_counter() - t0
    info = SolveInfo("fista", finfo.iterations, finfo.objective, finfo.stop_reason,
                     timing["solve"], {"L": finfo.L, "restarts": 0, "rejected": 0,
                                       "backend": cfg.backend, "device": cfg.device})
    if not cfg.qcr and info.stop_reason == "max_iter":
        warns.append(f"without QCR the problem is ill-conditioned and fista stopped at its cap "
                     f"of {iterations} iterations: the estimate is not converged")

    t0 = time.perf_counter()
    if keep.all():
        full = x
    else:
        full = xp.zeros((x.shape[0], ulags.size), dtype=x.dtype, device=x.device)
        cols = be.asarray(np.flatnonzero(keep))
        full = _scatter_columns(be, full, x, cols)
    slices = xp.take(full, be.asarray(np.asarray(meas.inverse, dtype=np.int64)), axis=1)
    shape = (cfg.size, cfg.size)
    slices_host = None
    if cfg.depth == "argmax":  # on the device: only the peaks come back
        idx, peak, below, above = (be.to_numpy(a) for a in argmax_peaks(xp, slices))
        depth_flat = depth_from_peaks(idx, peak, below, above, lags, slices.shape[1],
                                      bin_width, cfg.pulse_width, cfg.subbin)
        conf = peak_confidence(peak)
        conf[~np.isfinite(depth_flat)] = 0.0
        low = ArgmaxDepth()._flag(depth_flat, conf)
    else:  # the image-structured estimators run on the host, on the slices
        from ..depth import ESTIMATORS, DepthContext

        slices_host = be.to_numpy(slices)
        est = ESTIMATORS.load(cfg.depth)().estimate(
            slices_host, DepthContext(lags, bin_width, cfg.pulse_width, shape, cfg.subbin))
        depth_flat, conf, low = est.depth, est.confidence, est.low_confidence
    depth = np.asarray(depth_flat).reshape(shape)
    timing["depth"] = time.perf_counter() - t0

    t0 = time.perf_counter()
    if slices_host is None:
        slices_host = be.to_numpy(slices)
    corr_host = be.to_numpy(corr)
    timing["to_host"] = time.perf_counter() - t0

    return finish_result(
        meas, cfg, depth=depth, slices=slices_host, corr=corr_host, keep=keep, auto=auto,
        confidence=conf, low_confidence=low, depth_info=None, lam=lam, lam_scale=lam_scale,
        sigma_eff=sigma_eff, info=info, iterations=iterations, timing=timing, warns=warns,
        lam_floored=floored)


def _scatter_columns(be: Any, full: Any, x: Any, cols: Any) -> Any:
    """``full[:, cols] = x`` (the array API has no integer-array assignment: one column at a
    time through basic indexing)."""
    for j, c in enumerate(be.to_numpy(cols).tolist()):
        full[:, c] = x[:, j]
    return full
