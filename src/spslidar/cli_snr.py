"""``spslidar snr``: the output SNR of one pattern's matched filter, eq. (10) of Shen et al.,
against its Monte-Carlo simulation (:mod:`spslidar.snr`); the sub-command's parser and its
command, as :mod:`spslidar.cli` registers them."""

from __future__ import annotations

import argparse

__all__ = ["add_snr_parser", "cmd_snr"]


def _duration(text: str) -> float:
    from .cli_common import _duration as parse

    return parse(text)


def add_snr_parser(subparsers: argparse._SubParsersAction) -> argparse.ArgumentParser:
    """Add the ``snr`` sub-command (eq. 10 against its simulation) to ``add_subparsers()``.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The sub-command registry of the ``spslidar`` parser (its ``parser_class`` is used, so
        errors stay one line when it is the CLI's ``_Parser``).

    Returns
    -------
    argparse.ArgumentParser
        The new sub-parser; :func:`cmd_snr` runs it.
    """
    from .codes import CODES
    from .snr import SNR_INTERVALS, SNR_METHODS  # standard library only

    p = subparsers.add_parser(
        "snr", help="output SNR of one pattern: eq. (10) against a Monte-Carlo simulation",
        description="Compare the output SNR of one pattern's matched filter over one code "
                    "period, eq. (10) of Shen et al., with a simulation of Poisson photon "
                    "counts and the unipolar replica. Prints theory and simulation (with a "
                    "95% interval). Where the periods cannot resolve the SNR (periods x SNR "
                    "under 4, fewer than 10 periods, or no variance in their counts) the ratio "
                    "reads 'unresolved' and "
                    "a warning names the --trials that would.")
    p.add_argument("--code", choices=CODES.names(), type=CODES.canonical, default="mseq",
                   help=f"code family: {CODES.help_text()}")
    p.add_argument("--code-length", type=int, default=16383, metavar="L",
                   help="code length T in bits; 2^n - 1 for mseq/gold (default 16383)")
    p.add_argument("--ones-ratio", type=float, default=0.5, metavar="R",
                   help="share of '1' bits of a random code, in (0, 1) (default 0.5)")
    p.add_argument("--code-index", type=int, default=None, metavar="I",
                   help="member of the Gold family / cyclic shift of the m-sequence (default "
                        "as run's: member 2 of a Gold family, its first true Gold code, as "
                        "members 0 and 1 are the preferred pair's two m-sequences; shift 0 of "
                        "an m-sequence)")
    p.add_argument("--signal", type=float, default=5.0, metavar="MS",
                   help="m_s: mean signal photons per laser pulse per DMD pixel (mirror on, "
                        "reflectivity 1), > 0 (default 5)")
    p.add_argument("--noise", type=float, default=10.0, metavar="MN",
                   help="m_n: mean noise counts per TDC bin per pixel, N^2 m_n per bin "
                        "(default 10)")
    p.add_argument("--size", type=int, default=64, metavar="N",
                   help="N x N DMD pixels (default 64)")
    p.add_argument("--on-fraction", type=float, default=0.5, metavar="F",
                   help="share of mirrors on in the binary pattern, in (0, 1] (default 0.5)")
    p.add_argument("--reflectivity", type=float, default=1.0, metavar="A",
                   help="reflectivity of the pixels, in (0, 1] (default 1)")
    p.add_argument("--trials", type=int, default=200, metavar="K",
                   help="code periods simulated, >= 2 (default 200; under 10 no ratio is "
                        "read: a variance from fewer is no estimate)")
    p.add_argument("--method", choices=SNR_METHODS, default="sum",
                   help="sum: one Poisson draw of the correlator's 'on' bins (default); "
                        "histogram: full TDC histograms and the matched filter")
    p.add_argument("--interval", choices=SNR_INTERVALS, default="delta",
                   help="standard error by the delta method (default) or a bootstrap")
    p.add_argument("--seed", type=int, default=0, help="random seed, >= 0 (default 0)")
    p.add_argument("--max-time", type=_duration, default=3600.0, metavar="TIME",
                   help="refuse a simulation estimated to take longer: seconds, or with a unit "
                        "(90s, 10min, 2h; default 1h)")
    p.add_argument("--json", action="store_true",
                   help='print {"theory", "simulated", "stderr", "ci95", "ratio", "resolved", '
                        '"params"} as JSON (null for a number that is not resolved)')
    from .cli_common import _add_stage_options

    # (a plugin family's options: listed in --help, their flags unknown, the family run at
    # its defaults without a word, an outside audit of a plugin developer; added after
    # snr's own flags, one of which a family's option may share: a plugin's --method made
    # every command a traceback, a review)
    p.set_defaults(code_option_keys=tuple(_add_stage_options(p, "code", skip_taken=True)))
    return p


