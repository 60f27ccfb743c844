"""What a measured file asks of ``reconstruct``, from one pass over it
(:func:`spslidar.io.scan_ptu`): the marker input and edge, the blocks against the patterns as
:mod:`.blocks` will read them, the bit rate and code lengths the TDC and sync fit, pile-up and
a dead time, and where the returns are (``spslidar inspect``).

Each sentence follows a rule ``reconstruct`` applies itself (the arming and end markers'
blocks by :func:`.blocks._short`, the sync period by the reader's half-bin tolerance, pile-up
by :mod:`.deadtime`'s 5 % rule, the returns by the automatic gate's
:func:`.gate.occupied_lags`), so that advice followed literally reads the file as
``reconstruct`` would have read it right (an outside audit of 2026-12-02 followed the first
version's advice into wrong maps on four layouts).
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["CODE_DOUBT", "CODE_SHARE_SIGMAS", "GATE_MARGIN_BINS", "PILE_UP_NO_JUDGE",
           "RETURN_SIGMAS", "TAIL_SHARE", "advice", "code_doubt_note",
           "count", "doubt_text", "explained_share", "header_refusal", "judge_code", "num",
           "occupied_delays", "pile_up_loss", "returns_in_file", "returns_text", "si",
           "unrelated_share"]

#: a delay holds a return where the whole acquisition's correlation rises this many
#: standard deviations above its median (:data:`.gate.AUTO_GATE_SIGMAS`'s rule, on the
#: photons of every block summed)
RETURN_SIGMAS = 5.0
#: the code is said not to be the one sent where the returns found through it leave more
#: than this share of the photons' variation unexplained that the same number of delays
#: would leave through a code unrelated to them (:func:`unrelated_share`): measured
#: 2026-12-03 on five simulated files (m-sequences of 127 and 1023 bits, a Gold and a random
#: code, an IRF, a GMAPD) at most 0.002 through the code sent and 1.19-3.6 through ten
#: others; 0.15 through the code sent for three weak returns through an IRF
CODE_DOUBT = 0.5
#: the share of the code's period after each of the strongest returns fitted as its tail
#: where the returns alone leave the code in doubt (:func:`_with_tails`)
TAIL_SHARE = 0.1
#: a detector that lost this share of its photons to pile-up distorts the code's bits past
#: any fit: the code is not judged then
PILE_UP_NO_JUDGE = 0.2
#: that share is judged only where the variation stands this many of its own standard
#: deviations (``sqrt(2 n)`` for ``n`` bits) above the Poisson noise
CODE_SHARE_SIGMAS = 5.0
#: bins of margin on each side of the delays that hold returns, in the range gate said
GATE_MARGIN_BINS = 3
#: a marker input reads as ending its patterns where at least this share of a block's
#: photons come before its first marker and at most :data:`END_AFTER` of those after its
#: last
END_BEFORE, END_AFTER = 0.5, 0.5
#: the share of the photons in TDC bins past the sync period from which they are said
PAST_SHARE = 1e-3
#: photons a channel needs before its rate is said
MIN_RATE_PHOTONS = 100
#: TDC bins and sync periods a header can give (outside them: no instrument's)
RESOLUTION_S = (1e-15, 1e-3)


def si(seconds: float) -> str:
    """A time with its unit (ps, ns, us, ms, s), 4 significant digits."""
    for unit, scale in (("s", 1.0), ("ms", 1e-3), ("us", 1e-6), ("ns", 1e-9), ("ps", 1e-12)):
        # (a value that rounds to 1000 of a unit is one of the next: "1000 ps", an audit)
        if abs(seconds) >= scale * (1 - 5e-5) or unit == "ps":
            return f"{seconds / scale:.4g} {unit}"
    return f"{seconds:g} s"  # pragma: no cover


def num(n: float) -> str:
    """A whole number with thin thousands separators, as the README writes counts."""
    return f"{int(n):,}".replace(",", " ")


def count(n: float, word: str, plural: str | None = None) -> str:
    """``n word(s)``, the number as :func:`num` writes it."""
    return f"{num(n)} {word if int(n) == 1 else plural or word + 's'}"


def header_refusal(scan: dict[str, Any]) -> list[str]:
    """The header's timing, where ``reconstruct`` refuses it: one sentence, or none."""
    h = scan["header"]
    lo, hi = RESOLUTION_S
    if scan["mode"] == "T3":
        res, period = h["resolution_s"], h["sync_period_s"]
        if not (isinstance(res, float) and lo <= res <= hi):
            return [f"the header gives no TDC bin a TDC has (MeasDesc_Resolution {res!r}): "
                    f"reconstruct refuses the file"]
        if not (isinstance(period, float) and lo <= period <= 1.0):
            return [f"the header gives no sync period (MeasDesc_GlobalResolution {period!r}): "
                    f"reconstruct refuses the file"]
    else:
        unit = h["time_unit_s"]
        if not (isinstance(unit, float) and lo <= unit <= hi):
            return [f"the header gives no time tag unit (MeasDesc_GlobalResolution {unit!r}): "
                    f"reconstruct refuses the file"]
    return []


