"""The ``spslidar`` command-line tool: a thin layer over the library.

Only argparse is imported at start-up, so ``spslidar --help`` is instant; the numerical stack is
imported inside each sub-command. Bad input prints one line on stderr and exits with status 2.
"""

from __future__ import annotations

import argparse
import re
import sys
import warnings
from pathlib import Path

from .cli_check import add_check_parser, cmd_check
from .cli_common import (  # noqa: F401  (_memory: spslidar.cli._memory, as before)
    _WRITTEN,
    SAID_AT_LOAD,
    _add_fov_option,
    _add_regulariser_option,
    _add_stage_options,
    _choices,
    _duration,
    _fov,
    _memory,
    _OneLineWarnings,
    _stage_name,
    _Tolerant,
    _written,
    say_warnings,
    warn_fov,
)
from .cli_inspect import add_inspect_parser, cmd_inspect
from .cli_measured import (
    add_calibrate_parser,
    add_reconstruct_parser,
    cmd_calibrate,
    cmd_reconstruct,
)
from .cli_snr import add_snr_parser, cmd_snr  # noqa: F401  (re-exported: spslidar.cli.cmd_snr)
from .errors import one_line  # (spslidar.cli.one_line, as before)

EXIT_BAD_INPUT = 2


class _Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line (plus exit status 2), which takes no prefix
    of a long option for the option, and which reads a
    negative number in scientific notation (``--system-delay -1e-9``) as a value: Python 3.11's
    ``argparse`` takes only ``-1`` and ``-1.5`` for numbers, and said "expected one argument"
    (an audit), so the value's own refusal was never reached (3.13 reads them itself)."""

    def __init__(self, *args, **kwargs):
        # no prefixes of long options: ``reconstruct --lam 0.1`` (it has no --lam) was read as
        # --lam-scale 0.1, a weight 134 times smaller than asked, without a word (an audit)
        kwargs.setdefault("allow_abbrev", False)
        super().__init__(*args, **kwargs)
        if hasattr(self, "_negative_number_matcher"):  # (private: where it is, widened)
            self._negative_number_matcher = re.compile(
                r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|nan)$")

    def error(self, message):  # noqa: D401
        self.exit(EXIT_BAD_INPUT,
                  f"{self.prog}: error: {one_line(message)} (see {self.prog} --help)\n")


