"""What a run needs before its first large array: random streams, code, range gate, the
memory estimate (refused in one line before any work), and the detector's options.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from ..config import Config
from ..constants import SPEED_OF_LIGHT
from ..correlate import PLATEAU_SHARE, auto_replica, gate_lags, replica_plateau
from ..forward import lag_to_depth
from ..patterns import HADAMARD_KINDS, PATTERNS, n_patterns_for
from ..scenes import load_scene
from ..solvers.entries import TV_REGULARISERS
from .acquisition import GATE_PAD_BINS, Acquisition, default_gate, make_acquisition
from .budget import check_budget, estimate_budget
from .gate import gate_text, unique_lags
from .measurement import _resolve
from .simulate import simulation_threads


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
        warns.append(gate_alias_warning(gate, lags.size, acq.period, acq.unambiguous_range,
                                        acq.description))
    if cfg.range_gate is None and lags[-1] >= acq.period:
        warns.append(default_gate_beyond_warning(scene, gate, acq))
    elif (cfg.range_gate is not None and lags.size <= acq.period
          and gate[0] >= acq.unambiguous_range):
        # (a given gate at 40-60 m through a 30.67 m code read the wall at 50 m, said by
        # reconstruct and not by run: an audit)
        warns.append(gate_beyond_warning(gate, acq.unambiguous_range, acq.description))
    warns.extend(rep_rate_warnings(cfg, acq))
    span = read_span(lags, bin_width, cfg.pulse_width)
    outside = (scene.depth < span[0]) | (scene.depth >= span[1])
    if np.any(outside & scene.valid):
        # (most of them are given a depth inside the gate all the same, the solve's faint
        # ghosts of the scene, with a confidence of 0.8-1.0: 458 of 672 on a 5-60 m ramp
        # through a 20-40 m gate, an outside audit; no per-pixel test tells them from a dark
        # surface, so the warning says it)
        warns.append(f"{int((outside & scene.valid).sum())} pixels lie outside the range gate "
                     f"{gate_text(gate)} m: their returns alias into the gate or are lost, "
                     f"and they may be given depths inside the gate all the same (faint "
                     f"ghosts that their confidence does not flag): widen the gate to hold "
                     f"them")
    # the pixels without a truth are simulated too, and the default gate is the truth's: a
    # scene of one valid pixel had 255 surfaces outside it unsaid, its figure all noise (an
    # audit)
    unscored = outside & ~np.asarray(scene.valid, dtype=bool) & (
        np.asarray(scene.reflectivity) > 0)
    if np.any(unscored):
        warns.append(f"{int(unscored.sum())} pixels without a ground truth (not scored) have "
                     f"surfaces outside the range gate {gate_text(gate)} m: their returns "
                     f"alias into the gate or are lost")
    warns.extend(delay_warnings(cfg, scene, gate, acq.unambiguous_range, span))
    return seq_pat, seq_counts, seq_probe, acq, gate, lags, ulags, inverse


def default_gate_beyond_warning(scene, gate: tuple[float, float], acq: Acquisition) -> str:
    """The warning for a default range gate (placed from the scene's own depths) that
    reaches beyond the code's unambiguous range: the returns there wrap with the code, and
    only the truth's prior put the gate where they read right (the camera at 20-20.8 m with a
    1023-bit code, 15.33 m unambiguous, gave an RMSE of 0.0048 m and no word; a gate placed
    within one unambiguous range instead reads it 15.33 m too near)."""
    ru = acq.unambiguous_range
    far = float(scene.depth_max)
    cure = ("a slower --rep-rate (or none: the default covers the gate)"
            if acq.lidar == "conventional" else "a longer --code-length")
    return (f"the default range gate {gate_text(gate)} m was placed from the scene's own "
            f"depths, which a real acquisition does not know, and reaches beyond the "
            f"{ru:.4g} m unambiguous range of the {acq.description}: a real acquisition would "
            f"read these returns aliased to their depth modulo {ru:.4g} m (the farthest, "
            f"{far:.4g} m, at {far % ru:.4g} m); give the --range-gate the instrument would "
            f"know, or {cure}{_units_hint(scene, ru)}")


#: the nearest depth from which a scene beyond the unambiguous range is asked whether it is
#: in millimetres (10 cm in millimetres)
MM_PLAUSIBLE_M = 100.0


def _units_hint(scene, ru: float) -> str:
    """Where a whole scene lies beyond the code's unambiguous range, the question of its
    units (a depth map in millimetres, 2500-3550, was simulated at 2.5-3.55 km, and each
    warning said only to lengthen the code, which left an RMSE of 137 m, an audit)."""
    near, far = float(scene.depth_min), float(scene.depth_max)
    # (not of a scene within MM_PLAUSIBLE_M, whose metres would be a few centimetres: the
    # camera at 20 m with a 1023-bit code was asked, a review)
    if not (near > ru and near >= MM_PLAUSIBLE_M):
        return ""
    return (f"; are the scene's depths in metres? It lies at {near:.4g}-{far:.4g} m (read as "
            f"millimetres, {near / 1000:.4g}-{far / 1000:.4g} m)")


def rep_rate_warnings(cfg: Config, acq: Acquisition) -> list[str]:
    """The conventional lidar's pulse period is a whole number of TDC bins: a ``--rep-rate``
    that rounding changes by more than 1 % is said, with the rate used (``--rep-rate 4e9`` at
    10 GHz ran at 5 GHz without a word)."""
    if acq.lidar != "conventional" or cfg.rep_rate is None:
        return []
    used = acq.repetition_rate
    if abs(used - cfg.rep_rate) <= 0.01 * cfg.rep_rate:
        return []
    return [f"--rep-rate {cfg.rep_rate:g} Hz is not a whole number of --bit-rate "
            f"{cfg.bit_rate:g} Hz bins: the pulse period is rounded to {acq.period} bins and "
            f"the lidar runs at {used:.6g} Hz ({100 * (used / cfg.rep_rate - 1):+.3g} %)"]


def read_span(lags: np.ndarray, bin_width: float, pulse_width: float) -> tuple[float, float]:
    """The depths ``[lo, hi)`` whose returns a gate's delays ``lags`` read where they are:
    the gate's lags are its ends rounded outward, and lag ``b`` holds the returns whose
    leading edge lies within half a bin of its :func:`~spslidar.forward.lag_to_depth`, so a
    wall 1.7 cm past a 3.13 m gate's far end was read right at 3.15 m while the warnings,
    which compared with the gate itself, called it outside (an outside audit of
    2026-12-03)."""
    half = SPEED_OF_LIGHT * bin_width / 4.0  # half a bin of depth
    ends = lag_to_depth(np.array([lags[0], lags[-1]]), bin_width, pulse_width)
    return float(ends[0] - half), float(ends[1] + half)


def delay_warnings(cfg: Config, scene, gate: tuple[float, float],
                   unambiguous: float | None = None,
                   span: tuple[float, float] | None = None) -> list[str]:
    """What a simulated ``system_delay`` does to ``run``'s own depths: ``run`` reconstructs
    as an uncalibrated instrument would, so every return reads ``c delay / 2`` too far, and
    with the default gate (set from the scene's true depths) the returns fall beyond it and
    the depth map is noise (measured: the camera with 13.74 ns, RMSE 0.34 m and no warning).
    The delay is for ``--save-ptu`` acquisitions that ``spslidar calibrate`` and
    ``reconstruct --calibration`` remove it from. ``span`` is the depths the gate's delays
    read (:func:`read_span`; the gate itself where not given)."""
    if not cfg.system_delay > 0:
        return []
    shift = SPEED_OF_LIGHT * float(cfg.system_delay) / 2.0
    seen = scene.depth + shift
    ru = unambiguous if unambiguous and shift >= unambiguous * (1 - 1e-9) else None
    lo, hi = span if span is not None else gate
    if ru:  # the returns wrap with the code (a delay of one period read the true depths)
        inside = lo + np.mod(seen - lo, ru) < hi
    else:
        inside = (seen >= lo) & (seen < hi)
    beyond = int(np.sum(~inside & scene.valid))
    where = (f"; {beyond} pixels' delayed returns fall outside the range gate "
             f"{gate_text(gate)} m" if beyond else "")
    wrapped = shift % ru if ru else shift
    if ru and min(wrapped, ru - wrapped) < 1e-6 * ru:  # a whole number of periods: 0 m
        wrapped = 0.0
    far = (f"{wrapped:.3g} m too far, modulo the code's {ru:.3g} m unambiguous range that "
           f"the {shift:.3g} m reaches" if ru else f"{shift:.3g} m too far")
    return [f"--system-delay {cfg.system_delay:g} s delays every return by {shift:.3g} m and "
            f"run reads its depths as an uncalibrated instrument does ({far}{where}): "
            f"calibrate on a flat target and reconstruct --calibration, as in the README's "
            f"'From your hardware to a depth map'"]


def ignored_keys(cfg: Config) -> dict[str, str]:
    """The options set away from their defaults where the rest of the configuration gives
    them no effect, each with its warning (a sweep may cross such options, so they are said,
    not refused, and a sweep's points that differ only in them share their seed):
    ``rep_rate`` of a PSST lidar (its period is the code's), ``hadamard_order`` and
    ``hadamard_realisation`` of patterns that are not Hadamard rows, ``pattern_sigma`` of
    patterns that are not grey Gaussian ones, ``qcr_form`` without QCR, ``fairness`` of a
    PSST lidar, the code of a conventional one (under its ``power`` fairness, which counts
    the code's ones, the ones ratio of an m-sequence or Gold code and the shift of an
    m-sequence: :func:`_power_ignored`), ``lam_scale`` beside ``lam``."""
    import dataclasses

    fields = {f.name: f.default for f in dataclasses.fields(Config)}

    def changed(name: str) -> bool:  # set away from the Config's own default
        return getattr(cfg, name) != fields[name]

    out: dict[str, str] = {}
    if changed("rep_rate") and cfg.lidar != "conventional":
        out["rep_rate"] = (f"--rep-rate {cfg.rep_rate:g} is ignored: it sets the pulse period of "
                           f"--lidar conventional; a {cfg.lidar} lidar repeats its code")
    if changed("hadamard_order") and cfg.patterns != "hadamard":
        out["hadamard_order"] = (f"--hadamard-order {cfg.hadamard_order} is ignored: it orders "
                                 f"the rows of --patterns hadamard, not {cfg.patterns}")
    if changed("qcr_form") and not cfg.qcr:
        out["qcr_form"] = f"--qcr-form {cfg.qcr_form} is ignored with --no-qcr"
    if changed("hadamard_realisation") and cfg.patterns not in HADAMARD_KINDS:
        # (scrambled Hadamard rows are shown so too: it was said to be ignored there while it
        # was applied, an outside audit)
        out["hadamard_realisation"] = (
            f"--hadamard-realisation {cfg.hadamard_realisation} is ignored: it shows the rows "
            f"of --patterns {' or '.join(HADAMARD_KINDS)}, not {cfg.patterns}")
    if changed("noise_split") and cfg.ambient == "paper":
        # (under the paper's ambient light the three shares add up to m_n per bin whatever
        # they are: an audit's splits gave the same depth map, the GMAPD's included)
        out["noise_split"] = (
            f"--noise-split {' '.join(f'{v:g}' for v in cfg.noise_split)} is ignored with "
            f"--ambient paper, where the three shares add up to --noise per bin whatever they "
            f"are; they differ under --ambient modulated (the ambient share through the "
            f"patterns)")
    if changed("pattern_sigma") and cfg.patterns != "gaussian":
        out["pattern_sigma"] = (f"--pattern-sigma {cfg.pattern_sigma:g} is ignored: it spreads "
                                f"the grey levels of --patterns gaussian, not {cfg.patterns}")
    if changed("fairness") and cfg.lidar != "conventional":
        out["fairness"] = (f"--fairness {cfg.fairness} is ignored: it sets the pulses of "
                           f"--lidar conventional against the PSST's; a {cfg.lidar} lidar is "
                           f"the reference")
    if cfg.lidar == "conventional" and cfg.fairness != "power":
        keys = [k for k in ("code", "code_index", "ones_ratio") if changed(k)]
        if keys:
            unused = [f"--{k.replace('_', '-')} {getattr(cfg, k)}" for k in keys]
            text = (f"{', '.join(unused)} {'is' if len(unused) == 1 else 'are'} ignored: "
                    f"--lidar conventional fires single pulses, not a code (--code-length "
                    f"still sets each pattern's time)")
            out.update(dict.fromkeys(keys, text))
    elif cfg.lidar == "conventional":  # 'power' takes only the code's count of ones
        out.update(_power_ignored(cfg, changed))
    if cfg.lam is not None and cfg.lam_scale is not None:
        out["lam_scale"] = (f"--lam-scale {cfg.lam_scale:g} is ignored: --lam {cfg.lam:g} sets "
                            f"the weight itself")
    return out


def nonneg_dropped(cfg: Config) -> str | None:
    """Why ``cfg``'s non-negativity bound is not applied, where it is asked for and dropped
    (:func:`~spslidar.pipeline.score.resolved_config` records ``nonneg`` false then): without
    QCR under a TV regulariser (the mean-eliminated problem has no sign constraint), or
    under the wavelet regulariser (its prox has no closed form under the bound); else None.
    Said only where the bound was asked for (:func:`asked_notes`): the default's is dropped
    in every such run."""
    from .weights import regulariser_kind

    if not cfg.nonneg:
        return None
    kind = regulariser_kind(cfg)
    if not cfg.qcr and kind in TV_REGULARISERS:
        return ("the non-negativity bound asked for (--nonneg, nonneg = true) is not applied "
                "with --no-qcr: the mean-eliminated problem it solves has no sign constraint "
                "(metrics.json's config says nonneg false)")
    if kind == "wavelet":
        whose = " (gpsr's default)" if cfg.solver == "gpsr" else ""
        return (f"the non-negativity bound asked for (--nonneg, nonneg = true) is not applied "
                f"with --regulariser wavelet{whose}: its prox has no closed form under the "
                f"bound (metrics.json's config says nonneg false)")
    return None


def asked_notes(cfg: Config, asked, said=()) -> list[str]:
    """What a reconstruction with ``cfg`` says of its processing keys, less what is already
    ``said``: each processing key it ignores (:func:`ignored_keys`: ``lam_scale`` beside
    ``lam``, ``qcr_form`` without QCR), and the non-negativity bound where it was ``asked``
    for (the user's own keys: :attr:`~.measurement.Measurement.asked` and reconstruct's) and
    dropped (:func:`nonneg_dropped`). ``reconstruct(meas, lam=0.1, lam_scale=0.3)`` recorded
    its weight factor without a word, and ``--nonneg`` through ``reconstruct --no-qcr`` ran
    without the bound unsaid (a review of 2026-12-03)."""
    from .measurement import PROCESSING_KEYS

    notes = [text for key, text in ignored_keys(cfg).items() if key in PROCESSING_KEYS]
    wanted = dict(asked).get("nonneg")
    if wanted is not None and not isinstance(wanted, str) and bool(wanted):  # (np.True_ too)
        notes += [n for n in (nonneg_dropped(cfg),) if n]
    return [n for n in dict.fromkeys(notes) if n not in said]


def report_only_keys(cfg: Config) -> dict[str, str]:
    """The chosen detector's options set away from their defaults that change only its
    report, not its counts (the class's ``report_only``, a mapping from each option to what
    it sets, or a sequence of names: the linear counter's ``dead_time``, which sets its
    pile-up flag), each with its warning. Not said by a run, whose report is what the option
    is for; a sweep's points that differ only in them share their seed and are said (a grid
    over ``dead_time`` of the linear counter drew other noise at each point, an effect of
    dead time that it does not model: an outside audit of 2026-12-03). The words are the
    class's (they named the pile-up report for any detector's option: a review)."""
    from ..config import stage_options
    from ..detectors import DETECTORS

    own = stage_options()
    declared = getattr(DETECTORS.load(cfg.detector), "report_only", ())
    sets = declared if isinstance(declared, dict) else dict.fromkeys(declared, "its report")
    out: dict[str, str] = {}
    for name, what in sets.items():
        default = own[name][1].default if name in own else None
        value = cfg.extra.get(name, default)
        if value != default:  # (a plugin's option need not be a number)
            text = f"{value:g}" if isinstance(value, (int, float)) else str(value)
            out[name] = (f"--{name.replace('_', '-')} {text} of --detector {cfg.detector} "
                         f"changes only {what}, not its counts")
    return out


def _power_ignored(cfg: Config, changed) -> dict[str, str]:
    """The code options a conventional lidar under ``--fairness power`` ignores: it takes
    only the code's count of ones (its pulses share the PSST's photons), which a cyclic shift
    of an m-sequence keeps and a ones ratio sets only for a random code (a PSST lidar refuses
    that ratio; here a sweep may cross it, so it is said)."""
    out: dict[str, str] = {}
    if changed("ones_ratio") and cfg.code != "random":
        from ..codes import CODES

        fixed = "an m-sequence's" if cfg.code == "mseq" else f"a {CODES.get(cfg.code).display}'s"
        out["ones_ratio"] = (f"--ones-ratio {cfg.ones_ratio:g} is ignored: {fixed} share of "
                             f"ones is fixed, and --lidar conventional --fairness power takes "
                             f"only the code's count of ones")
    if changed("code_index") and cfg.code == "mseq":
        out["code_index"] = (f"--code-index {cfg.code_index} is ignored: a cyclic shift keeps "
                             f"the m-sequence's count of ones, all that --lidar conventional "
                             f"--fairness power takes from the code")
    return out


def ignored_options(cfg: Config) -> list[str]:
    """A warning for each option set away from its default where the rest of the
    configuration gives it no effect (:func:`ignored_keys`), and for natural-order Hadamard
    rows below full sampling (legal, but they alias)."""
    from .measurement import PROCESSING_KEYS

    # (a processing key's, --lam-scale beside --lam, is said by reconstruct from the
    # configuration it solves with: said here, a sweep's shared measurement carried one
    # point's note to the next, a review)
    out = list(dict.fromkeys(text for key, text in ignored_keys(cfg).items()
                             if key not in PROCESSING_KEYS))
    if cfg.patterns == "hadamard" and cfg.hadamard_order == "natural" and cfg.compression < 1:
        # legal, kept as the reference ordering, but a trap (found by a sweep of unusual
        # regimes: the steps at 32x32, 25 %, 0.25 m against cake-cutting's 0.0015 m, no word)
        out.append(f"--hadamard-order natural at --compression {cfg.compression:g} takes the "
                   f"first rows of Sylvester's order, whose patterns repeat down the image "
                   f"(every {cfg.compression:g} of its height or so): rows that far apart "
                   f"cannot be told apart and each object is copied into bands; cake-cutting "
                   f"(the default) or sequency order does not alias")
    return out


def _dense_patterns(cfg: Config) -> bool:
    """Whether the run holds its ``M x Q`` patterns as a matrix: a dense kind, or differential
    Hadamard rows on another backend than NumPy (which builds them as a matrix: 3.4 GB at
    128x128, a MemoryError at 256x256, which no estimate had counted)."""
    if PATTERNS.get(cfg.patterns).defaults.get("dense"):
        return True
    # (scrambled-hadamard's differential rows are built as a matrix too, and were not
    # counted: 0.32 GB estimated, 0.49 GB at its peak at 128x128, an audit of 2026-11-29)
    return (cfg.backend != "numpy" and cfg.patterns in HADAMARD_KINDS
            and cfg.hadamard_realisation == "differential")


def _plan(cfg: Config, scene, warns: list[str], announce: bool = True,
          check: bool = True) -> _Plan:
    """The cheap part of :func:`measure`: code, range gate and the memory check (refused in
    one line before any large array exists). ``check=False`` (an accelerator: its patterns and
    arrays live in its own memory, and it runs far above the host's estimated FLOP rate)
    estimates without refusing."""
    seq_pat, seq_counts, seq_probe, acq, gate, lags, ulags, inverse = timeline(cfg, scene,
                                                                                warns)
    warns.extend(ignored_options(cfg))
    bin_width = 1.0 / cfg.bit_rate
    q = cfg.size * cfg.size
    m = n_patterns_for(cfg.compression, q)
    dtype = np.float32 if cfg.dtype == "float32" else np.float64
    bin_depth = SPEED_OF_LIGHT * bin_width / 2.0
    budget = estimate_budget(
        cfg, n_patterns=m, period=acq.period, n_lags=lags.size, n_ulags=ulags.size,
        window_bins=int((scene.depth_max - scene.depth_min) / bin_depth) + 2 * GATE_PAD_BINS,
        pattern_bytes_per_entry=(np.dtype(dtype).itemsize if _dense_patterns(cfg) else None),
        threads=simulation_threads())
    _check_half_frames(cfg, acq)
    if check:
        check_budget(budget, cfg.max_memory, cfg.patterns, cfg.max_time, announce=announce)
    return _Plan(seq_pat, seq_counts, seq_probe, acq, gate, lags, ulags, inverse, m, dtype,
                 budget)


def _check_half_frames(cfg: Config, acq: Acquisition) -> None:
    """Refuse (one line) a GMAPD with a dead time under differential Hadamard frames of a
    whole number and a half of periods: each frame lasts half the dwell, and the dead-time
    model draws whole periods (none of half a period: exit 0 with an empty map, an outside
    audit; a third too few of 1.5). Checked with the plan, so that ``preflight`` and a
    sweep's check see it (a review); without a dead time the counts are Poisson, any dwell."""
    if not (cfg.patterns in HADAMARD_KINDS and cfg.hadamard_realisation == "differential"
            and cfg.detector == "gmapd" and cfg.dead_time > 0 and acq.n_periods % 2):
        return
    from ..errors import ConfigError

    if acq.lidar == "conventional":
        fix = (f"give an even number of pulses per pattern ({acq.n_periods} now: --periods "
               f"or --rep-rate)")
        what = f"{acq.n_periods} pulses"
    else:
        fix = "give an even --periods"
        what = f"{acq.n_periods} code period{'s' if acq.n_periods != 1 else ''}"
    raise ConfigError(f"--hadamard-realisation differential shows each pattern as two frames, "
                      f"each for half of its {what}, and --detector gmapd with a dead time "
                      f"simulates whole periods: {fix}")


def preflight(config: Config | dict | None = None, **overrides):
    """Check that a configuration can run here, without running it: its scene loads and its
    estimated memory fits (:func:`~spslidar.pipeline.budget.check_budget`). Sweeps call it for
    every point before the first run. Returns the :class:`~spslidar.pipeline.budget.Budget`."""
    cfg = _resolve(config, overrides)
    _check_pattern_floor(cfg)
    scene = load_scene(cfg.scene, cfg.size, cfg.depth_min, cfg.depth_max)
    return preflight_plan(cfg, scene).budget


def preflight_plan(cfg: Config, scene) -> Any:
    """:func:`preflight`'s checks of ``cfg`` on a scene already loaded, returning the whole
    plan (its acquisition's code period and bin width, which a check of the IRF needs, and
    its budget): a sweep loads each distinct scene once for all its points."""
    _check_pattern_floor(cfg)
    return _plan(cfg, scene, [], announce=False)


def _check_pattern_floor(cfg: Config) -> None:
    """Refuse at once a run whose dense pattern matrix alone cannot fit (the full estimate
    needs the scene, whose loading takes a while at large sizes)."""
    if not PATTERNS.get(cfg.patterns).defaults.get("dense"):
        return
    from .budget import BASE_BYTES, DENSE_PATTERN_COPIES, Budget

    q = cfg.size * cfg.size
    m = n_patterns_for(cfg.compression, q)
    floor = DENSE_PATTERN_COPIES * m * q * (4 if cfg.dtype == "float32" else 8)
    parts = {"interpreter": BASE_BYTES, "patterns": floor}
    check_budget(Budget(BASE_BYTES + floor, 0.0, parts), cfg.max_memory, cfg.patterns)


def detector_options(cfg: Config) -> dict[str, Any]:
    """The chosen detector model's keyword arguments: the options its registry entry declares
    (each under its ``param`` name) and the context it asks for (``context=("bin_width",)``:
    the TDC bin width); dark counts are in the noise model."""
    from ..detectors import DETECTORS

    entry = DETECTORS.get(cfg.detector)
    context = {"bin_width": 1.0 / cfg.bit_rate}
    out = {name: context[name] for name in entry.defaults.get("context", ())}
    from ..config import chosen_stage_options

    out.update(chosen_stage_options(cfg, "detector"))
    return out


def gate_beyond_warning(gate, unambiguous: float, description: str) -> str:
    """The warning for a given range gate that lies wholly beyond the code's unambiguous range
    (``run`` and ``reconstruct``): it reads what lies there only if the target is known to
    be in it."""
    lo, hi = (float(v) for v in gate)
    ru = float(unambiguous)
    return (f"the range gate {gate_text((lo, hi))} m lies beyond the {ru:.4g} m unambiguous "
            f"range of the {description}: a return is known only modulo {ru:.4g} m (this "
            f"gate reads what lies at {lo % ru:.4g}-{lo % ru + hi - lo:.4g} m, {ru:.4g} m "
            f"farther, ...), so its depths are right only if the target is known to be in "
            f"the gate")


def gate_alias_warning(gate, n_lags: int, period: int, unambiguous: float,
                       description: str) -> str:
    """The warning for a gate of more delay bins than the code's period (``run`` and
    ``reconstruct``). Its ends are rounded out to whole bins, so a gate a hair shorter than the
    unambiguous range can span one bin more than the period: said with the bins, not only
    the metres (0-1.9186 m "longer than the 1.92 m unambiguous range" read as nonsense)."""
    return (f"range gate {gate_text(gate)} m spans {n_lags} delay bins (its ends rounded "
            f"out to whole bins), more than the {period} of one period of the {description} "
            f"({unambiguous:.4g} m unambiguous range): returns at d and d + {unambiguous:.4g} m "
            f"are indistinguishable and the estimate takes the nearest alias inside the gate")


def plateau_notes(acq, plateau: float, unipolar: bool, reg_kind: str) -> list[str]:
    """What a replica's plateau (:func:`~spslidar.correlate.replica_plateau`) does that no
    step undoes, in one line each: a pedestal below zero, which the non-negative solve
    clips, and a unipolar plateau under a sparsity prior, which shrinks it before it is
    taken out (both exit 0 without a word before: a noiseless 16x16 scene read 0.29-0.31 m
    with 28-34 % of its pixels lost, and 0.22 m against TV's 0.0015 m; an outside audit of
    2026-11-30, options paired)."""
    notes = []
    if plateau <= -PLATEAU_SHARE:
        code = np.asarray(acq.code)
        ones = f"{int(np.count_nonzero(code > 0))} of its {code.size} bits ones"
        auto = "unipolar" if acq.lidar == "conventional" else auto_replica(code)
        fix = f"--replica auto takes the {auto} replica for such a code"
        if acq.lidar != "conventional":
            # (a code this short leaves a pedestal through every replica that sums to zero:
            # the advice named the replica in use, a 3-bit code's bipolar one, -1.00)
            plateaus = {k: replica_plateau(code, k) for k in ("zero-mean", "bipolar")}
            best = max(plateaus, key=plateaus.get)
            if plateaus[best] <= -PLATEAU_SHARE:
                shortest = int(np.ceil(1.0 + 1.0 / PLATEAU_SHARE))
                fix = (f"no replica avoids it for a code of {code.size} bits (the {best} "
                       f"one leaves {plateaus[best]:+.2f}): use a code of at least "
                       f"{shortest} bits (--code-length)")
            elif auto == acq.replica:  # (auto's own choice: name the one that avoids it)
                fix = f"--replica {best} leaves {plateaus[best]:+.2f}"
        notes.append(f"the {acq.replica} replica of this code ({ones}) leaves every "
                     f"profile on a pedestal of {plateau:+.2f} times its return, which the "
                     f"solve's non-negativity clips: depths can be lost or wrong; {fix}")
    if unipolar and reg_kind not in TV_REGULARISERS:
        notes.append(f"the unipolar replica leaves {plateau:.2f} times each return at every "
                     f"delay, which the {reg_kind} prior shrinks as it would noise before "
                     f"it is taken out: depths can be lost or wrong; use --regulariser tv "
                     f"(with a solver that takes it: fista, twist, tval3) or another "
                     f"--replica")
    return notes