def _bits(scan: dict[str, Any]) -> list[str]:
    """The bit rate and code lengths the TDC bin and the sync period fit."""
    from ..io.ptu_blocks import _fitting_codes

    h = scan["header"]
    if scan["mode"] == "T2":
        return [f"a T2 file's delays are counted in its time tags ({si(h['time_unit_s'])}): "
                f"give the code's --bit-rate with --allow-binning, which merges (or splits) "
                f"them into bits"]
    res, bpp = h["resolution_s"], h.get("bins_per_period")
    text = f"--bit-rate {1 / res:.6g} reads one TDC bin per code bit"
    if bpp:
        text += f"; {_fitting_codes(bpp, res, 0.5)}"
        div = h.get("sync_divider")
        if (isinstance(div, int) and not isinstance(div, bool) and div > 1
                and abs(bpp - div * round(bpp / div)) <= 0.5):  # (the reader's tolerance)
            text += (f"; or, as the header's sync divider says, each sync spans {div} code "
                     f"periods of {round(bpp / div)} bits")
    out = [text + "; a code clocked k times slower than the TDC: its own --bit-rate with "
                  "--allow-binning"]
    counts = scan.get("dtime_counts")
    if bpp and counts is not None and counts.size > round(bpp):
        past = int(counts[round(bpp):].sum())  # (the reader drops bins >= the code's length)
        total = int(counts.sum())
        if past >= PAST_SHARE * total and past:  # (a stray photon or two is no divider)
            out.append(f"{count(past, 'photon')} ({100 * past / max(total, 1):.3g} %) "
                       f"{'lies' if past == 1 else 'lie'} in TDC bins past the sync period's "
                       f"{bpp:.6g}: reconstruct leaves them out (a sync every few code "
                       f"periods that the header does not say? --sync-divider)")
    return out


def _edge(b: dict[str, Any]) -> str:
    """``"end"`` where an input's photons before its first marker are about a block's and
    under half as many come after its last (its marker ends each pattern), else
    ``"start"``."""
    ph = b["photons_per_block"]
    if ph is None or not ph["median"] > 0:
        return "start"
    before, after = b["photons_before_first"], b["photons_after_last"]
    # (about a block's photons before the first marker and fewer after the last: the light
    # after an end-of-acquisition marker is no pattern's, an audit)
    if before >= END_BEFORE * ph["median"] and after <= END_AFTER * before:
        return "end"
    return "start"


def _markers(scan: dict[str, Any], patterns: bool = False) -> list[str]:
    """Which ``--marker`` input, at which edge (``patterns``: the blocks are set against
    them in a sentence of their own)."""
    if not scan["markers"]:
        return ["no marker records: reconstruct splits the photons into patterns at the "
                "DMD's markers (its trigger output on a marker input)"]
    most = max(scan["markers"].values())
    top = [k for k, n in scan["markers"].items() if n == most]
    blocks = scan["blocks"]
    if len(top) == 1:
        k = top[0]
        if _edge(blocks[k]) == "end":
            b = blocks[k]
            return [f"--marker {k} --marker-edge end: {count(most, 'marker')}, with "
                    f"{count(b['photons_before_first'], 'photon')} before the first (about a "
                    f"block's) and {num(b['photons_after_last'])} after the last: its marker ends "
                    f"each pattern"]
        return [f"--marker {k}: {count(most, 'marker')}" + ("" if patterns else
                ", as many patterns (or the sequence --repeats times)")]
    # inputs of as many markers: one starts each pattern, another ends it; the start's
    # markers come first (an audit: numbered the other way round, both readings were wrong)
    first = sorted(top, key=lambda k: blocks[k]["first_s"])
    s, e = first[0], first[-1]
    return [f"inputs {', '.join(map(str, top))} hold {count(most, 'marker')} each, input "
            f"{s}'s first: one starts each pattern and another ends it: --marker {s}, or "
            f"--marker {e} --marker-edge end"]