def _add_run_options(p: argparse.ArgumentParser) -> None:
    S = argparse.SUPPRESS  # only options given on the command line override the config file
    codes, codes_help = _choices("code")
    patterns, patterns_help = _choices("patterns")
    detectors, detectors_help = _choices("detector")
    solvers, solvers_help = _choices("solver")
    depths, depths_help = _choices("depth")
    g = p.add_argument_group("scene")
    from .scenes import SCENES

    g.add_argument("--scene", default=S, metavar="NAME|PATH",
                   help=f"built-in scene ({SCENES.help_text()}) or a file: .npy depth in "
                        "metres (the range along each pixel's ray, which a lidar measures, not "
                        "a z-buffer), .npz with 'depth' (+ 'reflectivity', 'valid'), .png/.tif "
                        "grey image (.jpg too, said to be lossy) mapped into [--depth-min, "
                        "--depth-max]")
    g.add_argument("--size", type=int, default=S, metavar="N", help="N x N pixels (default 64)")
    g.add_argument("--depth-min", type=float, default=S, metavar="M",
                   help="rescale the scene's depth into [MIN, MAX] metres")
    g.add_argument("--depth-max", type=float, default=S, metavar="M")
    g = p.add_argument_group("instrument")
    g.add_argument("--lidar", choices=("psst", "conventional"), default=S,
                   help="psst: pseudo-random coded laser (default); conventional: periodic "
                        "single pulses in the same acquisition time (whole pulse periods: up "
                        "to one period less)")
    g.add_argument("--code", choices=codes, type=_stage_name("code"), default=S, help=codes_help)
    _add_stage_options(g, "code")
    g.add_argument("--code-length", type=int, default=S, metavar="L",
                   help="bits per code period; 2^n - 1 for mseq/gold (default 16383); sets the "
                        "acquisition time per pattern (L / bit rate) for both lidars")
    g.add_argument("--ones-ratio", type=float, default=S, metavar="R",
                   help="share of '1' bits of a random code, in (0, 1) (default 0.5)")
    g.add_argument("--code-index", type=int, default=S, metavar="I",
                   help="member of the Gold family (default 2, the first Gold code; 0 and 1 "
                        "are the preferred pair's m-sequences) / cyclic shift of the "
                        "m-sequence (default 0)")
    g.add_argument("--bit-rate", type=float, default=S, metavar="HZ",
                   help="return-to-zero bit rate = TDC bin rate (default 10e9: 1.5 cm bins)")
    g.add_argument("--pulse-width", type=float, default=S, metavar="BITS",
                   help="laser pulse width as a fraction of a bit (default 0.5, RZ)")
    g.add_argument("--rep-rate", type=float, default=S, metavar="HZ",
                   help="conventional lidar pulse rate (default: the fastest whose unambiguous "
                        "range covers the range gate)")
    g.add_argument("--fairness", choices=("energy", "power"), default=S,
                   help="conventional vs PSST: same pulse energy (default, the paper's) or same "
                        "average power")
    g.add_argument("--system-delay", type=float, default=S, metavar="SECONDS",
                   help="extra delay of every return by the instrument's cables and "
                        "electronics (default 0; run's own depths keep it, as an "
                        "uncalibrated instrument's do; 'spslidar calibrate' measures it "
                        "and 'reconstruct --calibration' removes it)")
    g.add_argument("--irf", default=S, metavar="SPEC",
                   help="instrument response of every return: gaussian:FWHM[,tail:TAU"
                        "[,weight:W]] (seconds) or a .npy file per TDC bin (default none)")
    g.add_argument("--periods", type=int, default=S, metavar="N",
                   help="code periods accumulated per DMD pattern, the dwell (default 1, the "
                        "paper's); signal and noise photons grow with it")
    g.add_argument("--patterns", choices=patterns, type=_stage_name("patterns"), default=S,
                   help=f"DMD patterns: {patterns_help}")
    _add_stage_options(g, "patterns")
    g.add_argument("--pattern-sigma", type=float, default=S, metavar="S",
                   help="spread of the grey levels of --patterns gaussian, "
                        "clip(0.5 + S N(0, 1), 0, 1) (default 0.25)")
    from .patterns import HADAMARD_ORDERS, HADAMARD_REALISATIONS

    g.add_argument("--hadamard-order", choices=HADAMARD_ORDERS, default=S,
                   help="row ordering of --patterns hadamard: cake-cutting (fewest constant "
                        "pieces first, default), sequency, random or natural")
    g.add_argument("--hadamard-realisation", choices=HADAMARD_REALISATIONS, default=S,
                   help="+-1 Hadamard rows on a 0/1 DMD: shifted ((1+h)/2, DC removed by QCR "
                        "centring; default), differential (two frames, half the time each) or "
                        "complementary (shifted, a random half of the rows shown as (1-h)/2, "
                        "so that QCR's centring leaves no pixel unseen)")
    g.add_argument("--compression", type=float, default=S, metavar="F",
                   help="M/Q: patterns per pixel, in (0, 1] (default 0.25)")
    g = p.add_argument_group("photons")
    g.add_argument("--signal", type=float, default=S, metavar="MS",
                   help="m_s: mean signal photons per laser pulse per DMD pixel (mirror on, "
                        "reflectivity 1); a pattern collects m_s * sum(Phi * alpha) per pulse "
                        "(eq. 8). Default 5")
    g.add_argument("--noise", type=float, default=S, metavar="MN",
                   help="m_n: mean noise counts per TDC bin per pixel, ambient + background + "
                        "dark, so N^2 * m_n per bin in total (eq. 9-10 read per pixel: "
                        "docs/reading.md). Default 10")
    g.add_argument("--noise-split", type=float, nargs=3, default=S,
                   metavar=("AMB", "BG", "DARK"),
                   help="shares of m_n: ambient via the scene, background, dark (default 1/3 "
                        "each)")
    g.add_argument("--ambient", choices=("paper", "modulated"), default=S,
                   help="ambient light unmodulated N^2 m_n1 (paper, default) or through the DMD")
    g.add_argument("--background-rate", type=float, default=S, metavar="CPS",
                   help="extra background counts per second (physical units)")
    g.add_argument("--dark-count-rate", type=float, default=S, metavar="CPS",
                   help="extra dark counts per second")
    g.add_argument("--detector", choices=detectors, type=_stage_name("detector"), default=S,
                   help=f"detector model: {detectors_help}")
    _add_stage_options(g, "detector")
    g.add_argument("--noiseless", action=argparse.BooleanOptionalAction, default=S,
                   help="use expected counts (no Poisson noise); --no-noiseless undoes a "
                        "config file's")
    g = p.add_argument_group("processing")
    g.add_argument("--replica", choices=("auto", "bipolar", "zero-mean", "unipolar"),
                   default=S,
                   help="matched-filter replica (auto: for psst bipolar 2s-1 where the code "
                        "is balanced, zero-mean s-mean(s) otherwise; unipolar for "
                        "conventional)")
    g.add_argument("--range-gate", type=float, nargs=2, default=S, metavar=("MIN", "MAX"),
                   help="delays to reconstruct, in metres (default: the scene's depth window "
                        "padded by 3 bins)")
    g.add_argument("--auto-gate", action=argparse.BooleanOptionalAction, default=S,
                   help="drop the range slices without returns before solving (default: on "
                        "for large gates)")
    g.add_argument("--qcr", action=argparse.BooleanOptionalAction, default=S,
                   help="quadratic correlation reconstruction (default on)")
    g.add_argument("--qcr-form", choices=("centred", "covariance"), default=S,
                   help="centred least squares (default) or the paper's literal ||Delta - Hp||")
    g.add_argument("--solver", choices=solvers, type=_stage_name("solver"), default=S,
                   help=f"reconstruction algorithm: {solvers_help}")
    _add_stage_options(g, "solver")
    _add_regulariser_option(g)
    g.add_argument("--lam", type=float, default=S, metavar="W",
                   help="regularisation weight (default: lam-scale x the noise level estimated "
                        "from the measurements, never below 0.003 max|A^T y|, where the "
                        "iteration cap is multiplied by 5; a warning says when the floor "
                        "overrides --lam-scale)")
    g.add_argument("--lam-scale", type=float, default=S, metavar="K",
                   help="the weight as a multiple of the estimated noise level (default: the "
                        "solver's, fista 0.45, the others 0.3)")
    g.add_argument("--iterations", type=int, default=S, metavar="K",
                   help="maximum solver iterations (default: the solver's, fista 60, twist "
                        "60, tval3 100, gpsr 120)")
    g.add_argument("--tol", type=float, default=S,
                   help="relative-change stopping tolerance (default 1e-4)")
    g.add_argument("--nonneg", action=argparse.BooleanOptionalAction, default=S,
                   help="constrain the reconstructed return strengths to be non-negative "
                        "(default on; physical, since photon returns cannot be negative; "
                        "not with --regulariser wavelet, gpsr's default, whose prox has no "
                        "closed form under the bound, nor with --no-qcr, whose "
                        "mean-eliminated problem has no sign constraint: said where "
                        "--nonneg is given, and metrics.json's config says which)")
    g.add_argument("--depth", choices=depths, type=_stage_name("depth"), default=S,
                   help=f"depth estimator: {depths_help}")
    _add_stage_options(g, "depth")
    g.add_argument("--subbin", action=argparse.BooleanOptionalAction, default=S,
                   help="place each return below a bin from its peak and the two beside it, "
                        "with the pulse's shape (--no-subbin undoes a config file's)")
    g.add_argument("--dtype", choices=("float32", "float64"), default=S,
                   help="precision of the solve (default float32); the simulated counts and their "
                        "correlations are float32 whatever it says")
    g.add_argument("--backend", choices=("numpy", "torch", "cupy", "array-api-strict"),
                   default=S,
                   help="array library of the numeric core (default numpy; torch: pip install "
                        "spslidar[gpu], cupy: spslidar[cupy]; array-api-strict: the standard's "
                        "reference, on the CPU, to check a backend's results against NumPy's); "
                        "patterns, counts, matched filter, QCR, FISTA + TV and argmax run "
                        "there, every other stage on the host")
    g.add_argument("--device", choices=("cpu", "cuda"), default=S,
                   help="where the backend runs (default cpu; cuda needs torch or cupy)")
    g.add_argument("--seed", type=int, default=S, help="random seed (default 0)")
    g.add_argument("--max-memory", type=_memory, default=S, metavar="GB",
                   help="refuse a run whose estimated peak memory exceeds this: gigabytes, or "
                        "with a unit (500MB, 2GB, 1.5GiB; default: the memory available now); "
                        "the estimate is checked before any work")
    g.add_argument("--max-time", type=_duration, default=S, metavar="TIME",
                   help="refuse a run whose estimated time exceeds this: seconds, or with a "
                        "unit (90s, 10min, 2h; default 1h); a run estimated over 30 s says so "
                        "before it starts")