def _code_options(args: argparse.Namespace) -> dict:
    """The code families' options given on the command line: those given a flag here
    (``code_option_keys``; one named as snr's own flag has none), and only where given (a
    family's own defaults apply otherwise)."""
    return {k: getattr(args, k) for k in getattr(args, "code_option_keys", ())
            if hasattr(args, k)}


def cmd_snr(args: argparse.Namespace) -> int:
    """Run ``spslidar snr``: print eq. (10) and its simulation; return the exit status.

    Parameters
    ----------
    args : argparse.Namespace
        Parsed options of :func:`add_snr_parser`.

    Returns
    -------
    int
        0 on success.

    Raises
    ------
    ConfigError
        On invalid options (:func:`main` prints it as one line and exits with status 2).

    Notes
    -----
    Plain output is two lines: eq. (10) with its parameters, then the simulated SNR with its
    standard error and 95 % interval and the ratio simulated / theory. With ``--json`` one JSON
    object ``{"theory", "simulated", "stderr", "ci95", "ratio", "resolved", "params"}``.

    Where the trials cannot resolve the SNR (:func:`~spslidar.snr.snr_simulated`'s
    RuntimeWarning, printed as one line on stderr: ``trials x SNR`` below 4, fewer than 10
    trials, or no variance in
    the counts) the ratio reads ``unresolved`` (``null`` and ``"resolved": false`` in JSON),
    and so does any simulated number that is not finite; the status stays 0, since eq. (10)
    and the simulation's bound are still printed and the options are valid. A signal or a
    reflectivity of 0 is refused (ConfigError, status 2): eq. (10) is then 0 and there is
    nothing to compare.
    """
    import json
    import math

    from .snr import snr_simulated
    from .snr.theory import as_integer, config_error

    seed = as_integer(args.seed, "seed")
    if seed < 0:
        raise config_error(f"seed must be a non-negative integer, got {seed}")
    r = snr_simulated(args.code, args.code_length, args.ones_ratio, args.signal, args.noise,
                      args.size, args.on_fraction, args.reflectivity, args.trials, seed,
                      method=args.method, interval=args.interval, code_index=args.code_index,
                      max_time=args.max_time, code_options=_code_options(args))
    params = {key: r[key] for key in (
        "code", "code_length", "code_index", "ones_ratio", "ones", "ones_ratio_actual", "signal",
        "noise", "size", "on_fraction", "mirrors_on", "reflectivity", "trials", "method",
        "interval", "replica", "delay", "code_options")}
    params["seed"] = seed
    resolved = math.isfinite(r["ratio"])  # (NaN where snr_simulated warned it is not)
    if args.json:
        def finite(x: float) -> float | None:
            return x if math.isfinite(x) else None

        print(json.dumps({
            "theory": finite(r["theory"]), "simulated": finite(r["simulated"]),
            "stderr": finite(r["stderr"]), "ci95": [finite(r["ci_low"]), finite(r["ci_high"])],
            "ratio": finite(r["ratio"]), "resolved": resolved, "params": params}))
        return 0

    def shown(x: float, spec: str) -> str:
        return format(x, spec) if math.isfinite(x) else "unresolved"

    print(f"theory    SNR = {r['theory']:.6g}  (eq. 10: {r['code']} T={r['code_length']}, "
          f"R_a={r['ones_ratio_actual']:.5g}, M2={r['mirrors_on']} mirrors on, "
          f"a={r['reflectivity']:g}, m_s={r['signal']:g}, m_n={r['noise']:g}, N={r['size']})")
    if math.isfinite(r["simulated"]):
        sim = (f"{r['simulated']:.6g} +- {shown(r['stderr'], '.3g')} (95% interval "
               f"{shown(r['ci_low'], '.4g')} .. {shown(r['ci_high'], '.4g')}; ")
    else:
        sim = "unresolved ("
    print(f"simulated SNR = {sim}{r['trials']} periods, {r['method']}, unipolar replica); "
          f"simulated/theory = {shown(r['ratio'], '.4f')}")
    return 0