def _extra_block(d: np.ndarray, c: np.ndarray, m: int) -> str:
    """Which of ``m + 1`` or ``m + 2`` blocks ``reconstruct`` leaves out, by its own rule
    (:func:`.blocks.extra_block`; :func:`.blocks._short` for both ends of ``m + 2``)."""
    from .blocks import extra_block

    which, first, last, typ_d, typ_c = extra_block(d, c)
    ends = (f"first block {count(round(d[0]), 'code period')} with "
            f"{count(c[0], 'photon')}, last {count(round(d[-1]), 'code period')} with "
            f"{count(c[-1], 'photon')}, a pattern's {count(round(typ_d), 'code period')} "
            f"with {count(typ_c, 'photon')}")
    if d.size == m + 2:
        if first and last:
            return f"and an arming and an end marker's block ({ends}): both left out"
        return (f"and two more, not both short of a pattern's or empty ({ends}): reconstruct "
                f"refuses the file with these patterns")
    if first and last:
        return (f"and both ends are short or empty ({ends}): the {which}, of the lower "
                f"photon rate, is left out")
    if first:
        return f"and the first block, short or empty, is an arming marker's ({ends}): left out"
    if last:
        return f"and the last block is an end marker's ({ends}): left out"
    rates = c / np.maximum(d, 1.0)
    lowest = float(np.min(rates[1:-1])) if d.size > 2 else np.inf
    if rates[0] < lowest:  # (light before the sequence under an arming marker, an audit)
        return (f"and neither end is short or empty ({ends}); the first block's photon rate, "
                f"{rates[0] / max(typ_c / max(typ_d, 1.0), 1e-300):.2g} of a pattern's, is "
                f"the lowest of all: an arming marker's block with light before the "
                f"sequence? reconstruct keeps it as pattern 0 and leaves out the last block "
                f"(no option leaves out the first: record the arming marker just before the "
                f"sequence, or without light)")
    return (f"and neither end is short or empty ({ends}): reconstruct leaves out the last, "
            f"and asks whether a row is missing from --patterns")


def _against(k: int, blocks: int, m: int, arrays: tuple | None) -> tuple[int, str]:
    """How well ``blocks`` blocks on input ``k`` fit ``m`` patterns (0 best) and in words."""
    head = (f"--patterns holds {count(m, 'pattern')} and --marker {k} cuts "
            f"{count(blocks, 'block')}")
    if blocks == m:
        return 0, head + ": one per pattern"
    if blocks < m:
        return 3, (head + ": fewer blocks than patterns (another --marker input, markers "
                          "missed, or an acquisition cut short)")
    if blocks % m == 0:
        return 1, head + f": --repeats {blocks // m}"
    if blocks - m in (1, 2) and arrays is None:  # (read at its end edge: reconstruct's own)
        return 1, (f"{head}: one per pattern and {count(blocks - m, 'block')} more, which "
                   f"reconstruct leaves out and says")
    if blocks - m in (1, 2):
        return 1, f"{head}: one per pattern, {_extra_block(*arrays, m)}"
    for extra in (1, 2):
        if (blocks - extra) % m == 0:
            return 2, (head + f": --repeats {(blocks - extra) // m}, and "
                              f"{count(extra, 'block')} more (an arming or end marker's)")
    if arrays is not None:
        from .blocks import BOUNCE_MIN_DWELL, BOUNCE_PERIODS

        d = arrays[0]
        typ = float(np.median(d))
        slivers = int(np.count_nonzero(d[1:-1] < typ / 3))
        if slivers and any((blocks - slivers - e) % m == 0 for e in (0, 1, 2)):
            return 2, (head + f", {count(slivers, 'block')} of them under a third of a "
                              f"pattern's {count(round(typ), 'code period')} (markers that "
                              f"bounced?): reconstruct merges a bounce of up to "
                              f"{BOUNCE_PERIODS} code periods where patterns last "
                              f"{BOUNCE_MIN_DWELL} or more"
                              + ("" if typ >= BOUNCE_MIN_DWELL else
                                 ", which these do not: longer dwells or a debounced "
                                 "trigger"))
    return 2, (head + ": no whole number of sequences (a DMD looping its sequence while the "
                      "recording started: --first-pattern auto; or a marker missed or "
                      "added)")