def build_parser() -> argparse.ArgumentParser:
    """The ``spslidar`` parser with every sub-command (their options and choices read from
    the registries, a plugin's stages included once loaded)."""
    from .version import __version__

    parser = _Parser(
        prog="spslidar",
        description="Simulate and reconstruct the pseudo-random spread-spectrum single-pixel "
                    "photon-counting ToF lidar (Shen et al.).",
    )
    parser.add_argument("--version", action="version", version=f"spslidar {__version__}")
    parser.add_argument("--plugin", action="append", metavar="MODULE", default=argparse.SUPPRESS,
                        help="import MODULE (a module name or a .py file) before anything "
                             "else: stages it registers are choices with their options' "
                             "flags, in sweep and reproduce workers too (repeatable; also "
                             "SPSLIDAR_PLUGINS, commas)")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    p = sub.add_parser("run", help="simulate one acquisition, reconstruct it and score it",
                       description="Simulate one acquisition of a scene, reconstruct the depth "
                                   "map and score it; writes metrics.json, depth.npy, "
                                   "reflectivity.npy, confidence.npy, points.ply, truth.npy, "
                                   "valid.npy, depth.png and, from --depth guarded/evidence, "
                                   "depth2.npy into --out (only when complete).")
    p.add_argument("--config", metavar="FILE.toml",
                   help="TOML file with the same keys (command-line options override it)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder: new, empty, or a previous result (with --overwrite); "
                        "a folder holding anything else is refused")
    p.add_argument("--overwrite", action="store_true",
                   help="replace the previous spslidar result in --out")
    p.add_argument("--no-figure", action="store_true", help="skip depth.png")
    _add_fov_option(p)
    p.add_argument("--save-ptu", default=argparse.SUPPRESS, metavar="FILE.ptu",
                   help="also write the simulated acquisition photon by photon as a T3 PTU "
                        "file (sync = code period, a marker per pattern; low flux only), for "
                        "'spslidar reconstruct': the same scene, patterns and code, its "
                        "photons drawn afresh (another realisation of the run's noise)")
    _add_run_options(p)
    add_snr_parser(sub)
    add_reconstruct_parser(sub)
    add_calibrate_parser(sub)
    add_inspect_parser(sub)
    add_check_parser(sub)

    from .experiments.reproduce import ALL, EXPERIMENT_REGISTRY

    # read from the registry when the parser is built, so a plugin's experiment (--plugin)
    # is a choice (the names frozen at import left it "invalid choice", an audit)
    experiments = (*EXPERIMENT_REGISTRY.names(), ALL)
    r = sub.add_parser("reproduce", help="reproduce the paper's figures and numbers beside ours",
                       description="Run one of the paper's experiments (or all) through the "
                                   "sweep engine; writes DIR/<experiment>/ (PNG figures, tidy "
                                   "CSV) and DIR/report.md + report.html with the paper's "
                                   "numbers next to ours. Finished runs are cached in "
                                   "DIR/cache, so an interrupted run resumes.")
    r.add_argument("experiment", choices=experiments, metavar="EXPERIMENT",
                   help=f"one of: {', '.join(experiments)}")
    r.add_argument("--out", required=True, metavar="DIR", help="report folder")
    r.add_argument("--quick", action="store_true",
                   help="reduced smoke-test version (32x32, fewer settings, one trial "
                        "unless --trials says)")
    _add_sweep_options(r, trials=True)

    w = sub.add_parser("sweep", help="run a user-defined parameter grid (TOML) of runs",
                       description="Run every point of the grid in CONFIG.toml (a [grid] table "
                                   "of lists of run keys, optional [base] table, seed, trials) "
                                   "and write DIR/results.csv (one row per run). Finished runs "
                                   "are cached in DIR/runs, so an interrupted sweep resumes.",
                       epilog="Exit status: 0 when every run succeeded; 1 when the work did "
                              "not complete (some runs failed: results.csv has their error "
                              "column; or a worker process was killed: run the same command "
                              "again to resume); 2 on bad input (nothing runs); 130 after "
                              "Ctrl-C, 143 after SIGTERM.")
    w.add_argument("config", metavar="CONFIG.toml", help="sweep definition")
    w.add_argument("--out", required=True, metavar="DIR", help="output folder")
    w.add_argument("--overwrite", action="store_true",
                   help="replace the results.csv of another sweep (other points) in DIR; the "
                        "same sweep resumes without it")
    _add_sweep_options(w, trials=False)
    return parser


