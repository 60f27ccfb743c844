"""Scoring a reconstruction (equation 19, Sobel edges, the metrics that need no truth) and
assembling its :class:`~spslidar.pipeline.results.Result` and ``metrics.json``: the last
step of every backend's reconstruction.
"""

from __future__ import annotations

import copy
import time
from typing import Any

import numpy as np

from ..config import Config, registries, stage_options
from ..constants import SPEED_OF_LIGHT
from ..correlate import window_response
from ..depth.profile import (
    NOISE_BESIDE_MIN,
    NOISE_ONLY_MIN_SLICES,
    verdict_and_room,
)
from ..instrument import window_share
from ..metrics import (
    chance_rmse,
    depth_errors,
    edge_agreement,
    sobel_edges,
    truth_edge_mask,
)
from ..plugins import code_fingerprint, load_plugins
from ..products import reflectivity_image
from ..solvers.entries import TV_REGULARISERS
from ..version import __version__
from .acquisition import Acquisition
from .gate import gate_text
from .measurement import Measurement
from .plan import detector_options, ignored_keys
from .results import Result
from .weights import regulariser_kind


def finish_result(meas: Measurement, cfg: Config, *, depth: np.ndarray, slices: np.ndarray,
                  corr: np.ndarray, keep: np.ndarray, auto: bool, confidence: np.ndarray,
                  low_confidence: np.ndarray, depth_info: dict | None, lam: float,
                  lam_scale: float, sigma_eff: float, info: Any, iterations: int,
                  timing: dict[str, float], warns: list[str],
                  lam_floored: bool = False, depth2: np.ndarray | None = None,
                  low_confidence_threshold: float | None = None,
                  estimate: dict[str, float] | None = None,
                  noise_sample: np.ndarray | None = None,
                  refit: tuple[np.ndarray, dict] | None = None) -> Result:
    """Score a reconstruction (eq. 19, Sobel edges) and assemble its :class:`Result` and
    ``metrics.json``: the last step of :func:`reconstruct` (on every backend) and of a
    measured acquisition's reconstruction, so all report the same keys. ``noise_sample``:
    an automatic gate's solved delays, its occupied ones and the noise's sample beside them
    (:func:`~spslidar.pipeline.gate.with_reference`), which the noise verdict reads in place
    of ``slices``, where the delays not solved are zeros. ``refit``: the reflectivity
    refitted with the depth held and its record (:func:`spslidar.refit.refit_reflectivity`),
    which replaces the window's sum wherever that has one."""
    scene, acq, sim = meas.scene, meas.acq, meas.sim
    warns.extend(w for w in replaced_stages(cfg) if w not in warns)
    bin_depth = SPEED_OF_LIGHT * acq.bin_width / 2.0
    shape = (cfg.size, cfg.size)
    t0 = time.perf_counter()
    noiseless = bool(getattr(cfg, "noiseless", False))
    # (a simulation's slices read reflectivity: a gate without the scene holds round-off,
    # 3e-6 on the camera through 1-3 m, where its returns read 0.5-1.1)
    empty = noiseless and not float(np.max(slices, initial=0.0)) > 1e-4
    if empty:  # no pixel holds a return: the estimators' relative no-return rule cannot say
        # so (it kept every pixel: coverage 1.0 and an RMSE of 2.29 m beside this warning)
        depth = np.full(np.shape(depth), np.nan)
        confidence = np.zeros(np.shape(depth))
        low_confidence = np.zeros(np.shape(depth), dtype=bool)
        if depth2 is not None:  # looked for and none found: depth2.npy all NaN, a share of 0
            # (it was dropped, so no depth2.npy and a null share beside the estimator's own
            # share in depth_info: an audit of 2026-11-29)
            depth2 = np.full(np.shape(depth2), np.nan)
        if depth_info and "two_surface_fraction" in depth_info:
            depth_info = {**depth_info, "two_surface_fraction": 0.0}
        warns.append(f"no pixel holds a return in the range gate {gate_text(meas.gate)} m "
                     f"(a noiseless run): the depth map is empty; check "
                     f"that the gate holds the scene")
    unlit = sim.get("unlit_pixels")
    if unlit is not None and bool(np.any(unlit)) and not empty:
        # pixels no pattern lights were measured by none: the solve's prior fills them in,
        # and they were given confident depths, 62 % of the lit pixels' reflectivity, with
        # "returns in 100% of pixels" (an outside lab audit of 2026-11-30: a 16x32 DMD region
        # padded to 32x32)
        unlit = np.asarray(unlit, dtype=bool).ravel()

        def cleared(arr, value):  # (each in its own shape: the confidence is flat)
            return np.where(unlit.reshape(np.shape(arr)), value, arr)

        depth = cleared(depth, np.nan)
        confidence = cleared(confidence, 0.0)
        low_confidence = cleared(low_confidence, False)
        if depth2 is not None:
            depth2 = cleared(depth2, np.nan)
        warns.append(f"{int(unlit.sum())} of the {unlit.size} pixels are lit by no pattern "
                     f"(their mirror is 0 in every one: a mask, or a padded region): nothing "
                     f"measured them, so they have no depth (NaN) or reflectivity")
    if getattr(scene, "has_truth", True):
        err = depth_errors(depth, scene.depth, scene.valid)
        # (random depths where a map can put them: a gate longer than the code's unambiguous
        # range holds its first range only, and over the pixels the RMSE is over: a review)
        lo, hi = (float(v) for v in meas.gate)
        err["chance_rmse_m"] = chance_rmse(
            scene.depth, (lo, lo + min(hi - lo, acq.unambiguous_range)),
            np.asarray(scene.valid, dtype=bool) & np.isfinite(depth))
        edge_corr = edge_agreement(sobel_edges(depth), sobel_edges(scene.depth),
                                   truth_edge_mask(scene.valid))
    else:  # a measured acquisition: only what needs no truth
        found = np.isfinite(depth)
        err = {key: None for key in ("depth_rmse_m", "depth_mae_m", "depth_bias_m",
                                     "depth_max_abs_error_m", "depth_median_abs_error_m",
                                     "off_5cm_fraction", "chance_rmse_m")}
        err.update(n_valid=0, missing_fraction=float(1.0 - found.mean()),
                   coverage=float(found.mean()))
        edge_corr = None
    reflectivity = reflectivity_image(slices, depth, meas.lags, acq.bin_width)
    refit_info = {"method": "window"}
    if refit is not None and not empty:  # (an empty map: nothing refitted, NaN throughout)
        # (a return on no solved delay keeps its window's sum: an automatic gate's, or a
        # depth the estimators put outside the gate's delays)
        fitted = refit[0].reshape(shape)
        reflectivity = np.where(np.isfinite(reflectivity) & np.isfinite(fitted), fitted,
                                reflectivity)
        refit_info = {"method": "refit", **refit[1]}
    if sim.get("delay_response") is None:  # (a calibration's gain already holds the code's)
        # the code's own sidelobes beside its peak, summed with the return (a Gold code's
        # wall read 1.125 for 1, an outside audit of 2026-12-01)
        reflectivity = reflectivity / window_response(acq.code, acq.replica)
        # and the simulated instrument's IRF and jitter beyond that window (a tailed IRF's
        # wall read 0.74-0.79 of its reflectivity, an outside audit of 2026-12-03)
        share = window_share(cfg, acq.bin_width, acq.period, detector_options(cfg))
        if share != 1.0:  # (said where an instrument spreads its returns)
            reflectivity = reflectivity / share
            refit_info = {**refit_info, "instrument_window_share": share}
    # the estimators' no-return rule is relative to the brightest pixels: an image of noise
    # (nothing in the gate, too little signal) would come out as a full depth map, silently
    # (a calibrated instrument's returns span its response: sim's response_half_width)
    # (a noiseless run has no noise to tell a return from: its jitter or IRF-spread returns
    # were said to be "mostly noise" at 0.0015 m; it is said only where the gate holds none)
    aliased = meas.lags.size > acq.period  # each profile repeats its peak every period
    # (an aliased profile's noise maximum beside its peak is the peak's own repeat, ratio
    # 1.00: no verdict to make; its white-noise reference of 2048 x K slices ran out of
    # memory at K = 66 714, a 0-1000 m gate, an audit)
    half = max(2, int(sim.get("response_half_width") or 2))
    # (an automatic gate's unsolved delays are zeros, no noise: the verdict reads the solved
    # ones, the occupied delays and the noise's sample beside them, ``noise_sample``)
    seen = slices if noise_sample is None else noise_sample
    n_seen = (f"{np.shape(seen)[1]} slices" if seen is slices else
              f"the {np.shape(seen)[1]} slices solved of {np.shape(slices)[1]}")
    verdict, room = ((None, None) if noiseless or aliased else
                     verdict_and_room(seen, exclude=half))
    # None: no verdict (noiseless, aliased, too few slices, a diverged solve)
    peak_ratio, peak_floor, null = verdict if verdict is not None else (None, None, None)
    if aliased and not noiseless:
        # (a noiseless aliased run was also said to be "mostly noise": the gate-alias
        # warning says what it is)
        warns.append(
            f"no noise verdict: the range gate spans more than one code period, so each "
            f"pixel's peak repeats every {acq.unambiguous_range:.4g} m (see the range-gate "
            f"warning)")
    elif verdict is not None and peak_ratio < peak_floor:
        ratio_text, floor_text = _apart(peak_ratio, peak_floor)
        warns.append(
            f"the depth map is mostly noise: at most a tenth of the pixels hold a return above "
            f"it (the 90th percentile of each pixel's peak over its own profile's noise maximum "
            f"is {ratio_text}, under the {floor_text} a return stands at; noise alone "
            f"gives {null:.2f} here, {n_seen}): check that the range gate "
            f"{gate_text(meas.gate)} m holds the scene, the signal level, or "
            f"acquire longer")
    elif verdict is None and not noiseless and (
            room is not None or (np.shape(seen)[1] < NOISE_ONLY_MIN_SLICES
                                 and np.isfinite(seen).all())):
        # (a gate of 16+ slices that leaves too few beside a calibrated response's width
        # had its verdict dropped without a word)
        n_sl = int(np.shape(seen)[1])
        if room is None:
            qual = "too few beside a return"
            need = f"{NOISE_ONLY_MIN_SLICES} or more"
        else:
            k_eff, beside = room
            wide = (f" {2 * half + 1} slices wide (the instrument's response)" if half > 2
                    else "")
            qual = (f"as independent as {k_eff} (the matched filter correlates neighbouring "
                    f"delays) and {beside} of them beside a return{wide}, too few")
            need = (f"{NOISE_ONLY_MIN_SLICES} independent slices, {NOISE_BESIDE_MIN} of them "
                    f"beside the return")
        if noise_sample is None:
            warns.append(
                f"the range gate {gate_text(meas.gate)} m holds {n_sl} slices, {qual} to "
                f"tell it from noise ({need}): nothing here checks that the depth map is not "
                f"noise (a wider --range-gate lets it)")
        else:  # (it said "holds 15 slices" of a 19-slice gate, 15 of them solved, a review)
            warns.append(
                f"the automatic gate solved {n_sl} of the {np.shape(slices)[1]} slices of the "
                f"range gate {gate_text(meas.gate)} m, {qual} to tell it from noise ({need}): "
                f"nothing here checks that the depth map is not noise (--no-auto-gate solves "
                f"them all)")
    timing["metrics"] = time.perf_counter() - t0
    timing["total"] = sum(timing.values())

    metrics: dict[str, Any] = {
        **err,
        "depth_rmse_bins": (err["depth_rmse_m"] / bin_depth if err["depth_rmse_m"] is not None
                            else None),
        "has_truth": bool(getattr(scene, "has_truth", True)),
        # the scene used, by its canonical name (config.scene keeps the spelling given:
        # ' PROCEDURAL:007' ran procedural:7), and what it is in words (or null)
        "scene_name": str(scene.name),
        "scene_note": getattr(scene, "description", "") or None,
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
        # a measured file's share of its returns outside the range gate (None: simulated, or
        # the scene's truth says it: run's own warning)
        "returns_outside_gate_fraction": sim.get("outside_share"),
        "depth_estimator": cfg.depth,
        "low_confidence_fraction": float(np.mean(low_confidence)),
        # the estimator's confidence below which a depth is flagged (its class's
        # LOW_CONFIDENCE): a fraction means nothing without it
        "low_confidence_threshold": low_confidence_threshold,
        # 90th percentile of each pixel's peak over its own profile's noise maximum
        # (spslidar.depth.profile.peak_to_noise), and the level below which the image is said
        # to be mostly noise (None under 16 slices)
        "peak_to_noise_p90": peak_ratio,
        "peak_to_noise_floor": peak_floor,
        # share of pixels where the estimator found a second surface (None: not looked for)
        "two_surface_fraction": (float(np.mean(np.isfinite(depth2))) if depth2 is not None
                                 else None),
        "mean_reflectivity": (float(np.nanmean(reflectivity)) if np.isfinite(reflectivity).any()
                              else None),
        # how reflectivity.npy was read: refitted with the depth held (spslidar.refit), or the
        # profile's sum over the return's window (a device's solve, a unipolar replica's
        # plateau; a calibrated instrument is refitted as the ideal one is, an audit of
        # 2026-12-03)
        "reflectivity_method": refit_info,
        **({"depth_info": depth_info} if depth_info else {}),
        "lam": lam,
        "lam_scale": lam_scale if cfg.lam is None else None,
        "lam_floored": bool(lam_floored),
        "noise_level": sigma_eff,
        "solver_info": dict(info.as_dict()),
        # (a copy: the measurement's dict was every result's, so editing one result's
        # metrics["detector"] edited the next's: an audit of 2026-11-30)
        "detector": copy.deepcopy(sim["pileup"]),
        # the configuration's estimate; with ``time_s_at_floor`` where the weight met its
        # floor and the solve ran the floored cap (priced again then), and with
        # ``time_s_reconstruct`` where reconstruct() changed a simulation's processing
        "estimate": {**sim.get("estimate", {}), **(estimate or {})},
        "warnings": warns,
        "timing_s": dict(timing),
        "config": resolved_config(cfg, acq, meas.gate, auto, iterations, lam_scale),
        # the options set where the rest of the configuration gives them no effect, each
        # with its warning: config keeps them as given, so it reads back into a Config
        # (--fairness power of a PSST lidar read as applied there, an outside audit of
        # options; written null, the config no longer read back, a review)
        "ignored_options": ignored_keys(cfg),
        "seed": cfg.seed,
        "version": __version__,
        # what ran: the plugins loaded and the code's fingerprint (a plugin's "argmax" ran
        # as "argmax", metrics.json naming neither; an outside audit of 2026-11-30)
        "plugins": load_plugins([]),
        "code_fingerprint": code_fingerprint(),
    }
    return Result(cfg, scene, depth, slices, meas.lags, corr, metrics, timing, warns,
                  confidence=np.asarray(confidence).reshape(shape),
                  low_confidence=np.asarray(low_confidence).reshape(shape),
                  reflectivity=reflectivity,
                  depth2=None if depth2 is None else np.asarray(depth2).reshape(shape))