def _patterns(scan: dict[str, Any], m: int) -> list[str]:
    """The blocks of the busiest input against ``m`` patterns, and another input's where it
    fits them better."""
    period = scan.get("sync_period_s")

    def arrays(k: int) -> tuple | None:  # (dwells in code periods, as .blocks reads them)
        a = scan["block_arrays"].get(k)
        return None if a is None or not period else (a[0] / period, a[1])

    blocks = scan["blocks"]
    verdicts = {k: _against(k, n, m, arrays(k) if _edge(blocks[k]) == "start" else None)
                for k, n in scan["markers"].items()}
    most = max(scan["markers"].values())
    # (of inputs with as many markers, the one that starts the patterns: an audit)
    top = min((k for k, n in scan["markers"].items() if n == most),
              key=lambda k: blocks[k]["first_s"])
    out = [verdicts[top][1]]
    better = [k for k in verdicts if verdicts[k][0] < verdicts[top][0]]
    if better:
        k = min(better, key=lambda k: verdicts[k][0])
        out.append(f"input {k} fits the patterns better: {verdicts[k][1]}")
    return out


def _rates(scan: dict[str, Any], sync_channel: int | None) -> list[str]:
    """Pile-up and a dead time, per detector channel."""
    from .deadtime import (
        GAP_EVIDENCE,
        LOSS_TO_WARN,
        MAX_DETECTOR_RATE_HZ,
        TYPICAL_DEAD_TIMES_S,
        apparent_dead_time,
    )

    out, span = [], scan["span_s"]
    lo, hi = min(TYPICAL_DEAD_TIMES_S), max(TYPICAL_DEAD_TIMES_S)
    for c, n in scan["photons"].items():
        if c == sync_channel or not span > 0 or n < MIN_RATE_PHOTONS:
            continue  # (3 photons in 25 ns read as 1.2e8 per second: a rate needs counts)
        r = n / span
        g = scan["gaps"].get(c)  # (the dead time reconstruct reads from the same gaps)
        seen = apparent_dead_time({c: g}, span) if g else None
        if r >= MAX_DETECTOR_RATE_HZ:
            out.append(f"channel {c} counts {r:.3g} photons/s, more than a single-photon "
                       f"detector can: a simulated linear counter, or the photons of several "
                       f"detectors on one channel")
        elif seen is not None:
            # (the share a non-paralysable detector lost of what arrived is r D, r the rate
            # it recorded: load / (1 + load) on the recorded rate was wrong, an audit)
            lost = r * seen
            out.append(f"channel {c}: no two detections closer than {si(seen)}, where a "
                       f"detector without a dead time would have given more than "
                       f"{GAP_EVIDENCE:g} closer gaps: its dead time"
                       + (f", at which it lost {100 * lost:.2g} % of the photons to pile-up: "
                          f"--dead-time {seen:.3g} (one --channel at a time)"
                          if lost >= LOSS_TO_WARN else " (pile-up under 5 %)"))
        elif r * hi >= 1:
            out.append(f"channel {c} counts {r:.3g} photons/s, more than a detector with a "
                       f"{si(hi)} dead time records: its dead time, if it has one, is under "
                       f"{si(1 / r)}")
        elif r * hi >= LOSS_TO_WARN:
            out.append(f"channel {c} counts {r:.3g} photons/s: a detector with a dead time of "
                       f"{si(lo)} to {si(hi)} lost {100 * r * lo:.2g} to {100 * r * hi:.2g} % "
                       f"of the photons to pile-up: give its --dead-time")
    detectors = [c for c in scan["photons"] if c != sync_channel]
    if len(detectors) > 1:
        out.append(f"{len(detectors)} detector channels hold photons: all are read together "
                   f"unless --channel picks one" + _delays(scan))
    return out


def _delays(scan: dict[str, Any]) -> str:
    """The channels' delays against the busiest one's, as ``reconstruct`` reads them
    (:func:`.skew.channel_delays` on each channel's photons over the TDC bins), in words."""
    from .skew import SKEW_BINS, channel_delays

    per = scan.get("channel_dtime_counts")
    res = scan["header"]["resolution_s"]
    if not per or len(per) < 2:
        return ("; --align-channels moves them onto one where cables of different lengths "
                "delay them")
    n = max(h.size for h in per.values())
    hists = {c: np.pad(h, (0, n - h.size)) for c, h in per.items()}
    delays = channel_delays(hists)
    late = {c: d for c, d in delays.items() if abs(d) >= SKEW_BINS}
    if not late:
        return ("; their photons arrive together (no delay of "
                f"{SKEW_BINS:g} TDC bins or more between them)")
    ref = next(c for c, d in delays.items() if d == 0.0)
    said = ", ".join(f"channel {c} {d:+.3g} bins ({d * res * 1e9:+.3g} ns)"
                     for c, d in late.items())
    return (f"; against channel {ref}'s photons, {said}: cables of different lengths? "
            f"--align-channels moves each onto channel {ref}")