def _add_sweep_options(p: argparse.ArgumentParser, trials: bool) -> None:
    if trials:
        p.add_argument("--trials", type=int, metavar="K",
                       help="Monte-Carlo trials per setting (default: 5 for fig3, 3 for fig4, "
                            "fig5 (fig4's runs) and pileup, else 1; 1 with --quick)")
    p.add_argument("--jobs", type=int, default=1, metavar="J",
                   help="local worker processes (-1: all cores; default 1; at most the "
                        "cores; ignored with --scheduler)")
    p.add_argument("--scheduler", metavar="ADDR",
                   help="Dask scheduler address (tcp://HOST:PORT) instead of local processes")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--max-time", type=_duration, default=3600.0, metavar="TIME",
                   help="refuse work whose estimated total time exceeds this: seconds, or with "
                        "a unit (90s, 10min, 2h; default 1h); sweep estimates all its runs "
                        "first, reproduce each batch added to the ones before it (the "
                        "experiments finished keep their sections)")


def _cmd_run(args) -> int:

    from .config import Config, check_overridden, read_toml
    from .outdir import check_output
    from .pipeline import run

    opts = {k: v for k, v in vars(args).items()
            if k not in ("command", "config", "out", "no_figure", "overwrite", "func",
                         "save_ptu", "fov")}
    save_ptu = getattr(args, "save_ptu", None)
    if save_ptu is not None and (not str(save_ptu).strip()  # "" wrote nothing, saying nothing
                                 or Path(save_ptu).name in ("", ".", "..")
                                 or Path(save_ptu).is_dir()):  # ('.': a traceback, an audit)
        from .errors import ConfigError

        raise ConfigError(f"--save-ptu must name a file (FILE.ptu), not {save_ptu!r}")
    if save_ptu:
        from .outfiles import check_files
        from .pipeline.export import ptu_companions

        ptu_files = [save_ptu, *ptu_companions(save_ptu)]
        check_files(ptu_files, args.overwrite, outside=args.out)  # refuse before any work
    check_output(args.out, args.overwrite)  # refuse before any work
    base = read_toml(args.config) if args.config else {}
    from .config import unchosen_options

    base, unchosen = unchosen_options(base, opts, str(args.config))
    cfg = Config.from_dict(base, **opts)  # (a TOML's code-length, overridden by --code-length)
    check_overridden(base, opts, args.config)  # (after: the run's own errors said as such)
    if save_ptu and "hadamard" in cfg.patterns and cfg.hadamard_realisation == "differential":
        from .errors import ConfigError

        # (its +-1 rows went into the photon rates: a traceback, "lam < 0", an audit)
        raise ConfigError("--save-ptu writes one marker block per pattern, a DMD frame of "
                          "mirror states in [0, 1]: --hadamard-realisation differential shows "
                          "each pattern as two frames, which 'spslidar reconstruct' does not "
                          "read; use --hadamard-realisation shifted")
    if save_ptu:
        from .outfiles import write_files
        from .pipeline import measure, reconstruct
        from .pipeline.export import (
            check_ptu_photons,
            write_measurement_arrays,
            write_measurement_ptu,
        )

        meas = measure(base, **opts)  # (the file's keys and the flags: what was asked)
        check_ptu_photons(meas)  # before the solve
        result = reconstruct(meas)
        if cfg.detector not in ("linear", "gmapd"):  # (its dead time and jitter were
            # silently left out; the GMAPD's detections are drawn event by event)
            result.warnings.append(
                f"--save-ptu draws the file's photons by linear Poisson counting from the "
                f"expected counts: --detector {cfg.detector}'s dead time, jitter and "
                f"afterpulses are in run's own depth map, not in {save_ptu}")
        if cfg.noiseless:  # (the file's photons are drawn: a reconstruct read 0.044 m for
            # run's noiseless 0.0015 m without a word, an outside audit of 2026-11-30)
            result.warnings.append(
                f"--save-ptu draws the file's photons (Poisson counts from the expected "
                f"ones): --noiseless is in run's own depth map, not in {save_ptu}")
        info: dict = {}

        def write(tmps) -> None:  # under temporary names, moved into place all together
            info.update(write_measurement_ptu(meas, tmps[0]))
            write_measurement_arrays(meas, tmps[0], paths=tmps[1:])

        write_files(ptu_files, write, args.overwrite)
        _WRITTEN.extend(ptu_files)
        print(f"wrote {save_ptu}: {info['photons']} photons, {info['records']} T3 records; "
              f"the patterns shown and the code in {ptu_files[1]} and {ptu_files[2]}")
    else:
        # (given as the file's keys and the flags, as cfg was made: the pipeline then knows
        # what was asked, an explicit --nonneg it drops said there, as for any caller)
        result = run(base, **opts)
    for note in unchosen:
        result.warnings.append(note)
        said = result.metrics.setdefault("warnings", [])
        if said is not result.warnings:
            said.append(note)
    say_warnings(result.warnings)
    warn_fov(args.fov)
    out = result.save(args.out, figure=not args.no_figure, overwrite=args.overwrite,
                      fov_deg=args.fov, option="--out", replace="--overwrite")
    _WRITTEN.append(f"{out}/")
    print(result.summary())
    print(f"wrote {out}/: {' '.join(_written(out))}")
    return 0


