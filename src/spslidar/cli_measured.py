"""``spslidar reconstruct`` and ``spslidar calibrate``: a measured T3 PTU acquisition to a
depth map, and a flat target's to the instrument's system delay and response; the
sub-commands' parsers and commands, as :mod:`spslidar.cli` registers them (moved out of
``cli.py``, which had grown past 750 lines)."""

from __future__ import annotations

import argparse

__all__ = ["add_calibrate_parser", "add_reconstruct_parser", "cmd_calibrate",
           "cmd_reconstruct"]


def add_code_args(p: argparse.ArgumentParser, required: bool = True, more: str = "") -> None:
    """``--code``, ``--code-length`` and ``--code-index`` as the measured paths read them
    (reconstruct, calibrate, inspect); ``more``: what the command does with the code."""
    p.add_argument("--code", required=required, metavar="CODE|FAMILY",
                   help="bits of one code period: a .npy, a text file (0110... or numbers, "
                        "0/1 or -1/+1), a .mat vector; or a code family's name (e.g. mseq, "
                        "gold: one whose bits a name, length and index fix) with "
                        "--code-length, as run makes it" + more)
    p.add_argument("--code-length", type=int, metavar="L",
                   help="bits per code period of a named family (2^n - 1 for mseq/gold)")
    p.add_argument("--code-index", type=int, metavar="I",
                   help="member of the named family (gold: default 2) / cyclic shift of the "
                        "m-sequence (default 0), as run --code-index")


def _add_acquisition_args(p: argparse.ArgumentParser, ptu_metavar: str, ptu_help: str,
                          many: bool = False) -> None:
    """The flags that describe a measured acquisition (reconstruct, calibrate); ``many``:
    ``--ptu`` takes several files (a repeated ``--ptu`` adds to them: it had kept the last
    alone, without a word, an outside lab audit of 2026-11-30)."""
    p.add_argument("--ptu", required=True, metavar=ptu_metavar, help=ptu_help,
                   action="extend", nargs="+" if many else 1)
    p.add_argument("--patterns", required=True, metavar="PATTERNS",
                   help="the mirror states shown, in marker order (0/1 or grey in [0, 1]): an "
                        "(M, N, N) .npy; a MATLAB .mat (N x N x M, or M x N^2 rows flattened "
                        "column-major; FILE.mat:NAME picks one array); a multi-page TIFF; or "
                        "a folder of images, one per pattern in the order of their names "
                        "(p2 before p10), each as displayed, binary images as 0/1")
    p.add_argument("--pattern-size", type=int, default=None, metavar="N",
                   help="the patterns' side: where --patterns holds them finer (images at "
                        "the DMD's resolution, each pattern pixel a block of mirrors), each is "
                        "read as N x N blocks, every block checked to hold one state; for a "
                        "MATLAB sensing matrix whose two sides are squares, it says which "
                        "holds the pixels")
    add_code_args(p)
    p.add_argument("--bit-rate", type=float, required=True, metavar="HZ",
                   help="bits (TDC bins) per second; must match the file's resolution")
    p.add_argument("--marker", type=int, default=1, metavar="K",
                   help="marker input flagging a pattern change (default 1)")
    p.add_argument("--marker-edge", choices=("start", "end"), default="start",
                   help="whether the DMD's marker starts each pattern (default) or ends it")
    p.add_argument("--channel", type=int, metavar="C",
                   help="detector channel, numbered from 0: the channel field of HydraHarp, "
                        "TimeHarp and MultiHarp records; a PicoHarp's inputs 1-4 are 0-3 "
                        "(default all; a channel without photons is refused)")
    p.add_argument("--allow-binning", action="store_true",
                   help="merge k dtime units into one bin where the file's resolution is "
                        "1/k of 1/--bit-rate (a TDC finer than the code's bits), or split "
                        "each TDC bin between the bits it overlaps where it is no whole "
                        "fraction of one (an 80 ps TDC under 100 ps bits, a code clock off "
                        "the TDC's)")
    p.add_argument("--settle", type=float, default=0.0, metavar="S",
                   help="seconds at the start of each pattern whose photons are dropped (the "
                        "DMD's mirrors settling after its marker, or a marker early against "
                        "them); each pattern's dwell is shortened by as much (default 0)")
    p.add_argument("--repeats", type=int, default=1, metavar="K",
                   help="times the pattern sequence was shown in a row: the file holds K x M "
                        "marker blocks, block r M + i showing pattern i; each pattern's blocks "
                        "are summed (default 1)")
    p.add_argument("--first-pattern", type=_first_pattern, default=None, metavar="I|auto",
                   help="a free-running DMD, looping its sequence while the recording started "
                        "at some moment: the --patterns row (from 0) the file's first marker "
                        "block shows; block b shows pattern (I + b) mod M, the file may hold "
                        "any number of blocks from M on (the last cut anywhere), each "
                        "pattern's summed (not with --repeats, --frame or several files; "
                        "default: block b shows pattern b). 'auto' finds I from the data, "
                        "and refuses where it cannot tell")
    p.add_argument("--sync-divider", type=int, default=None, metavar="D",
                   help="code periods per sync record, where the file's header does not say "
                        "(a sync from the code generator every D periods; default: the "
                        "header's HWSync_Divider, or 1)")
    p.add_argument("--sync-channel", type=int, default=None, metavar="C",
                   help="a T2 file whose sync went to a detector input: channel C's events "
                        "(numbered as --channel) are the code's syncs, not photons "
                        "(HydraHarp, TimeHarp, MultiHarp)")
    p.add_argument("--align-channels", action="store_true",
                   help="detector channels read together (no --channel) moved onto the one "
                        "with the most photons by the delays their photons show (a cable "
                        "between them; the file is read twice); a calibration made with it "
                        "applies its own")
    p.add_argument("--dead-time", type=float, metavar="S",
                   help="the detector's (and TCSPC's) non-paralysable dead time, seconds: each "
                        "pattern's histogram is corrected for pile-up before the matched "
                        "filter (0: it has none; default: counts taken as they are, with a "
                        "warning where the count rate says pile-up matters)")
    p.add_argument("--afterpulse-prob", type=float, default=0.0, metavar="P",
                   help="the detector's afterpulse probability per avalanche, taken out with "
                        "--dead-time")
    p.add_argument("--afterpulse-delay", type=float, default=0.0, metavar="S",
                   help="mean afterpulse delay after re-arming, seconds (with "
                        "--afterpulse-prob)")