def advice(scan: dict[str, Any], n_patterns: int | None = None) -> list[str]:
    """What ``reconstruct`` needs that a :func:`~spslidar.io.scan_ptu` result says, one
    sentence each; with ``n_patterns`` (the rows of ``--patterns``), the blocks set against
    them."""
    bad = header_refusal(scan)
    if bad:
        return bad
    out: list[str] = []
    sync_channel = None
    if scan["mode"] == "T2" and (scan["sync_records"] or 0) < 2:
        per = scan["periodic_channel"]
        out.append("no sync records: reconstruct reads a T2 file from the code's sync, "
                   "recorded on the sync input"
                   + (f"; channel {per['channel']}'s events come every {si(per['period_s'])}, "
                      f"as a sync's would: --sync-channel {per['channel']}" if per else ""))
        sync_channel = per["channel"] if per else None
    out += _bits(scan)
    if not any(c != sync_channel for c in scan["photons"]):
        return out + ["no detector photons: reconstruct refuses the file"]
    out += _markers(scan, n_patterns is not None)
    if n_patterns is not None and scan["markers"]:
        out += _patterns(scan, int(n_patterns))
    out += _rates(scan, sync_channel)
    return out


def returns_in_file(scan: dict[str, Any], code: np.ndarray, bit_rate: float
                    ) -> dict[str, Any]:
    """Where a T3 file's returns are, before any pattern is read: the photons of every block
    and channel summed per code bit, correlated with the code's replica (eq. 5-6), and the
    delays that rise :data:`RETURN_SIGMAS` standard deviations (their Poisson noise,
    :func:`~spslidar.correlate.correlation_noise_sigma`) above the median, a code's
    sidelobes cleaned as the automatic range gate cleans them
    (:func:`~spslidar.pipeline.gate.occupied_lags`).

    Returns
    -------
    dict
        ``ok`` False with ``why`` (a sentence) where the file cannot be read with this code
        and bit rate (T2, a TDC bin that is no whole fraction of the bit, a sync period the
        code does not fill, more than half the delays standing out); else ``peaks`` (up to
        five runs of delays that hold returns, strongest first: ``lag`` (bits), ``range_m``
        (c lag / 2 bit_rate: the delay the photons show, cables and electronics included),
        ``sigmas``), ``gate_m`` (a range gate over every run, :data:`GATE_MARGIN_BINS` bits
        beyond each end; None where no delay stands out), ``unambiguous_m`` and ``replica``.
        Where the variation over the code's bits is enough to judge, ``code_share``
        (:func:`explained_share`), ``occupied_share`` (of the delays), ``unrelated_share``
        (:func:`unrelated_share` of it) and ``code_doubt``: True where the returns leave more than
        :data:`CODE_DOUBT` of what an unrelated code's would leave unexplained, a code that is
        not the one sent (a strong return correlated with another code of the same length
        stands out at many delays, an audit); ``code_share`` None where the counts do not vary
        enough to tell.
    """
    from ..constants import SPEED_OF_LIGHT

    h = scan["header"]
    counts = scan.get("dtime_counts")
    refused = header_refusal(scan)
    if refused:
        return {"ok": False, "why": refused[0]}
    if counts is None:
        return {"ok": False, "why": "a T2 file without sync records holds no delays (its "
                                    "sync on a detector input: reconstruct --sync-channel)"}
    n = int(np.size(code))
    if scan["mode"] == "T3":
        res, period = float(h["resolution_s"]), float(h["sync_period_s"])
    else:  # (a T2 file's delays are counted in its time tags since each sync record)
        res, period = float(h["time_unit_s"]), float(scan["sync_period_s"])
    width = 1.0 / bit_rate
    k = width / res
    if not (round(k) >= 1 and abs(k - round(k)) <= 1e-3 * k):
        return {"ok": False, "why": f"the TDC bin ({si(res)}) is no whole fraction of the "
                                    f"code's bit ({si(width)}): reconstruct splits it "
                                    f"between bits (--allow-binning); inspect does not"}
    k = int(round(k))
    div = h.get("sync_divider")
    declared = div if isinstance(div, int) and not isinstance(div, bool) and div > 1 else 1
    fold = max(1, round(period / (n * width)))
    if abs(period - fold * n * width) > 0.5 * width:
        return {"ok": False, "why": f"the sync period ({si(period)}) is no whole number of "
                                    f"{n}-bit periods at {bit_rate:.6g} Hz: reconstruct says "
                                    f"what fits"}
    bits = np.bincount((np.arange(counts.size) // k) % n, weights=counts, minlength=n)[:n]
    if not bits.sum() > 0:
        return {"ok": False, "why": "the file holds no photons"}
    kind, corr, sigma, hit = occupied_delays(bits, code)
    metres = SPEED_OF_LIGHT * width / 2
    out: dict[str, Any] = {"ok": True, "unambiguous_m": n * metres, "replica": kind,
                           "peaks": [], "gate_m": None,
                           # (a sync every few code periods the header does not say: the
                           # --sync-divider reconstruct needs, an audit)
                           "sync_divider": fold if fold > 1 and fold != declared else None}
    if not hit.any():
        return out
    if hit.mean() > 0.5:  # (no scene fills half the code's period: not this code's photons)
        return {"ok": False, "why": f"{100 * hit.mean():.0f} % of the delays stand above the "
                                    f"background: the photons do not follow this code (the "
                                    f"wrong code or --bit-rate, or no PSST acquisition)"}
    runs = _runs(hit)
    base = float(np.median(corr))
    peaks = []
    for r in runs:
        top = max(r, key=lambda i: corr[i])
        peaks.append({"lag": top, "range_m": top * metres,
                      "sigmas": float((corr[top] - base) / sigma[0])})
    peaks.sort(key=lambda p: -p["sigmas"])
    out["peaks"] = peaks[:5]
    if pile_up_loss(scan) < PILE_UP_NO_JUDGE:  # (pile-up distorts the code's bits: the
        # code sent read 0.38-0.54 of them at 95 % lost, a review of 2026-12-03)
        out.update(judge_code(bits, code, hit, corr))
    else:
        out["code_share"] = None
    first = runs[0][0]
    span = (runs[-1][-1] - first) % n
    lo = first - GATE_MARGIN_BINS
    lo += n if lo < 0 else 0  # (a gate in metres from 0: the same delays a period on)
    out["gate_m"] = (lo * metres, (lo + span + 2 * GATE_MARGIN_BINS) * metres)
    return out


def occupied_delays(bits: np.ndarray, code: np.ndarray
                    ) -> tuple[str, np.ndarray, np.ndarray, np.ndarray]:
    """The photons of a whole acquisition summed per code bit, correlated with the code's
    replica (eq. 5-6), and the delays that rise
    :data:`~spslidar.pipeline.file_advice.RETURN_SIGMAS` standard deviations above the
    median, a code's sidelobes cleaned (:func:`~spslidar.pipeline.gate.occupied_lags`):
    ``(replica kind, correlation, its noise sigma, occupied mask)``."""
    from ..correlate import auto_replica, correlation_noise_sigma, make_replica
    from .gate import code_sidelobes, occupied_lags

    bits = np.asarray(bits, dtype=np.float64)
    n = bits.size
    kind = auto_replica(code)
    replica = make_replica(code, kind)
    corr = np.fft.irfft(np.fft.rfft(bits) * np.conj(np.fft.rfft(replica)), n=n)
    sigma = correlation_noise_sigma(bits[None, :], replica)
    hit = occupied_lags(corr[None, :], sigma, RETURN_SIGMAS, 0, np.arange(n),
                        code_sidelobes(code, replica))
    return kind, corr, sigma, hit


def _doubt(share: float, chance: float) -> bool:
    """The returns leave more than :data:`CODE_DOUBT` of what an unrelated code's would
    leave unexplained: their share lies nearer that code's than the code sent's 1."""
    return bool((1 - share) > CODE_DOUBT * (1 - chance))


def _runs(hit: np.ndarray) -> list[list[int]]:
    """The runs of occupied delays around the period, in order from the first after the
    longest gap (the scene's arc: read from the array's end, a gate spanned the empty part,
    an audit), a run across the period's end kept whole; none where nothing is occupied."""
    n = hit.size
    occ = np.flatnonzero(hit)
    if not occ.size:
        return []
    gaps = np.diff(np.append(occ, occ[0] + n))  # (from each occupied delay to the next)
    start = int(occ[(int(np.argmax(gaps)) + 1) % occ.size])
    runs, cur = [], []
    for i in (start + np.arange(n)) % n:
        if hit[i]:
            cur.append(int(i))
        elif cur:
            runs.append(cur)
            cur = []
    if cur:
        runs.append(cur)
    return runs


def _with_tails(hit: np.ndarray, corr: np.ndarray) -> np.ndarray:
    """``hit`` with the :data:`TAIL_SHARE` of the period after each of the five strongest
    runs of occupied delays (:func:`_runs`, by their ``corr`` peak) added: a response's tail,
    below the threshold delay by delay (an IRF's diffusion tail of 5-8 ns at 10 GHz through
    a 1023-bit code explained 0.47 of the counts at its occupied delays alone, a review of
    2026-12-03)."""
    n = hit.size
    runs = sorted(_runs(hit), key=lambda r: -float(corr[r].max()))
    out = hit.copy()
    reach = max(1, int(TAIL_SHARE * n))
    for r in runs[:5]:
        out[(r[-1] + 1 + np.arange(reach)) % n] = True
    return out


def judge_code(bits: np.ndarray, code: np.ndarray, hit: np.ndarray, corr: np.ndarray
               ) -> dict[str, Any]:
    """Whether the photons follow ``code``, from its occupied delays ``hit`` and correlation
    ``corr`` (:func:`occupied_delays`): ``code_share`` (:func:`explained_share`; None
    where the counts do not vary enough to tell) and, where it is known, ``occupied_share``,
    ``unrelated_share`` and ``code_doubt`` (:func:`_doubt`: the returns' share lies nearer
    an unrelated code's than the code sent's), False where the returns with a tail after
    each of the strongest (:func:`_with_tails`) pass the same test."""
    share = explained_share(bits, code, hit) if hit.any() else None
    out: dict[str, Any] = {"code_share": share}
    if share is not None:
        chance = unrelated_share(float(hit.mean()))
        doubt = _doubt(share, chance)
        if doubt:  # (the tails' delays are chosen by place, not height: the chance share
            # of as many delays chosen by height, the larger, is the bar, as above)
            tailed = _with_tails(hit, corr)
            wide = explained_share(bits, code, tailed)
            doubt = wide is not None and _doubt(wide, unrelated_share(float(tailed.mean())))
        out.update(occupied_share=float(hit.mean()), unrelated_share=chance,
                   code_doubt=doubt)
    return out


def pile_up_loss(scan: dict[str, Any]) -> float:
    """The largest share of its photons a channel of ``scan`` lost to its dead time, as
    :func:`_rates` says it (its rate times the dead time its detections show; 0 where none
    shows)."""
    from .deadtime import apparent_dead_time

    span, lost = scan.get("span_s") or 0.0, 0.0
    for c, n in scan.get("photons", {}).items():
        g = scan.get("gaps", {}).get(c)
        seen = apparent_dead_time({c: g}, span) if g and span > 0 else None
        if seen is not None and n >= MIN_RATE_PHOTONS:
            lost = max(lost, n / span * seen)
    return lost


def doubt_text(said: dict[str, Any], what: str = "this code") -> str:
    """The words of a code in doubt (:func:`judge_code`'s ``said``)."""
    return (f"the photons do not follow {what}: the returns it shows, at "
            f"{100 * said['occupied_share']:.2g} % of its delays, explain "
            f"{100 * said['code_share']:.2g} % of how the counts vary over its bits, nearer "
            f"the {100 * said['unrelated_share']:.2g} % that as many delays of a code "
            f"unrelated to the photons explain than the nearly 100 % of the code sent: check "
            f"--code (its family, length, --code-index, or a file's bit order) and --bit-rate "
            f"(a response far wider than a bit, or heavy pile-up, can do this too)")


def code_doubt_note(bits: np.ndarray, code: np.ndarray, lost: float = 0.0) -> str | None:
    """``reconstruct``'s warning where the photons summed over every pattern, per code bit,
    do not follow ``code`` (:func:`judge_code`); None where they do or cannot be judged (no
    delay stands out, or more than half of them do: the noise verdict speaks then; or the
    detector ``lost`` :data:`PILE_UP_NO_JUDGE` of its photons to pile-up or more)."""
    bits = np.asarray(bits, dtype=np.float64)
    if (bits.ndim != 1 or bits.size != np.size(code) or not bits.sum() > 0
            or lost >= PILE_UP_NO_JUDGE):
        return None
    _, corr, _, hit = occupied_delays(bits, code)
    if not hit.any() or hit.mean() > 0.5:
        return None
    said = judge_code(bits, code, hit, corr)
    if not said.get("code_doubt"):
        return None
    return doubt_text(said, "--code") + "; the depth map is read through it"


def explained_share(bits: np.ndarray, code: np.ndarray, occupied: np.ndarray
                    ) -> float | None:
    """How much of the photons' variation over the code's bits the returns at the
    ``occupied`` delays explain, through this code: ``1 - E_1 / E_0``, where ``E_0`` is the
    counts' chi-square about their mean and ``E_1`` about the best fit of a background plus
    the code delayed to each occupied delay (``sum_l a_l s(i - l)``, eq. 5's photon rate
    summed over the patterns), each less its degrees of freedom; both weighed by the fit's
    counts, their Poisson variance. None where ``E_0`` stands less than
    :data:`CODE_SHARE_SIGMAS` of its own standard deviations (``sqrt(2 n)``) above the
    noise: no variation to explain.

    The code sent explains nearly all of it (a strong return's photons follow the code's
    bits wherever it is delayed), another code little: a code correlated with photons it
    did not modulate gives peaks at like strengths scattered over its period (an audit of
    2026-12-03: a random 1023-bit code read one box as five "returns" at 86-103 standard
    deviations where the code sent reads one at 1180), each explaining a few per cent.
    Solved by SciPy's LSQR over the occupied delays' amplitudes, the code's delays applied
    by FFT (no ``n x n`` matrix for a long code); the occupied delays of one scene are few.
    """
    from scipy.sparse.linalg import LinearOperator, lsqr

    from ..codes.sequences import code_bits

    b = np.asarray(bits, dtype=np.float64)
    n = b.size
    lags = np.flatnonzero(occupied)
    mean = float(b.mean())
    if not (n > lags.size + 1 and mean > 0):
        return None
    spec = np.fft.rfft(code_bits(code).astype(np.float64))

    def forward(x: np.ndarray) -> np.ndarray:
        a = np.zeros(n)
        a[lags] = x[1:]
        return x[0] + np.fft.irfft(spec * np.fft.rfft(a), n=n)

    def adjoint(y: np.ndarray) -> np.ndarray:
        c = np.fft.irfft(np.conj(spec) * np.fft.rfft(y), n=n)
        return np.concatenate([[y.sum()], c[lags]])

    op = LinearOperator((n, lags.size + 1), matvec=forward, rmatvec=adjoint,
                        dtype=np.float64)
    fit = forward(lsqr(op, b, atol=1e-12, btol=1e-12, iter_lim=500)[0])
    var = np.maximum(fit, 1.0)  # (Poisson: a bit's variance is its rate)
    e0 = float(np.sum((b - mean) ** 2 / var)) - (n - 1)
    if not e0 > CODE_SHARE_SIGMAS * np.sqrt(2.0 * n):
        return None
    e1 = float(np.sum((b - fit) ** 2 / var)) - (n - lags.size - 1)
    return float(min(1.0, max(0.0, 1.0 - e1 / e0)))


def unrelated_share(q: float) -> float:
    """The share of the photons' variation that the ``q n`` delays standing highest explain
    through a code unrelated to the photons: its correlation with them spreads a return over
    every delay like Gaussian noise, and the delays above the ``1 - q`` quantile of ``|Z|``
    hold ``E[Z^2; |Z| > z] = q + 2 z phi(z)`` of ``E[Z^2] = 1``, ``z`` that quantile."""
    from scipy.stats import norm

    if not q > 0:
        return 0.0
    z = float(norm.isf(min(q, 1.0) / 2))
    return float(min(1.0, q + 2 * z * norm.pdf(z)))


def returns_text(found: dict[str, Any]) -> list[str]:
    """:func:`returns_in_file`'s result in words."""
    if not found["ok"]:
        return [f"no range said: {found['why']}"]
    if not found["peaks"]:
        return [f"no delay holds a return {RETURN_SIGMAS:g} standard deviations above the "
                f"background, over the whole {found['unambiguous_m']:.4g} m of the code's "
                f"period: a scene too dark, the wrong code, or the wrong --bit-rate"]
    doubt = []
    if found.get("code_doubt"):  # (said first: the returns below are then no scene's)
        doubt = [doubt_text(found) + "; the returns and range gate below are then not the "
                                     "scene's"]
    peaks = "; ".join(f"{p['range_m']:.4g} m ({p['sigmas']:.3g} sigma)"
                      for p in found["peaks"])
    lo, hi = found["gate_m"]
    u = found["unambiguous_m"]
    out = doubt + [f"returns (the photons of every block, correlated with the code): {peaks}; "
           f"--range-gate {lo:.4g} {hi:.4g} holds them: the delays the photons show, cables "
           f"included (reconstruct's --calibration takes the gate in true metres: less "
           f"the calibrated delay's range, c x delay / 2), modulo the "
           f"code's {u:.4g} m: add the whole number of {u:.4g} m your scene's distance needs "
           f"to both ends (one: --range-gate {lo + u:.4g} {hi + u:.4g})"]
    if found.get("sync_divider"):
        out.append(f"the sync period is {found['sync_divider']} periods of this code, which "
                   f"the header does not say: --sync-divider {found['sync_divider']}")
    return out