def _cmd_reproduce(args) -> int:
    from .experiments.reproduce import reproduce_main

    return reproduce_main(args.experiment, args.out, quick=args.quick, trials=args.trials,
                          jobs=args.jobs, scheduler=args.scheduler,
                          progress=not args.no_progress, max_time=args.max_time)


def _cmd_sweep(args) -> int:
    """``spslidar sweep``: exit status 0 when every run succeeded, 1 when the work did not
    complete (some runs failed, or a worker process was killed), 2 on bad input."""
    from .experiments.sweep import sweep_main
    from .experiments.sweep.command import SweepIncomplete
    from .experiments.sweep.engine import WorkerLost

    try:
        return 1 if sweep_main(args.config, args.out, jobs=args.jobs, scheduler=args.scheduler,
                               progress=not args.no_progress, max_time=args.max_time,
                               overwrite=args.overwrite) else 0
    except (WorkerLost, SweepIncomplete) as exc:  # (a killed worker was joblib's 30-line
        # traceback: an audit of 2026-11-29; a results.csv a full disk refused exited 2, as
        # bad input: an outside audit of 2026-12-03) one line; the work did not complete, as
        # where runs failed
        print(f"spslidar sweep: {exc}", file=sys.stderr)
        return 1


COMMANDS = {"run": _cmd_run, "reconstruct": cmd_reconstruct, "calibrate": cmd_calibrate,
            "snr": cmd_snr, "check": cmd_check, "inspect": cmd_inspect,
            "reproduce": _cmd_reproduce, "sweep": _cmd_sweep}