def _first_pattern(text: str) -> int | str:
    """``--first-pattern``: a whole number, or ``auto``."""
    if text == "auto":
        return text
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"a whole number (a --patterns row) or auto, "
                                         f"got {text!r}") from None


def _detector_args(args) -> dict:
    """The detector's dead time and afterpulsing as the measured paths take them."""
    from .pipeline.deadtime import DEAD_TIME_KEYS

    return {k: getattr(args, k) for k in DEAD_TIME_KEYS}


def _code(args) -> tuple:
    """``--code``'s bits, read once (a FIFO given as the code hung when it was read here
    and again by the library: an audit of stop 67), and what ``metrics.json`` /
    ``CAL.json`` record of where they came from (``inputs.code``'s ``file`` and
    ``family``): the file as given, or the family's name, length and index."""
    from .codes import CODES
    from .pipeline.inputs import is_family, load_code

    bits = load_code(args.code, args.code_length, args.code_index)
    name = str(args.code)
    if not is_family(name):
        return bits, {"file": name, "family": None}
    name = CODES.canonical(name)
    index = (CODES.get(name).defaults.get("index", 0) if args.code_index is None
             else int(args.code_index))
    return bits, {"file": None,
                  "family": {"name": name, "length": int(args.code_length), "index": index}}


def add_reconstruct_parser(sub) -> None:
    """``spslidar reconstruct``: a measured T3 PTU acquisition -> depth map."""
    from .cli_common import (
        _add_fov_option,
        _add_regulariser_option,
        _add_stage_options,
        _choices,
        _duration,
        _memory,
        _stage_name,
    )

    solvers, _ = _choices("solver")
    depths, _ = _choices("depth")
    S = argparse.SUPPRESS
    p = sub.add_parser(
        "reconstruct", help="reconstruct a measured PicoQuant PTU acquisition (T3, or T2 "
                            "with sync records)",
        description="Read photon time tags (sync = code period start, a marker per DMD "
                    "pattern change), histogram them per pattern over the code period and run "
                    "the matched filter, QCR, solver and depth stages of 'run'; writes "
                    "metrics.json, depth.npy, reflectivity.npy, confidence.npy, points.ply, "
                    "depth.png (and depth2.npy from --depth guarded/evidence; truth.npy and "
                    "valid.npy with --truth) into --out (only when complete).")
    _add_acquisition_args(p, "FILE.ptu", "PTU file, T3 or T2 with the code's sync recorded; or "
                                         "several, an acquisition saved one "
                                         "file per pass, each holding the sequence --repeats "
                                         "times, read in the order given and summed", many=True)
    p.add_argument("--frame", type=int, default=None, metavar="I",
                   help="with --repeats (or several --ptu files): reconstruct repeat I of the "
                        "sequence alone (from 0, counted through the files), a frame of a "
                        "video (default: all repeats summed)")
    p.add_argument("--range-gate", type=float, nargs=2, required=True, metavar=("MIN", "MAX"),
                   help="depths to reconstruct, metres")
    p.add_argument("--calibration", metavar="CAL.json",
                   help="remove the system delay and match the IRF measured by 'spslidar "
                        "calibrate' (the range gate is then in true metres)")
    p.add_argument("--truth", metavar="TRUTH.npy",
                   help="(N, N) true depth in metres (NaN where unknown), only to score the "
                        "result: without it every metric that needs no truth is given")
    p.add_argument("--auto-gate", action=argparse.BooleanOptionalAction, default=S,
                   help="drop the range slices without returns before solving (default: on "
                        "for gates over 256 slices; --no-auto-gate solves every slice, as "
                        "the warning on a sampled gate says)")
    _add_fov_option(p)
    p.add_argument("--solver", choices=solvers, type=_stage_name("solver"), default=S)
    _add_stage_options(p, "solver")
    _add_regulariser_option(p)
    p.add_argument("--depth", choices=depths, type=_stage_name("depth"), default=S)
    _add_stage_options(p, "depth")
    p.add_argument("--lam", type=float, default=S, metavar="W",
                   help="regularisation weight (default: --lam-scale times the noise level "
                        "estimated from the measurements, as in 'run')")
    p.add_argument("--lam-scale", type=float, default=S, metavar="K")
    p.add_argument("--iterations", type=int, default=S, metavar="K")
    p.add_argument("--tol", type=float, default=S,
                   help="relative-change stopping tolerance (default 1e-4)")
    p.add_argument("--qcr", action=argparse.BooleanOptionalAction, default=S)
    p.add_argument("--qcr-form", choices=("centred", "covariance"), default=S,
                   help="centred least squares (default) or the paper's literal ||Delta - Hp||")
    p.add_argument("--nonneg", action=argparse.BooleanOptionalAction, default=S,
                   help="non-negative return strengths (default on, as in 'run')")
    p.add_argument("--subbin", action=argparse.BooleanOptionalAction, default=S,
                   help="place each return below a bin from its peak and the two beside it, "
                        "with the pulse's shape (with --calibration the calibrated "
                        "response's own sub-bin step applies, whatever this says)")
    p.add_argument("--max-memory", type=_memory, default=S, metavar="GB",
                   help="refuse a reconstruction whose estimated peak memory exceeds this: "
                        "gigabytes, or with a unit (500MB, 2GB; default: the memory available "
                        "now)")
    p.add_argument("--max-time", type=_duration, default=S, metavar="TIME",
                   help="refuse a reconstruction whose estimated solve time exceeds this: "
                        "seconds, or with a unit (90s, 10min, 2h; default 1h)")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the previous spslidar result in --out")
    p.add_argument("--no-figure", action="store_true", help="skip depth.png")


