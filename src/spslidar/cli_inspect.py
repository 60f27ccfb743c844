"""``spslidar inspect``: what a PTU file holds, and the ``reconstruct`` options it asks for,
before any is guessed (:func:`spslidar.io.ptu_scan.scan_ptu`); the sub-command's parser and
its command, as :mod:`spslidar.cli` registers them."""

from __future__ import annotations

import argparse
import json
import sys
from typing import Any

__all__ = ["add_inspect_parser", "cmd_inspect", "describe"]


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
    from .cli_measured import add_code_args

    add_code_args(p, required=False,
                  more="; with --bit-rate, the photons of every block and channel are "
                       "correlated with it and the delays that hold returns are said, with "
                       "a --range-gate around them")
    p.add_argument("--bit-rate", type=float, metavar="HZ",
                   help="the code's bits per second (with --code)")
    p.add_argument("--pattern-size", type=int, default=None, metavar="N",
                   help="the patterns' side, as reconstruct --pattern-size (images at the "
                        "DMD's resolution; a MATLAB matrix whose two sides are squares)")
    p.add_argument("--json", action="store_true",
                   help="print the counts as JSON (one object per file, in a list; a file it "
                        "cannot read is {\"path\", \"error\"}) instead "
                        "of sentences")
    return p


def _blocks_text(k: int, b: dict[str, Any]) -> str:
    from .pipeline.file_advice import count, num, si

    if b["dwell_s"] is None:
        return f"--marker {k}: one marker, at {si(b['first_s'])}"
    d, ph = b["dwell_s"], b["photons_per_block"]
    text = (f"--marker {k}: {count(b['markers'], 'marker')}, blocks of {si(d['median'])} "
            f"({si(d['min'])} to {si(d['max'])}) holding {count(ph['median'], 'photon')} "
            f"(median; {num(ph['min'])} to {num(ph['max'])})")
    extra = []
    if b["empty_blocks"]:
        extra.append(f"{b['empty_blocks']} empty")
    if b["irregular_blocks"]:
        extra.append(f"{b['irregular_blocks']} over 1.5 times the median length or under "
                     f"its two thirds (a marker missed, or a bounce)")
    extra.append(f"{count(b['photons_before_first'], 'photon')} before the first marker, "
                 f"{num(b['photons_after_last'])} after the last")
    return text + "; " + "; ".join(extra)


def describe(scan: dict[str, Any], name: str) -> list[str]:
    """The sentences ``spslidar inspect`` prints for one :func:`~spslidar.io.scan_ptu`
    result (what the file holds; :func:`~spslidar.pipeline.file_advice.advice` says what
    follows)."""
    from .pipeline.file_advice import count, header_refusal, num, si

    h = scan["header"]
    # (a creation time ptufile could not read stays a number: left out)
    made = ", ".join(v for v in (h.get("hardware"), h.get("creator"), h.get("created"))
                     if isinstance(v, str) and v)
    lines = [f"{name}: {h['record_type']} records ({scan['mode']})"
             + (f"; {made}" if made else "")]
    timed = not header_refusal(scan)
    if scan["mode"] == "T3" and timed:
        div = h.get("sync_divider")
        lines.append(
            f"  TDC bin {si(h['resolution_s'])}; sync period {si(h['sync_period_s'])}"
            + (f" (sync divider {div})" if isinstance(div, int) and not isinstance(div, bool)
               and div > 1 else "")
            + (f", {h['bins_per_period']:.6g} TDC bins" if h.get("bins_per_period") else "")
            + (f"; photons in TDC bins up to {scan['dtime_max']}"
               if scan["dtime_max"] is not None else ""))
    elif timed:
        sp = scan.get("sync_period_s")
        lines.append(f"  time tag unit {si(h['time_unit_s'])}; "
                     f"{count(scan['sync_records'], 'sync record')}"
                     + (f", every {si(sp)}" if sp else ""))
    n_ph = sum(scan["photons"].values())
    lines.append(f"  {count(scan['n_records_read'], 'record')}"
                 + (f" over {si(scan['span_s'])}" if timed else "")
                 + f": {count(n_ph, 'photon')}, {count(scan['marker_records'], 'marker record')}"
                 f", {count(scan['overflow_records'], 'overflow record')}")
    span = scan["span_s"] if timed else 0.0
    if scan["photons"]:
        lines.append("  photons per --channel (from 0): " + ", ".join(
            f"{c}: {num(n)}" + (f" ({n / span:.3g}/s)" if span > 0 else "")
            for c, n in scan["photons"].items()))
    else:
        lines.append("  no photons")
    if scan["markers"]:
        lines.append("  markers per --marker input: " + ", ".join(
            f"{k}: {num(n)}" for k, n in scan["markers"].items()))
        if timed:
            lines += [f"  {_blocks_text(k, b)}" for k, b in scan["blocks"].items()]
    else:
        lines.append("  no marker records")
    return lines