def _load_plugins(argv: list[str]) -> list[str]:
    """Import the plugins of ``--plugin MODULE`` (before the command, repeatable) and of
    ``SPSLIDAR_PLUGINS`` before the parser is built, so their stages are choices with flags;
    return ``argv`` without the ``--plugin`` options (:mod:`spslidar.plugins`)."""
    from .plugins import load_plugins

    specs, rest, i = [], [], 0
    while i < len(argv):
        a = argv[i]
        if a == "--plugin" and i + 1 < len(argv):
            specs.append(argv[i + 1])
            i += 2
            continue
        if a.startswith("--plugin="):
            specs.append(a.split("=", 1)[1])
        else:
            rest.append(a)
        i += 1
    load_plugins()  # the environment's
    load_plugins(specs, export=True)  # and --plugin's, for worker processes too
    return rest




def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit status (0 success, 2 bad input)."""
    if argv is not None:
        # a call inside a Python session: its streams are the session's (swapping the
        # process's streams from two threads' calls left one swapped for good, and a None
        # stream, pythonw's, was an AttributeError: a review of 2026-11-30)
        return _main(argv)
    out, err = sys.stdout, sys.stderr
    sys.stdout = _Tolerant(out, True) if out is not None else out
    sys.stderr = _Tolerant(err, True) if err is not None else err
    try:
        status = _main(argv)
        for stream in (sys.stdout, sys.stderr):
            if stream is not None:
                stream.flush()
        return status
    finally:
        sys.stdout, sys.stderr = out, err


def _main(argv: list[str] | None = None) -> int:
    """:func:`main` with its streams in place."""
    from .errors import SpslidarError as _Bad

    own = argv is None  # a process of its own, not a call inside a Python session
    from .interrupts import EXIT_INTERRUPTED, Stopper, Terminated

    # (a signal while the plugins load and the parser is built, before the command's own
    # handlers, was a KeyboardInterrupt traceback or an exit without a word, an audit)
    early = Stopper(lambda terminated: f"spslidar: {'terminated' if terminated else 'interrupted'}"
                                       f"; nothing was written", None)
    if own:
        early.install()
    try:
        try:
            # (a plugin's replacement of a built-in stage was said as a raw two-line Python
            # warning, its source line included, an audit of 2026-11-29)
            with warnings.catch_warnings():
                warnings.showwarning = said = _OneLineWarnings("--plugin")
                argv = _load_plugins(sys.argv[1:] if argv is None else list(argv))
            SAID_AT_LOAD.clear()
            SAID_AT_LOAD.update(said.first.values())
            parser = build_parser()  # (a plugin's option whose flag is taken: one line)
        except _Bad as exc:
            print(f"spslidar: error: {one_line(exc)}", file=sys.stderr)
            return EXIT_BAD_INPUT
        args, extra = parser.parse_known_args(argv)
    except KeyboardInterrupt as exc:
        early.say(isinstance(exc, Terminated))
        return exc.status if isinstance(exc, Terminated) else EXIT_INTERRUPTED
    if extra:  # said by the command's own parser ("spslidar: error:" named no command)
        commands = next((a.choices for a in parser._actions
                         if isinstance(a, argparse._SubParsersAction)), {})
        (commands.get(getattr(args, "command", None)) or parser).error(
            f"unrecognized arguments: {' '.join(extra)}")
    _WRITTEN.clear()
    if args.command is None:
        parser.print_help()
        return EXIT_BAD_INPUT
    import signal

    from .errors import SpslidarError
    from .interrupts import (
        EXIT_INTERRUPTED,
        STOP_GRACE_S,
        Stopper,
        Terminated,
        kill_pool,
        quiet_resource_tracker,
        stop_pool,
    )

    def line(terminated: bool) -> str:
        if args.command in ("sweep", "reproduce"):
            # (a sweep stopped before its first run removes the folder it made, or leaves
            # a user's empty folder empty: the line said runs were cached; and a folder of
            # the user's files it had not claimed, its marker absent, was called a cache:
            # an outside audit of 2026-12-03)
            from .outdir import MARKER
            from .outwrite import read_marker

            out = Path(args.out)
            kept = (out.is_dir() and read_marker(out) is not None
                    and any(f.is_file() and f.name != MARKER for f in out.rglob("*")))
            done = ("the runs that finished are cached: run it again to resume" if kept
                    else "nothing was written")
        elif _WRITTEN:  # (--save-ptu's files were written, and the line said nothing was)
            done = f"{', '.join(_WRITTEN)} had been written, the rest was not"
        else:
            done = "nothing was written"
        return f"spslidar {args.command}: {'terminated' if terminated else 'interrupted'}; {done}"

    stopper = Stopper(line, STOP_GRACE_S if own else None)
    if own:
        quiet_resource_tracker()
        stopper.install()
    else:  # SIGTERM in a session: the clean-up of Ctrl-C, no watchdog
        stopper.install((signal.SIGTERM,))
    try:
        shown = _OneLineWarnings(args.command)
        with warnings.catch_warnings():  # a library's warning: one line, not its source line
            warnings.showwarning = shown
            try:
                status = COMMANDS[args.command](args)
            finally:
                shown.close()
        if own:
            stop_pool()
        return status
    except SpslidarError as exc:
        print(f"spslidar {args.command}: error: {one_line(exc)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as exc:
        where = exc.filename or ""
        out = getattr(args, "out", None)
        if not where and out:  # (a full disk said "File too large" and nothing more, an audit)
            where = (f"while writing --out {out} (written under a temporary name: what was "
                     f"there before is as it was)")
        why = exc.strerror or str(exc)
        if exc.errno is None and " requested and " in why and " written" in why:
            # (NumPy's short write on a full disk: "1024 requested and 496 written", an audit
            # of 2026-12-03)
            why = f"the disk is full ({why})"
        print(one_line(f"spslidar {args.command}: error: {why}: "
                       f"{where}".rstrip(": ")), file=sys.stderr)
        return EXIT_BAD_INPUT
    except MemoryError as exc:
        # (an allocation past what the machine had free was a NumPy traceback, exit 1: an
        # audit of 2026-11-29 met it under --save-ptu, the GMAPD, a 0-150 m gate and a
        # reconstruct of large patterns; the commands write their outputs only when complete)
        what = str(exc).splitlines()[0] if str(exc) else "an allocation failed"
        less = ("fewer patterns or a narrower --range-gate"
                if args.command in ("reconstruct", "calibrate") else
                "lower --size, the pattern count or the range gate, or give --max-memory to "
                "have a run that will not fit refused before the work")
        kept = f" ({', '.join(_WRITTEN)} had been written)" if _WRITTEN else ""
        print(f"spslidar {args.command}: error: out of memory ({what}): the machine has less "
              f"memory free than this needs; {less}{kept}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except (Exception, SystemExit) as exc:
        # a plugin's stage raising, in one line; a stage's `raise SystemExit(0)` or
        # `sys.exit()` too, wherever it is (it ended `run` with exit 0, writing nothing and
        # saying nothing: an outside audit of 2026-12-02; no command of spslidar's exits
        # this way, argparse's exits come before the command)
        from .errors import raised_text
        from .plugins import raised_in_plugin, where

        place = raised_in_plugin(exc)
        if place is None and not isinstance(exc, SystemExit):
            raise  # spslidar's own error: its traceback, for a bug report
        who = "a stage" if place is None else "a plugin's stage"
        print(f"spslidar {args.command}: error: {who} raised {raised_text(exc)}"
              f"{where(exc) if place is None else place}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt as exc:
        # a sweep's result generator, held by this exception's traceback, is closed when the
        # exception goes; joblib then warns of the tasks it cancelled, after this command's
        # one line and with its source line: the line below says it (in a process of its
        # own only: in a session the filter stayed, and hid the user's own joblib's: an
        # audit of 2026-11-30)
        if own:
            warnings.filterwarnings("ignore",
                                    message=r".*tasks .*(cancelled|not used)\. You could",
                                    category=UserWarning)
        terminated = isinstance(exc, Terminated)
        if own:
            kill_pool()
        stopper.say(terminated)
        return exc.status if terminated else EXIT_INTERRUPTED
    finally:
        if own:  # the handlers stay until the process ends
            stopper.exiting = True
        else:
            stopper.restore()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
