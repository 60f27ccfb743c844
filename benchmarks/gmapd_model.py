"""The GMAPD's renewal model over dead times from half a code period to many periods, against
the dense Markov chain of Rapp et al. (2019), same process.

What an engineer with an InGaAs detector (dead times of microseconds) asks before a
``run --detector gmapd``: how long does the model of its histograms take when the dead time is
many code periods long? :func:`spslidar.detectors.pileup.renewal_detection` solves each
pattern's stationary detection histogram by sweeping the unrolled time evolution of the
expectation with Anderson mixing, each sweep over as many periods as the dead time spans. The
peer is the textbook method, the chain of each detection's bin modulo the period as a dense
``L x L`` transition matrix solved for its stationary law
(:func:`spslidar.detectors.markov.chain_detection`, one dense solve per row): both must give
the same histograms to 1e-8 of their largest bin (checked; the script exits 1 otherwise).

The flux: an m-sequence of ``--bins`` bits at 10 GHz (100 ps bins), each row the code at its
own delay plus a tenth of its mean as background, scaled to ``--per-dead`` photons per dead
time (a GMAPD's operating point), ``--rows`` rows (a block of patterns). Time is the wall
clock of one solve of all rows (the faster of ``--repeat``). Run::

    python benchmarks/gmapd_model.py [--bins 1023] [--rows 64] [--per-dead 3]
        [--dead-times 5e-8,5e-7,2e-6,5e-6] [--repeat 1] [--out table.md]
"""

from __future__ import annotations

import argparse
import time

import _cli
import numpy as np

from spslidar.codes.sequences import make_code
from spslidar.detectors.markov import chain_detection
from spslidar.detectors.pileup import renewal_detection

BIN = 100e-12  # 10 GHz


def seconds_list(text: str) -> list[float]:
    """``type=`` of a comma-separated list of dead times of at least one bin."""
    try:
        out = [float(v) for v in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected seconds, comma-separated, got {text!r}") from None
    if not out or not all(np.isfinite(v) and v >= BIN and abs(v / BIN - round(v / BIN)) < 1e-6
                          for v in out):
        raise argparse.ArgumentTypeError(f"expected dead times of whole 100 ps bins (the "
                                         f"chain's), got {text}")
    return out


def flux(n_bins: int, rows: int, per_dead: float, dead_bins: float) -> np.ndarray:
    """``rows`` code-modulated fluxes (photons per bin per period), ``per_dead`` photons per
    dead time on average."""
    code = make_code("mseq", n_bins, 0.5, np.random.default_rng(0)).astype(float)
    delays = np.random.default_rng(1).integers(0, n_bins, rows)
    mu = np.stack([np.roll(code, k) for k in delays]) + 0.1
    return mu / mu.mean(axis=1, keepdims=True) * per_dead / dead_bins


def timed(repeat: int, fn, *args, **kwargs):
    """(seconds, the faster of ``repeat`` solves; the solve's output)."""
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn(*args, **kwargs)
        best = min(best, time.perf_counter() - t0)
    return best, out


def main(argv=None) -> int:
    p = _cli.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--bins", type=_cli.positive_int, default=1023, metavar="L",
                   help="bits of the m-sequence, 2^n - 1 (default 1023)")
    p.add_argument("--rows", type=_cli.positive_int, default=64, metavar="B",
                   help="patterns solved together (default 64)")
    p.add_argument("--per-dead", type=_cli.positive_float, default=3.0, metavar="N",
                   help="photons per dead time (default 3)")
    p.add_argument("--dead-times", type=seconds_list, default=[5e-8, 5e-7, 2e-6, 5e-6],
                   metavar="S,S,...", help="dead times in seconds, whole 100 ps bins "
                   "(default 5e-8,5e-7,2e-6,5e-6)")
    p.add_argument("--repeat", type=_cli.positive_int, default=1, metavar="K",
                   help="solves of each method, the fastest kept (default 1)")
    p.add_argument("--out", type=_cli.out_file, metavar="FILE",
                   help="also write the Markdown table here")
    args = p.parse_args(argv)
    if args.bins + 1 & args.bins or args.bins < 3:
        p.error(f"--bins must be 2^n - 1 (an m-sequence's length), got {args.bins}")

    lines = [
        f"m-sequence of {args.bins} bits at 10 GHz, {args.rows} rows, {args.per_dead:g} "
        f"photons per dead time; the two agree to 1e-8 of their largest bin",
        "",
        "| dead time | periods per dead time | renewal model [s] (sweeps) "
        "| dense Markov chain [s] | ratio |",
        "| --- | --- | --- | --- | --- |",
    ]
    for dead in args.dead_times:
        d = round(dead / BIN)
        mu = flux(args.bins, args.rows, args.per_dead, d)
        ours, (h, info) = timed(args.repeat, renewal_detection, mu, d, return_info=True)
        peer, ref = timed(args.repeat, chain_detection, mu, d)
        if not np.allclose(h, ref, rtol=0, atol=1e-8 * ref.max()):
            raise SystemExit(f"gmapd_model.py: the two solves differ at a dead time of "
                             f"{dead:g} s (by {np.abs(h - ref).max() / ref.max():.2g})")
        lines.append(f"| {dead * 1e9:g} ns | {d / args.bins:.2g} | {ours:.2f} "
                     f"({info['sweeps']}) | {peer:.2f} | {ours / peer:.3f} |")
    return _cli.emit(lines, args.out)


if __name__ == "__main__":
    raise SystemExit(_cli.run(main))