def _jsonable(scan: dict[str, Any]) -> dict[str, Any]:
    """The scan with string keys, as JSON writes them (the per-bin counts and per-block
    arrays left out)."""
    return json.loads(json.dumps({k: v for k, v in scan.items()
                                  if k not in ("dtime_counts", "channel_dtime_counts",
                                               "block_arrays")}, default=str))


def cmd_inspect(args: argparse.Namespace) -> int:
    """Run ``spslidar inspect``; return the exit status (0, or 2 for a file it cannot read,
    said in one line: before anything is printed where it is the only file; among several,
    each other file is still described)."""
    from .io.ptu_scan import scan_ptu
    from .pipeline.file_advice import advice, returns_in_file, returns_text
    from .pipeline.inputs import check_bit_rate, check_pattern_size

    check_pattern_size(args.pattern_size)  # (without --patterns too: 0 passed, an audit)
    m = None
    if args.patterns is not None:  # (read as reconstruct reads them: a code file was "127
        # patterns", an audit)
        from .pipeline.inputs import load_patterns

        m = int(load_patterns(args.patterns, size=args.pattern_size).shape[0])
    from .errors import ConfigError

    code = None
    loose = [f for f, v in (("--code-length", args.code_length),
                            ("--code-index", args.code_index)) if v is not None]
    if args.code is None and loose:  # (ignored without a word before: an outside audit)
        raise ConfigError(f"{' and '.join(loose)} name a code of a --code family (mseq, "
                          f"gold, random), with --bit-rate: give both, or neither")
    if args.code is not None or args.bit_rate is not None:
        if args.code is None or args.bit_rate is None:
            raise ConfigError("--code and --bit-rate go together: the range of the returns "
                              "needs both")
        check_bit_rate(args.bit_rate)  # (as reconstruct checks it)
        from .cli_measured import _code

        code = _code(args)[0]
    from .errors import SpslidarError

    scans, bad = [], []
    for path in args.ptu:  # (every file read before a word)
        try:
            scans.append((path, scan_ptu(path)))
        except SpslidarError as exc:
            if len(args.ptu) == 1:
                raise
            # (one file it cannot read among several: the others are still described, the
            # refusal said in its line and the exit 2; one such file among a lab folder's
            # hid every other file's report, an outside audit)
            bad.append((len(scans) + len(bad), path, exc))
    found = ([returns_in_file(s, code, args.bit_rate) for _, s in scans] if code is not None
             else [None] * len(scans))
    status = 0
    if bad:
        from .errors import one_line

        for _, _, exc in bad:  # (one line each, as the command line's own errors)
            print(f"spslidar inspect: error: {one_line(exc)}", file=sys.stderr)
        status = 2
    if args.json:  # (the advice too: a script could not get --repeats, an audit)
        read = iter([dict(_jsonable(s), path=p, advice=advice(s, m),
                          **({"returns": f} if f else {}))
                     for (p, s), f in zip(scans, found, strict=True)])
        # (a file it could not read is an object with its refusal, in the files' order: the
        # list left it out, so a script's i-th object was not its i-th file, stop 82's note)
        refused = {i: {"path": p, "error": one_line(e)} for i, p, e in bad}
        print(json.dumps([refused[i] if i in refused else next(read)
                          for i in range(len(args.ptu))], indent=1, default=str))
        return status
    for i, ((path, scan), f) in enumerate(zip(scans, found, strict=True)):
        if i:
            print()
        print("\n".join(describe(scan, path)))
        said = advice(scan, m) + (returns_text(f) if f is not None else [])
        if said:
            print("for 'spslidar reconstruct':")
            print("\n".join(f"  - {s}" for s in said))
    return status