def replaced_stages(cfg: Config) -> list[str]:
    """The warning a registry gave where a plugin replaced a built-in stage (at the plugin's
    load, on stderr), for each stage of ``cfg`` so replaced: a run's own record of it (a
    plugin's ``argmax`` ran with ``depth: "argmax"`` and no word in ``metrics.json``; an
    outside audit of 2026-11-30)."""
    from ..codes import CODES
    from ..depth import ESTIMATORS
    from ..detectors import DETECTORS
    from ..patterns import PATTERNS
    from ..scenes import SCENES
    from ..solvers.entries import REGULARISERS, SOLVERS

    chosen = ((CODES, cfg.code), (PATTERNS, cfg.patterns), (DETECTORS, cfg.detector),
              (SOLVERS, cfg.solver), (REGULARISERS, regulariser_kind(cfg)),
              (ESTIMATORS, cfg.depth), (SCENES, str(cfg.scene).strip().partition(":")[0]))
    out = []
    for reg, name in chosen:
        old = reg.replaced(name)
        if old is not None and name in reg and reg.get(name).target != old.target:
            out.append(f"the {reg.kind} {name!r} ({old.target!r}) is replaced by "
                       f"{reg.get(name).target!r}")
    return out


def resolved_config(cfg: Config, acq: Acquisition, gate, auto_gate: bool, iterations: int,
                    lam_scale: float) -> dict[str, Any]:
    """The config with every ``auto``/unset key replaced by the value the run used, so a
    score can be recomputed from ``metrics.json`` alone."""
    d = cfg.to_dict()
    d["iterations"] = int(iterations)
    d["lam_scale"] = float(lam_scale)
    d["code_index"] = acq.code_index
    d["replica"] = acq.replica
    if acq.lidar == "conventional":  # the pulse period is whole bins (--rep-rate 4e9 -> 5e9)
        d["rep_rate"] = acq.repetition_rate
    d["regulariser"] = regulariser_kind(cfg)
    d["range_gate"] = [float(gate[0]), float(gate[1])]
    d["auto_gate"] = bool(auto_gate)
    if not cfg.qcr and d["regulariser"] in TV_REGULARISERS:
        d["nonneg"] = False  # the mean-eliminated plain problem has no sign constraint
    if d["regulariser"] == "wavelet":  # no closed-form prox under the bound (make_wavelet_l1)
        d["nonneg"] = False
    # an option no chosen stage declares is not one the run used: null, as the README's rule
    # has it (a linear detector's run recorded the GMAPD's jitter and afterpulsing, and a
    # plugin's options of stages not chosen at their defaults: an outside audit of 2026-12-01)
    used = set()
    for key, registry in registries().items():
        used.update(opt.name for opt in registry.get(getattr(cfg, key)).options)
    for name in stage_options():
        if name not in used and name in d:
            d[name] = None
    return d



def _apart(value: float, floor: float) -> tuple[str, str]:
    """``value`` and ``floor`` with the digits (2 to 6) that tell them apart: "2.07, under the
    2.07" was said of 2.066 under 2.07 (an outside audit of 2026-12-03)."""
    for digits in range(2, 7):
        a, b = f"{value:.{digits}f}", f"{floor:.{digits}f}"
        if a != b:
            break
    return a, b