def cmd_reconstruct(args) -> int:
    """Run ``spslidar reconstruct``; return the exit status."""
    from .cli_common import _WRITTEN, _written, say_warnings, warn_fov
    from .outdir import check_output
    from .pipeline.real import reconstruct_ptu

    check_output(args.out, args.overwrite)  # refuse before any work
    from .pipeline.measurement import processing_keys

    # (with the options the solvers and estimators declare: a plugin's had no flag)
    processing = {k: getattr(args, k) for k in processing_keys() if hasattr(args, k)}
    ptu = args.ptu[0] if len(args.ptu) == 1 else args.ptu
    code, source = _code(args)
    result = reconstruct_ptu(ptu, args.patterns, code, args.bit_rate,
                             tuple(args.range_gate), marker=args.marker, channel=args.channel,
                             allow_binning=args.allow_binning, truth=args.truth,
                             calibration=args.calibration, marker_edge=args.marker_edge,
                             settle=args.settle, repeats=args.repeats,
                             sync_divider=args.sync_divider,
                             sync_channel=args.sync_channel,
                             align_channels=args.align_channels, frame=args.frame,
                             pattern_size=args.pattern_size,
                             first_pattern=args.first_pattern, **_detector_args(args),
                             **processing)
    result.metrics["inputs"]["code"].update(source)
    say_warnings(result.warnings)
    warn_fov(args.fov)
    out = result.save(args.out, figure=not args.no_figure, overwrite=args.overwrite,
                      fov_deg=args.fov, option="--out", replace="--overwrite")
    _WRITTEN.append(f"{out}/")
    m = result.metrics
    rmse = m.get("depth_rmse_m")
    import numpy as np

    from .metrics import mostly_noise, returns_phrase
    from .metrics import percent as _percent

    # returns among all pixels (coverage is the share with a truth and a return); a map of
    # noise has no reflectivity to speak of (its mean read 37 for a true 1, an audit)
    bright = ("" if mostly_noise(m) else f", mean reflectivity "
              f"{m.get('mean_reflectivity') or 0.0:.3g} photons per pulse")
    print(f"{m['n_patterns']} patterns, {int(sum(m['ptu']['counts_per_pattern']))} photons; "
          f"{returns_phrase(m, float(np.isfinite(result.depth).mean()))}{bright}; "
          + (f"depth RMSE {rmse:.4f} m over the {_percent(m['coverage'])} of pixels with a "
             f"truth and a return" if rmse is not None else "no ground truth (--truth)"))
    print(f"wrote {out}/: {' '.join(_written(out))}")
    return 0


