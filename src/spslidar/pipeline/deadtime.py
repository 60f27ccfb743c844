"""The dead time of a measured acquisition's detector: each marker block's histogram corrected
for pile-up before the matched filter (``reconstruct --dead-time``, ``calibrate
--dead-time``), and a word where the count rate says a dead time would matter and none was
given.

A real single-photon detector and its TCSPC electronics go dead after each detection (SPADs
and PicoQuant's HydraHarp and PicoHarp: 20-100 ns; non-paralysable), so the photons of a
strong return are counted less than those of a weak one, and each pattern's count is
compressed as ``n / (1 + n)`` of its photons per dead time: the contrast between patterns that
the reconstruction reads falls with it (README, "How to operate a PSST lidar with a GMAPD").
``run --detector gmapd`` simulates such a detector and corrects its histograms; this module
applies the same correction (:meth:`spslidar.detectors.gmapd.GMAPD.correct`, the generalised
Coates estimate of Rapp et al. 2019 for a free-running detector) to the histograms a file
holds, block by block with each block's own number of code periods (its dwell), and gives
the matched filter the corrected counts' variance
(:meth:`~spslidar.detectors.gmapd.GMAPD.noise_totals`).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..arrays import real_number
from ..errors import ConfigError

__all__ = ["DEAD_TIME_KEYS", "GAP_EVIDENCE", "LOSS_TO_WARN", "MAX_DETECTOR_RATE_HZ",
           "RATE_RATIO", "TYPICAL_DEAD_TIMES_S", "apparent_dead_time", "apply_dead_time",
           "calibration_note", "correct_blocks", "dead_time_model", "pileup_report",
           "rate_note"]

#: the keyword arguments of the measured paths (``reconstruct_ptu``, ``calibrate_ptu``)
DEAD_TIME_KEYS = ("dead_time", "afterpulse_prob", "afterpulse_delay")
#: dead times of the detectors and TCSPC electronics a PSST lidar is built with (SPADs,
#: HydraHarp / PicoHarp), for the word said where no --dead-time is given
TYPICAL_DEAD_TIMES_S = (20e-9, 100e-9)
#: the share of photons the longer typical dead time must lose for that word (the 5 % rule of
#: TCSPC practice: below it pile-up is negligible)
LOSS_TO_WARN = 0.05
#: counts per second past which no single detector counts (a simulation's linear counter, or
#: many channels merged): nothing is said of a dead time there
MAX_DETECTOR_RATE_HZ = 1e9
#: the longest dead time taken (as ``run --dead-time``): a millisecond is a unit mistake
MAX_DEAD_TIME_S = 1e-3
#: histograms corrected at a time (memory: the inverse's working arrays, about 40 of them)
CORRECT_ROWS = 64


def _time(value: Any, flag: str) -> float:
    """A non-negative time in seconds of at most ``MAX_DEAD_TIME_S``, or one line."""
    t = real_number(value)
    if t is None:
        raise ConfigError(f"{flag} must be a time in seconds, got {value!r}")
    if not (math.isfinite(t) and 0.0 <= t <= MAX_DEAD_TIME_S):
        raise ConfigError(f"{flag} must be a time in seconds from 0 to {MAX_DEAD_TIME_S:g} "
                          f"(detectors go dead for 10 ns to 10 us), got {value!r}")
    return t


def dead_time_model(bin_width: float, dead_time: Any = None, afterpulse_prob: Any = 0.0,
                    afterpulse_delay: Any = 0.0):
    """The detector model whose pile-up a measured acquisition is corrected for, or ``None``
    where no dead time is given (the counts are taken as they are).

    Parameters
    ----------
    bin_width : float
        The TDC bin, seconds.
    dead_time : float or None
        Non-paralysable dead time of the detector and its electronics, seconds: 0 (it has
        none: nothing is corrected, and nothing is said of the count rate) or at least one
        bin; ``None``: not given.
    afterpulse_prob, afterpulse_delay : float
        The detector's afterpulsing (probability per avalanche, mean delay after re-arming
        in seconds), taken out with the dead time.

    Returns
    -------
    GMAPD or None

    Raises
    ------
    ConfigError
        One line for a value that is not a time or probability, a dead time under one bin,
        or afterpulsing without its delay or without a dead time given.
    """
    prob = afterpulse_prob if afterpulse_prob is not None else 0.0
    delay = afterpulse_delay if afterpulse_delay is not None else 0.0
    p = real_number(prob)
    if p is None or not (math.isfinite(p) and 0.0 <= p < 1.0):
        raise ConfigError(f"--afterpulse-prob must be a probability in [0, 1), got {prob!r}")
    delay = _time(delay, "--afterpulse-delay")
    if dead_time is None:
        if p or delay:  # (they would do nothing: said, as run says it)
            raise ConfigError("--afterpulse-prob and --afterpulse-delay are corrected with the "
                              "detector's dead time: give --dead-time too (0 if it has none)")
        return None
    dead = _time(dead_time, "--dead-time")
    if 0.0 < dead < bin_width * (1 - 1e-9):
        raise ConfigError(f"--dead-time ({dead:g} s) must be 0 or at least one TDC bin "
                          f"(1 / --bit-rate = {bin_width:g} s)")
    if p > 0 and not delay > 0:
        raise ConfigError("--afterpulse-delay must be positive when --afterpulse-prob > 0")
    if delay > 0 and not p > 0:
        raise ConfigError("--afterpulse-delay does nothing without --afterpulse-prob (the "
                          "probability of an afterpulse) above 0")
    from ..detectors import build_detector

    # (the bin-level inverse in closed form: a code spreads a period's photons over hundreds
    # of pulses, so no bin's flux needs the sub-binned refinement, which near saturation ran
    # for 28 s per 64 patterns and read no closer: 30 photons per dead time, 2.2 against
    # 1.9 times the photons from one draw of the counts, both exact on expected counts)
    return build_detector("gmapd", dead_time=dead, bin_width=float(bin_width),
                          afterpulse_prob=p, afterpulse_delay=delay, oversample=1)


def correct_blocks(hist: np.ndarray, periods: np.ndarray, detector
                   ) -> tuple[np.ndarray, np.ndarray]:
    """Each block's histogram corrected for pile-up, with its own dwell.

    Parameters
    ----------
    hist : ndarray, shape (M, L)
        Detected counts per block (pattern) and TDC bin.
    periods : ndarray, shape (M,)
        Code periods each block lasted (whole numbers >= 1).
    detector : GMAPD
        From :func:`dead_time_model`.

    Returns
    -------
    corrected : ndarray, shape (M, L)
        The photons per bin a detector without dead time would have counted
        (:meth:`~spslidar.detectors.gmapd.GMAPD.correct`).
    noise_totals : ndarray, shape (M,)
        Per block, the corrected counts' variance summed over the bins, for the matched
        filter's noise level (:meth:`~spslidar.detectors.gmapd.GMAPD.noise_totals`).
    """
    h = np.asarray(hist, dtype=np.float64)
    n = np.maximum(np.round(np.asarray(periods, dtype=np.float64)), 1).astype(np.int64)
    fixed = np.empty_like(h)
    noise = np.empty(h.shape[0])
    for value in np.unique(n):  # (blocks of one dwell together: usually all of them)
        same = np.flatnonzero(n == value)
        # (CORRECT_ROWS at a time: the inverse's working arrays peaked at 42 times the
        # histograms' memory, a review)
        for start in range(0, same.size, CORRECT_ROWS):
            rows = same[start : start + CORRECT_ROWS]
            fixed[rows] = detector.correct(h[rows], int(value))
            noise[rows] = detector.noise_totals(h[rows], h[rows].sum(axis=1), int(value),
                                                corrected=fixed[rows])
    return fixed, noise


def _check_recordable(counts: np.ndarray, periods: np.ndarray, period_s: float, dead: float,
                      channel: Any, names: Any = None) -> None:
    """Refuse (one line) a dead time no block's counts could have been recorded through: a
    non-paralysable detector records at most one detection per dead time, ``T / D + 1`` over
    a block of ``T`` seconds (the Coates inverse of such counts has no solution, and its
    sub-binned refinement ran for many minutes on a linear counter's file)."""
    span = periods * period_s
    over = counts > span / dead + 1.0
    if not over.any():
        return
    k = int(np.argmax(counts * dead / span))
    merged = "" if channel is not None else ", or several channels are merged (--channel)"
    raise ConfigError(
        f"--dead-time {dead:g}: the block of pattern "
        f"{k if names is None else int(np.asarray(names)[k])} holds {counts[k]:.0f} detections in "
        f"{span[k]:.4g} s, {counts[k] * dead / span[k]:.3g} per dead time, where a detector "
        f"with that dead time records at most one: the dead time is too long for this "
        f"file{merged}")


#: gaps shorter than this share of a dead time given are not counted against it (the TDC's
#: bins and jitter)
GAP_TOLERANCE = 0.97
#: a dead time given is refused where more than this share of a channel's detections follow
#: the one before by less
GAP_SHARE = 0.01
#: a channel whose shortest gap a detector without a dead time would have undercut this many
#: times is read as showing its dead time
GAP_EVIDENCE = 20.0
def _read_channels(gaps: dict) -> list[int]:
    """The channels read that hold a share of the photons (another detector each)."""
    from .blocks import channels_holding

    return sorted(channels_holding({c: g["n"] for c, g in gaps.items()}))


def _check_gaps(gaps: dict, dead: float) -> None:
    """Refuse (one line) a dead time the file's detections contradict: a non-paralysable
    detector lets no two detections on its channel come closer than its dead time (an
    outside audit of 2026-11-30: 75 ns given for a 50 ns detector made a 0.21 m map 1.58 m,
    and 50 ns given for an ideal detector 0.38 -> 1.75 m, without a word); or one given for
    photons of several detectors merged, which one detector's correction does not model."""
    from ..io.ptu_blocks import GAP_EDGES_S

    used = _read_channels(gaps)
    if len(used) > 1:
        raise ConfigError(f"--dead-time corrects one detector's pile-up, and the photons of "
                          f"channels {', '.join(map(str, used))} are read together: read one "
                          f"--channel at a time")
    for c in used:
        g = gaps[c]
        # (the bins wholly below 97 % of the dead time: edges 0.8-1.6 % apart)
        below = int(g["counts"][: np.searchsorted(GAP_EDGES_S, GAP_TOLERANCE * dead,
                                                  side="right")].sum())
        if below > GAP_SHARE * g["n"]:
            raise ConfigError(
                f"--dead-time {dead:g}: {100 * below / g['n']:.3g} % of the detections on "
                f"channel {c} follow the one before by less (the shortest gap is "
                f"{g['shortest_s'] * 1e9:.4g} ns), which a detector with that dead time cannot "
                f"record: its dead time is at most that (or 0: it has none)")


def apparent_dead_time(gaps: dict, span_s: float) -> float | None:
    """A channel's shortest gap between detections where the data show it is a dead time: a
    detector without one, at the channel's rate, would have made at least
    :data:`GAP_EVIDENCE` shorter gaps (``n (1 - exp(-r G))`` of ``n`` Poisson gaps at rate
    ``r``); ``None`` otherwise, or for several channels read together."""
    used = _read_channels(gaps)
    if len(used) != 1 or not span_s > 0:
        return None
    g = gaps[used[0]]
    shortest, n = float(g["shortest_s"]), int(g["n"])
    expected = n * -np.expm1(-n / span_s * shortest)
    return shortest if shortest > 0 and expected >= GAP_EVIDENCE else None


def pileup_report(counts: np.ndarray, periods: np.ndarray, period_s: float, detector,
                  channel: Any = None, gaps: dict | None = None, names: Any = None
                  ) -> tuple[dict[str, Any], list[str]]:
    """What ``metrics.json``'s ``detector`` says of a measured acquisition's count rate and
    dead time, and the warnings to give.

    Without a dead time given (``detector`` ``None``) a warning says what the longer
    :data:`TYPICAL_DEAD_TIMES_S`, or the longer dead time the detections show
    (:func:`apparent_dead_time`), would lose at this rate where that is at least
    :data:`LOSS_TO_WARN` of the photons and the rate is one a single detector can count
    (below :data:`MAX_DETECTOR_RATE_HZ`): the non-paralysable loss is ``r D`` of the photons
    at a detected rate ``r``; and it names the dead time the detections show. With one, the
    GMAPD's own report (detections and incident photons per dead time) and its word on
    saturation, after the file's gaps between detections (``gaps``, the reader's
    ``detection_gaps``) are checked against it. ``names``: each row's pattern number, for a
    refusal's words (default the row).
    """
    counts = np.asarray(counts, dtype=np.float64)
    dwell = float(np.maximum(np.asarray(periods, dtype=np.float64), 1).sum())
    rate = float(counts.sum()) / (dwell * period_s)
    gaps = gaps or {}
    seen = apparent_dead_time(gaps, dwell * period_s)
    if detector is None:
        out: dict[str, Any] = {"model": "measured", "count_rate_hz": rate,
                               "dead_time_s": None, "corrected": False,
                               "apparent_dead_time_s": seen}
        # the loss at the longer typical dead time, or at the one the detections show where
        # that is longer (an InGaAs detector's microseconds: 2 us at 0.32 M photons/s loses
        # 65 %, which went unsaid because 100 ns would lose 3 %, and the reflectivity came out
        # a third of the corrected one; found 2026-11-30)
        longest = max(TYPICAL_DEAD_TIMES_S[-1], seen or 0.0)
        if rate * longest < LOSS_TO_WARN or rate >= MAX_DETECTOR_RATE_HZ:
            return out, []
        per = rate * period_s
        where = f" on channel {channel}" if isinstance(channel, int | np.integer) else ""
        shares = "; ".join(f"{d * 1e9:g} ns: {rate * d * 100:.2g} %" if rate * d < 1 else
                           f"{d * 1e9:g} ns: more than it can record" for d in
                           TYPICAL_DEAD_TIMES_S)
        if seen is not None and seen > TYPICAL_DEAD_TIMES_S[-1]:
            shares += f"; the {seen * 1e9:.4g} ns its detections show: {rate * seen * 100:.2g} %"
        shown = ("" if seen is None else
                 f"; its detections are never closer than {seen * 1e9:.4g} ns, which a "
                 f"detector without a dead time would have undercut many times: that is its "
                 f"dead time, --dead-time {seen:.4g}")
        note = (f"the detector recorded {rate / 1e6:.3g} M photons/s{where} ({per:.3g} per "
                f"code period): a non-paralysable dead time loses this rate times the dead "
                f"time of the photons ({shares}; SPADs and TCSPC electronics go dead for "
                f"20-100 ns), the strongest returns most (pile-up), which flattens the "
                f"contrast between patterns that the reconstruction reads; give the "
                f"detector's --dead-time (and --afterpulse-prob, --afterpulse-delay) to "
                f"correct it, or --dead-time 0 if it has none{shown}")
        return out, [note]
    if detector.dead_time > 0:  # (a saturated inverse ran for many minutes: refused first)
        _check_gaps(gaps, float(detector.dead_time))
        _check_recordable(counts, np.maximum(np.asarray(periods, np.float64), 1), period_s,
                          float(detector.dead_time), channel, names)
    out = detector.report(rate * period_s, period_s)
    short = _short_note(float(detector.dead_time), seen)
    out.update({"model": "measured", "dead_time_s": float(detector.dead_time),
                "afterpulse_prob": float(detector.afterpulse_prob),
                "afterpulse_delay_s": float(detector.afterpulse_delay),
                "corrected": bool(detector.dead_time > 0 or detector.afterpulse_prob > 0),
                "apparent_dead_time_s": seen})
    notes = [n.replace("lower --signal and --noise (and raise --periods)",
                       "record with less light (the detector cannot count more)")
             for n in detector.notes_after(out)]
    return out, notes + ([short] if short else [])


def _short_note(dead: float, seen: float | None) -> str | None:
    """A warning where the dead time given is shorter than the one the detections show
    (:func:`apparent_dead_time`), by more than the gaps' tolerance: the correction then
    restores too few of the photons lost (a 2 us detector read with --dead-time 0 or 1e-6:
    reflectivity 4.6 / 2.9 times too low, 58-62 % of pixels within 3 cm against 82 %, without
    a word; an outside audit of stop 68). A longer one is refused (:func:`_check_gaps`)."""
    if seen is None or dead >= GAP_TOLERANCE * seen:
        return None
    given = "says the detector has none" if dead == 0 else f"is {dead * 1e9:.4g} ns"
    return (f"--dead-time {dead:g} {given}, but its detections are never closer than "
            f"{seen * 1e9:.4g} ns, which a detector with a shorter dead time would have "
            f"undercut many times: the correction restores too few of the photons lost; its "
            f"dead time is about --dead-time {seen:.4g}")


def apply_dead_time(hist: np.ndarray, counts: np.ndarray, periods: np.ndarray,
                    period_s: float, detector, channel: Any = None, gaps: dict | None = None,
                    names: Any = None
                    ) -> tuple[np.ndarray, np.ndarray | None, dict[str, Any], list[str]]:
    """A measured acquisition's blocks through its detector's dead time, as ``reconstruct``
    and ``calibrate`` take them: :func:`pileup_report` of the ``counts``, then, where a dead
    time or afterpulsing was given, each block's histogram corrected
    (:func:`correct_blocks`).

    Returns
    -------
    (histograms, noise_totals, report, notes)
        ``hist`` itself and ``None`` where nothing is corrected.
    """
    report, notes = pileup_report(counts, periods, period_s, detector, channel, gaps, names)
    if not report["corrected"]:
        return hist, None, report, notes
    fixed, noise = correct_blocks(hist, periods, detector)
    return fixed, noise, report, notes


def _dead_time_of(detector) -> float:
    return 0.0 if detector is None else float(detector.dead_time)


#: a scan's count rate this many times the calibration's (or a fraction of it) is said
RATE_RATIO = 10.0


def _number(value: Any) -> float | None:
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    return float(value) if ok and math.isfinite(value) else None


def rate_note(cal: dict[str, Any], rate: float) -> str | None:
    """A warning where a scan's count rate is :data:`RATE_RATIO` times its calibration's or
    less than a tenth of it: a detector's timing walks with its count rate (an outside audit
    of 2026-11-30: a 1-bin walk between a wall at 0.05 and a scan at 1 photon per period gave
    a median bias of +20.5 mm, with nothing said though both files know their rates)."""
    record = cal.get("detector")
    then = _number(record.get("count_rate_hz")) if isinstance(record, dict) else None
    if not then or not rate > 0 or 1.0 / RATE_RATIO < rate / then < RATE_RATIO:
        return None
    return (f"this acquisition's count rate ({rate / 1e6:.3g} M/s) is {rate / then:.3g} times "
            f"the calibration's ({then / 1e6:.3g} M/s): a detector's timing walks with its "
            f"count rate (tens of picoseconds, a bin or more, for a SPAD), which the "
            f"calibration's delay does not hold; calibrate at the rate you scan at")


def calibration_note(cal: dict[str, Any], detector) -> str | None:
    """A warning where a calibration's response was read with another dead-time correction
    than the reconstruction's (``None`` where they agree, or where the calibration predates
    the ``detector`` record): its response is then not the one these histograms show."""
    record = cal.get("detector")
    if not isinstance(record, dict) or "dead_time_s" not in record:
        return None
    then = record.get("dead_time_s")
    then = float(then) if isinstance(then, (int, float)) and not isinstance(then, bool) else 0.0
    now = _dead_time_of(detector)
    if math.isclose(then, now, rel_tol=1e-9, abs_tol=0.0):
        return None

    def said(d: float) -> str:
        return f"--dead-time {d:g} corrected" if d > 0 else "no dead time corrected"

    return (f"the calibration's response was read with {said(then)}, this reconstruction "
            f"has {said(now)}: give both the detector's same --dead-time")
