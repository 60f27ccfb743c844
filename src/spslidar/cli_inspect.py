"""``spslidar inspect``: what a PTU file holds, and the ``reconstruct`` options it asks for,
before any is guessed (:func:`spslidar.io.ptu_scan.scan_ptu`); the sub-command's parser and
its command, as :mod:`spslidar.cli` registers them."""

from __future__ import annotations

import argparse
import json
import math
from typing import Any

import numpy as np

__all__ = ["add_inspect_parser", "cmd_inspect", "describe", "returns_in_file",
           "suggestions"]


def add_inspect_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``inspect`` sub-command to ``add_subparsers()``.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The sub-command registry of the ``spslidar`` parser.

    Returns
    -------
    argparse.ArgumentParser
        The new sub-parser; :func:`cmd_inspect` runs it.
    """
    p = subparsers.add_parser(
        "inspect", help="say what a PTU file holds and which reconstruct options it asks for",
        description="Read a PicoQuant PTU file (T3, or T2) once and say what it holds: its "
                    "header (hardware, TDC bin, sync period), the photons on each detector "
                    "channel (--channel), the markers on each marker input (--marker) and the "
                    "blocks they cut (length, photons), the count rate against pile-up, and "
                    "the options of 'spslidar reconstruct' that follow from them. Writes "
                    "nothing.")
    p.add_argument("ptu", nargs="+", metavar="FILE.ptu", help="PTU file(s)")
    p.add_argument("--patterns", metavar="PATTERNS",
                   help="the pattern file reconstruct will be given (any format it reads): "
                        "its number of patterns is set against the blocks the markers cut "
                        "(--repeats, an extra marker, a free-running DMD)")
    p.add_argument("--code", metavar="CODE|FAMILY",
                   help="the code's bits of one period, as reconstruct takes them (a file, "
                        "or a family's name with --code-length): with --bit-rate, the "
                        "photons of every block and channel are correlated with it and the "
                        "delays that hold returns are said, with a --range-gate around them")
    p.add_argument("--code-length", type=int, metavar="L",
                   help="bits per code period of a named family (as reconstruct)")
    p.add_argument("--code-index", type=int, metavar="I",
                   help="member of the named family (as reconstruct)")
    p.add_argument("--bit-rate", type=float, metavar="HZ",
                   help="the code's bits per second (with --code)")
    p.add_argument("--json", action="store_true",
                   help="print the counts as JSON (one object per file, in a list) instead "
                        "of sentences")
    return p


def _si(seconds: float) -> str:
    """A time with its unit (ps, ns, us, ms, s)."""
    for unit, scale in (("s", 1.0), ("ms", 1e-3), ("us", 1e-6), ("ns", 1e-9), ("ps", 1e-12)):
        if abs(seconds) >= scale or unit == "ps":
            return f"{seconds / scale:.4g} {unit}"
    return f"{seconds:g} s"  # pragma: no cover


def _n(value: float) -> str:
    """A count with thin thousands separators, as the README writes them."""
    return f"{int(value):,}".replace(",", " ")


def _blocks_text(k: int, b: dict[str, Any]) -> str:
    if "dwell_s" not in b:
        return f"--marker {k}: one marker, at {_si(b['first_s'])}"
    d, ph = b["dwell_s"], b["photons_per_block"]
    text = (f"--marker {k}: {_n(b['markers'])} markers, blocks of {_si(d['median'])} "
            f"({_si(d['min'])} to {_si(d['max'])}) holding {_n(ph['median'])} photons "
            f"(median; {_n(ph['min'])} to {_n(ph['max'])})")
    extra = []
    if b["empty_blocks"]:
        extra.append(f"{_n(b['empty_blocks'])} empty")
    if b["irregular_blocks"]:
        extra.append(f"{_n(b['irregular_blocks'])} over 1.5 times the median length or under "
                     f"its two thirds (a marker missed, or a bounce)")
    extra.append(f"{_n(b['photons_before_first'])} photons before the first marker, "
                 f"{_n(b['photons_after_last'])} after the last")
    return text + "; " + "; ".join(extra)


def describe(scan: dict[str, Any], name: str) -> list[str]:
    """The sentences ``spslidar inspect`` prints for one :func:`~spslidar.io.ptu_scan.scan_ptu`
    result."""
    h = scan["header"]
    # (a creation time ptufile could not read stays a number: left out)
    made = ", ".join(v for v in (h.get("hardware"), h.get("creator"), h.get("created"))
                     if isinstance(v, str) and v)
    lines = [f"{name}: {h['record_type']} records ({scan['mode']})"
             + (f"; {made}" if made else "")]
    if scan["mode"] == "T3":
        div = h.get("sync_divider")
        period = h["sync_period_s"] or 0.0
        lines.append(
            f"  TDC bin {_si(h['resolution_s'])}; sync period {_si(period)}"
            + (f" (sync divider {div})" if isinstance(div, int) and div > 1 else "")
            + (f", {h['bins_per_period']:.6g} TDC bins" if h.get("bins_per_period") else "")
            + (f"; photons in TDC bins up to {scan['dtime_max']}"
               if scan["dtime_max"] is not None else ""))
    else:
        sp = scan.get("sync_period_s")
        lines.append(f"  time tag unit {_si(h['time_unit_s'] or 0.0)}; {_n(scan['sync_records'])}"
                     f" sync records" + (f", every {_si(sp)}" if sp else ""))
    n_ph, n_mk = sum(scan["photons"].values()), sum(scan["markers"].values())
    lines.append(f"  {_n(scan['n_records'])} records over {_si(scan['span_s'])}: "
                 f"{_n(n_ph)} photons, {_n(n_mk)} marker records, "
                 f"{_n(scan['overflow_records'])} overflow records")
    span = scan["span_s"]
    if scan["photons"]:
        lines.append("  photons per --channel (from 0): " + ", ".join(
            f"{c}: {_n(n)}" + (f" ({n / span:.3g}/s)" if span > 0 else "")
            for c, n in scan["photons"].items()))
    else:
        lines.append("  no photons")
    if scan["markers"]:
        lines.append("  markers per --marker input: " + ", ".join(
            f"{k}: {_n(n)}" for k, n in scan["markers"].items()))
        lines += [f"  {_blocks_text(k, b)}" for k, b in scan["blocks"].items()]
    else:
        lines.append("  no marker records")
    return lines


def _dead_times(scan: dict[str, Any]) -> list[str]:
    """Channels whose shortest gap between detections shows a dead time (a detector without
    one would have undercut it :data:`~spslidar.pipeline.deadtime.GAP_EVIDENCE` times)."""
    from .pipeline.deadtime import GAP_EVIDENCE

    out, span = [], scan["span_s"]
    for c, g in scan["gaps"].items():
        n, shortest = g["n"], g["shortest_s"]
        if span > 0 and shortest > 0 and n * -math.expm1(-n / span * shortest) >= GAP_EVIDENCE:
            out.append(f"channel {c}: no two detections closer than {_si(shortest)}, where a "
                       f"detector without a dead time would have given "
                       f"{n * -math.expm1(-n / span * shortest):.3g} closer gaps: its dead "
                       f"time (--dead-time, read one --channel at a time)")
    return out


def _against_patterns(blocks: int, m: int, k: int) -> str:
    """What ``blocks`` marker blocks on input ``k`` say against ``m`` patterns."""
    head = f"--patterns holds {_n(m)} pattern{'s' if m != 1 else ''} and --marker {k} cuts "
    head += f"{_n(blocks)} block{'s' if blocks != 1 else ''}"
    if blocks == m:
        return head + ": one per pattern"
    if blocks < m:
        return (head + ": fewer blocks than patterns (another --marker input, markers "
                       "missed, or an acquisition cut short)")
    for extra, what in ((0, ""), (1, ", and one more (an arming or end-of-acquisition "
                                      "marker's, which reconstruct leaves out and says)"),
                        (2, ", and two more (an arming and an end marker's)")):
        if (blocks - extra) % m == 0:
            r = (blocks - extra) // m
            if r == 1:
                return head + what.replace(", and", ": one per pattern and", 1)
            return head + f": --repeats {r}{what}"
    return (head + ": no whole number of sequences (a DMD looping its sequence while the "
                   "recording started: --first-pattern auto; or a marker missed or added)")


def suggestions(scan: dict[str, Any], n_patterns: int | None = None) -> list[str]:
    """What ``reconstruct`` needs that the counts say, one sentence each; with
    ``n_patterns``, the blocks set against the patterns."""
    from .pipeline.deadtime import LOSS_TO_WARN, MAX_DETECTOR_RATE_HZ, TYPICAL_DEAD_TIMES_S

    h, out = scan["header"], []
    if scan["mode"] == "T2":
        if (scan["sync_records"] or 0) < 2:
            per = scan["periodic_channel"]
            out.append("no sync records: reconstruct reads a T2 file from the code's sync, "
                       "recorded on the sync input"
                       + (f"; channel {per['channel']}'s events come every "
                          f"{_si(per['period_s'])}, as a sync's would: --sync-channel "
                          f"{per['channel']}" if per else ""))
    else:
        from .io.ptu_blocks import _fitting_codes

        res, bpp = h["resolution_s"] or 0.0, h.get("bins_per_period")
        if res > 0:
            text = f"--bit-rate {1 / res:.6g} reads one TDC bin per code bit"
            if bpp:
                text += f"; {_fitting_codes(bpp, res, 0.5)}"
            div = h.get("sync_divider")
            if bpp and isinstance(div, int) and div > 1:
                text += (f"; or, as the header's sync divider says, each sync spans {div} "
                         f"code periods of {bpp / div:.6g} bins")
            out.append(text + "; a code clocked k times slower than the TDC: its own "
                              "--bit-rate with --allow-binning")
    if not scan["markers"]:
        out.append("no marker records: reconstruct splits the photons into patterns at the "
                   "DMD's markers (its trigger output on a marker input)")
    else:
        most = max(scan["markers"].values())
        top = [k for k, n in scan["markers"].items() if n == most]
        if len(top) == 1:
            out.append(f"--marker {top[0]}: {_n(most)} marker{'s' if most != 1 else ''}, "
                       f"as many patterns (or the "
                       f"sequence --repeats times)")
        else:
            out.append(f"inputs {', '.join(map(str, top))} hold {_n(most)} "
                       f"marker{'s' if most != 1 else ''} each (one "
                       f"may start each pattern, another end it): --marker {top[0]}, or "
                       f"--marker {top[-1]} --marker-edge end")
        if n_patterns is not None:
            out.append(_against_patterns(most, n_patterns, top[0]))
    span, longest = scan["span_s"], max(TYPICAL_DEAD_TIMES_S)
    for c, n in scan["photons"].items():
        load = (n / span if span > 0 else 0.0) * longest  # (photons per dead time)
        if load / longest >= MAX_DETECTOR_RATE_HZ:
            out.append(f"channel {c} counts {load / longest:.3g} photons/s, more than a "
                       f"single-photon detector can: a simulated linear counter, or the "
                       f"photons of several detectors on one channel")
        elif load >= LOSS_TO_WARN:
            out.append(f"channel {c} counts {load / longest:.3g} photons/s: a detector with "
                       f"a {_si(longest)} dead time loses {100 * load / (1 + load):.2g} % of "
                       f"them to pile-up: give its --dead-time")
    out += _dead_times(scan)
    if len(scan["photons"]) > 1:
        out.append(f"{len(scan['photons'])} detector channels hold photons: all are read "
                   f"together unless --channel picks one (--align-channels moves them onto "
                   f"one where cables of different lengths delay them)")
    return out


#: a delay holds a return where the whole acquisition's correlation rises this many
#: standard deviations above its median (:data:`spslidar.pipeline.gate.AUTO_GATE_SIGMAS`'s
#: rule, on the photons of every block summed)
RETURN_SIGMAS = 5.0
#: bins of margin on each side of the delays that hold returns, in the range gate said
GATE_MARGIN_BINS = 3


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
        code does not fill); else ``peaks`` (up to five runs of delays that hold returns,
        strongest first: ``lag`` (bits), ``range_m`` (c lag / 2 bit_rate: the delay the
        photons show, cables and electronics included), ``sigmas``), ``gate_m`` (a range
        gate over every run, :data:`GATE_MARGIN_BINS` bits beyond each end) and
        ``unambiguous_m``.
    """
    from .constants import SPEED_OF_LIGHT
    from .correlate import auto_replica, correlation_noise_sigma, make_replica
    from .pipeline.gate import code_sidelobes, occupied_lags

    h = scan["header"]
    counts = scan.get("dtime_counts")
    if scan["mode"] != "T3" or counts is None:
        return {"ok": False, "why": "a T2 file's delays are read from its syncs by "
                                    "reconstruct; inspect reads them from T3 records only"}
    n = int(np.size(code))
    res, period = float(h["resolution_s"] or 0.0), float(h["sync_period_s"] or 0.0)
    width = 1.0 / bit_rate
    k = width / res if res > 0 else 0.0
    if not (round(k) >= 1 and abs(k - round(k)) <= 1e-3 * k):
        return {"ok": False, "why": f"the TDC bin ({_si(res)}) is no whole fraction of the "
                                    f"code's bit ({_si(width)}): reconstruct splits it "
                                    f"between bits (--allow-binning); inspect does not"}
    k = int(round(k))
    div = h.get("sync_divider")
    fold = [d for d in {1, div if isinstance(div, int) and div > 1 else 1}
            if period > 0 and abs(period - d * n * width) <= 0.5 * width]
    if not fold:
        return {"ok": False, "why": f"the sync period ({_si(period)}) is not {n} bits at "
                                    f"{bit_rate:.6g} Hz: reconstruct says what fits"}
    bits = np.bincount((np.arange(counts.size) // k) % n, weights=counts, minlength=n)[:n]
    if not bits.sum() > 0:
        return {"ok": False, "why": "the file holds no photons"}
    kind = auto_replica(code)
    replica = make_replica(code, kind)
    corr = np.fft.irfft(np.fft.rfft(bits) * np.conj(np.fft.rfft(replica)), n=n)
    sigma = correlation_noise_sigma(bits[None, :], replica)
    lags = np.arange(n)
    hit = occupied_lags(corr[None, :], sigma, RETURN_SIGMAS, 0, lags,
                        code_sidelobes(code, replica))
    metres = SPEED_OF_LIGHT * width / 2
    out: dict[str, Any] = {"ok": True, "unambiguous_m": n * metres, "replica": kind,
                           "peaks": [], "gate_m": None}
    if not hit.any():
        return out
    if hit.mean() > 0.5:  # (no scene fills half the code's period: not this code's photons)
        return {"ok": False, "why": f"{100 * hit.mean():.0f} % of the delays stand above the "
                                    f"background: the photons do not follow this code (the "
                                    f"wrong code or --bit-rate, or no PSST acquisition)"}
    # runs of occupied delays around the period (a run may wrap past its end)
    start = int(np.flatnonzero(~hit)[-1]) + 1 if (~hit).any() else 0
    order = (start + lags) % n
    runs, cur = [], []
    for i in order:
        if hit[i]:
            cur.append(int(i))
        elif cur:
            runs.append(cur)
            cur = []
    if cur:
        runs.append(cur)
    base = float(np.median(corr))
    peaks = []
    for r in runs:
        top = max(r, key=lambda i: corr[i])
        peaks.append({"lag": top, "range_m": top * metres,
                      "sigmas": float((corr[top] - base) / sigma[0])})
    peaks.sort(key=lambda p: -p["sigmas"])
    out["peaks"] = peaks[:5]
    first = runs[0][0]
    span = (runs[-1][-1] - first) % n  # (the runs in order from the first after a gap)
    lo = first - GATE_MARGIN_BINS
    out["gate_m"] = (lo * metres, (lo + span + 2 * GATE_MARGIN_BINS) * metres)
    return out


def _returns_text(found: dict[str, Any]) -> list[str]:
    if not found["ok"]:
        return [f"no range said: {found['why']}"]
    if not found["peaks"]:
        return [f"no delay holds a return {RETURN_SIGMAS:g} standard deviations above the "
                f"background, over the whole {found['unambiguous_m']:.4g} m of the code's "
                f"period: a scene too dark, the wrong code, or the wrong --bit-rate"]
    peaks = "; ".join(f"{p['range_m']:.4g} m ({p['sigmas']:.3g} sigma)"
                      for p in found["peaks"])
    lo, hi = found["gate_m"]
    return [f"returns (the photons of every block, correlated with the code): {peaks}; "
            f"--range-gate {max(lo, 0.0):.4g} {hi:.4g} holds them (the delays the photons "
            f"show, cables included: with --calibration, the calibrated delay's range less; "
            f"ranges are modulo the code's {found['unambiguous_m']:.4g} m)"]


def _jsonable(scan: dict[str, Any]) -> dict[str, Any]:
    """The scan with string keys, as JSON writes them (the per-bin counts left out)."""
    return json.loads(json.dumps({k: v for k, v in scan.items() if k != "dtime_counts"},
                                 default=str))


def cmd_inspect(args: argparse.Namespace) -> int:
    """Run ``spslidar inspect``; return the exit status (0, or 2 for a file it cannot read,
    said in one line before anything is printed)."""
    from .io.ptu_scan import scan_ptu

    m = None
    if args.patterns is not None:
        from .io.lab_arrays import read_patterns_file

        m = int(read_patterns_file(args.patterns).shape[0])
    code = None
    if args.code is not None or args.bit_rate is not None:
        from .errors import ConfigError

        if args.code is None or args.bit_rate is None:
            raise ConfigError("--code and --bit-rate go together: the range of the returns "
                              "needs both")
        if not (math.isfinite(args.bit_rate) and args.bit_rate > 0):
            raise ConfigError(f"--bit-rate must be a positive number of bits per second, got "
                              f"{args.bit_rate!r}")
        from .cli_measured import _code

        code = _code(args)[0]
    scans = [(path, scan_ptu(path)) for path in args.ptu]  # (every file read before a word)
    found = ([returns_in_file(s, code, args.bit_rate) for _, s in scans] if code is not None
             else [None] * len(scans))
    if args.json:
        print(json.dumps([dict(_jsonable(s), path=p, **({"returns": f} if f else {}))
                          for (p, s), f in zip(scans, found, strict=True)], indent=1,
                         default=str))
        return 0
    for i, ((path, scan), f) in enumerate(zip(scans, found, strict=True)):
        if i:
            print()
        print("\n".join(describe(scan, path)))
        said = suggestions(scan, m) + (_returns_text(f) if f is not None else [])
        if said:
            print("for 'spslidar reconstruct':")
            print("\n".join(f"  - {s}" for s in said))
    return 0