def add_calibrate_parser(sub) -> None:
    """``spslidar calibrate``: a flat target at a known distance -> system delay and IRF."""
    from .cli_common import _fov

    p = sub.add_parser(
        "calibrate", help="measure the system delay and IRF from a flat target",
        description="Measure the instrument's system delay (sub-bin) and response (IRF) from a "
                    "PTU acquisition (T3, or T2 with sync records) of a flat target at a "
                    "known distance (any patterns) "
                    "and write them, with what they were measured from, to CAL.json for "
                    "'spslidar reconstruct --calibration'.")
    _add_acquisition_args(p, "FLAT.ptu", "PTU file of the target (T3, or T2 with sync "
                                         "records)")
    p.add_argument("--distance", type=float, required=True, metavar="M",
                   help="the flat target's distance from the lidar (on the optical axis), "
                        "metres")
    p.add_argument("--target", choices=("auto", "plane", "range"), default="auto",
                   help="what the target's pixels see: 'plane', a flat wall facing the lidar, "
                        "farther towards the corners (its spread removed); 'range', one range "
                        "on every pixel (a small target, a sphere); 'auto' (default): the "
                        "plane where the data ask for one")
    p.add_argument("--fov", type=_fov, default=None, metavar="DEG",
                   help="the flat wall's field of view across the image, degrees (default: "
                        "fitted from the data)")
    p.add_argument("--out", required=True, metavar="CAL.json", help="calibration file to write")
    p.add_argument("--overwrite", action="store_true",
                   help="replace a calibration file spslidar wrote")


def cmd_calibrate(args) -> int:
    """Run ``spslidar calibrate``; return the exit status."""
    from .cli_common import _WRITTEN
    from .pipeline.calibration import calibrate_ptu
    from .pipeline.calibration_file import check_calibration_out, write_calibration

    check_calibration_out(args.out, args.overwrite)  # refuse before any work
    if len(args.ptu) > 1:  # (a repeated --ptu kept the last alone, without a word)
        from .errors import ConfigError

        raise ConfigError(f"calibrate reads one PTU file, got {len(args.ptu)} (--ptu given "
                          f"more than once?)")
    code, source = _code(args)
    cal = calibrate_ptu(args.ptu[0], args.patterns, code, args.bit_rate, args.distance,
                        marker=args.marker, channel=args.channel,
                        allow_binning=args.allow_binning, target=args.target,
                        fov_deg=args.fov, marker_edge=args.marker_edge,
                        settle=args.settle, repeats=args.repeats,
                        sync_divider=args.sync_divider, sync_channel=args.sync_channel,
                        align_channels=args.align_channels,
                        pattern_size=args.pattern_size,
                        first_pattern=args.first_pattern, **_detector_args(args))
    cal["measured_from"]["inputs"]["code"].update(source)
    path = write_calibration(cal, args.out, args.overwrite)
    _WRITTEN.append(str(path))
    period_ns = cal["code_length"] / args.bit_rate * 1e9
    print(f"system delay {cal['delay_s'] * 1e9:.4f} ns ({cal['delay_bins']:.3f} bins, "
          f"{cal['delay_s'] * 149896229.0:.4f} m; known modulo the code's period, "
          f"{period_ns:.4g} ns); IRF FWHM {cal['irf_fwhm_bins']:.2f} bins; "
          f"{cal['measured_from']['photons']} photons, peak {cal['peak_to_noise']:.3g} noise "
          f"standard deviations")
    print(f"target: {cal['target']['reason']}")
    print(f"wrote {path}")
    return 0
