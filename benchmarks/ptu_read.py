"""Reading a PTU acquisition: spslidar's reader against ptufile's own decoding, same process.

What a lab asks before it records an hour of photons: how long does ``spslidar reconstruct``
take to read the file, and how much memory? The peer is what a user would write with
``ptufile`` alone: decode every record (``PtuFile.decode_records``, a record array of 12 bytes
a record), then histogram each marker block's photons over the code period with NumPy.
spslidar's reader (:func:`spslidar.io.read_ptu_histograms`) decodes in chunks and adds each
chunk to the histograms, so its memory is the histograms' and one chunk's, whatever the
file's length. Both must give the same histograms (checked, exactly). Then ``spslidar
inspect``'s pass (:func:`spslidar.io.scan_ptu`: photons per channel, markers per input, the
blocks and the gaps between detections) against the same ``decode_records`` counted in NumPy,
the counts checked equal.

The file is written here (``write_ptu_t3_stream``, in chunks): ``--patterns`` marker blocks of
equal dwell, photons spread uniformly over each block's syncs and over the code's
``--bins`` bins, HydraHarp v2 T3 records (or ``--record-type PicoHarpT3``). Time is the wall
clock of each read (the faster of ``--repeat`` reads, the file in the page cache after the
first); memory is the peak of ``tracemalloc`` during the read (NumPy's and ptufile's arrays
are traced; the interpreter's own baseline is not counted). Run::

    python benchmarks/ptu_read.py [--records 2e7] [--patterns 1024] [--bins 1023]
        [--record-type HydraHarp2T3] [--repeat 2] [--out table.md]
"""

from __future__ import annotations

import gc
import tempfile
import time
import tracemalloc
from pathlib import Path

import _cli
import numpy as np

from spslidar.io import read_ptu_histograms, scan_ptu, write_ptu_t3_stream

BIT_RATE = 10e9


def write_file(path: Path, n_photons: int, n_patterns: int, n_bins: int, record_type: str,
               seed: int = 0, chunk: int = 1_000_000) -> int:
    """A T3 file of ``n_photons`` photons in ``n_patterns`` marker blocks; records written."""
    rng = np.random.default_rng(seed)
    dwell = 20_000  # code periods per pattern (2 ms at a 1023-bit code and 10 GHz)
    per_block = np.full(n_patterns, n_photons // n_patterns)
    per_block[: n_photons % n_patterns] += 1

    def chunks():
        for b in range(n_patterns):
            start = b * dwell
            yield (np.array([start]), np.array([0]), 0, np.array([1]))  # the block's marker
            left = int(per_block[b])
            while left:
                n = min(left, chunk)
                nsync = np.sort(rng.integers(start, start + dwell, n))
                yield nsync, rng.integers(0, n_bins, n), 0, None
                left -= n

    return write_ptu_t3_stream(path, chunks(), resolution_s=1 / BIT_RATE,
                               sync_rate_hz=BIT_RATE / n_bins, record_type=record_type)


def read_spslidar(path: Path, n_bins: int) -> np.ndarray:
    return read_ptu_histograms(path, n_bins, marker=1).histograms


def read_ptufile(path: Path, n_bins: int) -> np.ndarray:
    """The peer: every record decoded by ptufile, then each block's histogram in NumPy."""
    import ptufile

    with ptufile.PtuFile(path) as f:
        rec = f.decode_records()
    marker = (rec["channel"] < 0) & ((rec["marker"] & 1) != 0)
    starts = np.flatnonzero(marker)
    photon = rec["channel"] >= 0
    block = np.cumsum(marker) - 1  # the block of each record (-1 before the first marker)
    keep = photon & (block >= 0)
    flat = block[keep].astype(np.int64) * n_bins + rec["dtime"][keep]
    return np.bincount(flat, minlength=starts.size * n_bins).reshape(starts.size, n_bins)


def scan_spslidar(path: Path, n_bins: int) -> dict:
    """``spslidar inspect``'s one pass: photons per channel, markers per input, blocks."""
    got = scan_ptu(path)
    return {"photons": got["photons"], "markers": got["markers"]}


def scan_ptufile(path: Path, n_bins: int) -> dict:
    """The peer: every record decoded by ptufile, then the photons per channel and the
    markers per input counted in NumPy."""
    import ptufile

    with ptufile.PtuFile(path) as f:
        rec = f.decode_records()
    ch = rec["channel"]
    per = np.bincount(ch[ch >= 0].astype(np.int64))
    mk = rec["marker"][(ch < 0) & (rec["marker"] != 0)]
    markers = {k: int(np.count_nonzero(mk & (1 << (k - 1)))) for k in (1, 2, 3, 4)}
    return {"photons": {int(c): int(n) for c, n in enumerate(per) if n},
            "markers": {k: n for k, n in markers.items() if n}}


def measure(fn, path: Path, n_bins: int, repeat: int) -> tuple[float, float, np.ndarray]:
    """(seconds, the faster of ``repeat`` reads; peak traced MB; the histograms)."""
    best, peak, out = float("inf"), 0.0, None
    for _ in range(repeat):
        out = None
        gc.collect()
        tracemalloc.start()
        t0 = time.perf_counter()
        out = fn(path, n_bins)
        best = min(best, time.perf_counter() - t0)
        peak = max(peak, tracemalloc.get_traced_memory()[1] / 1e6)
        tracemalloc.stop()
    return best, peak, out


def main(argv=None) -> int:
    p = _cli.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--records", type=_cli.positive_float, default=2e7, metavar="N",
                   help="photons in the file (default 2e7: 80 MB of records)")
    p.add_argument("--patterns", type=_cli.positive_int, default=1024, metavar="M",
                   help="marker blocks (default 1024)")
    p.add_argument("--bins", type=_cli.positive_int, default=1023, metavar="L",
                   help="bins per code period (default 1023)")
    p.add_argument("--record-type", default="HydraHarp2T3",
                   choices=("HydraHarp2T3", "HydraHarpT3", "PicoHarpT3", "GenericT3"))
    p.add_argument("--repeat", type=_cli.positive_int, default=2, metavar="K",
                   help="reads of each method, the fastest kept (default 2)")
    p.add_argument("--out", type=_cli.out_file, metavar="FILE",
                   help="also write the Markdown table here")
    args = p.parse_args(argv)
    if args.record_type == "PicoHarpT3" and args.bins > 4096:
        p.error("a PicoHarp T3 record holds dtime below 4096: --bins 4096 or fewer")

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "acq.ptu"
        t0 = time.perf_counter()
        n_rec = write_file(path, int(args.records), args.patterns, args.bins, args.record_type)
        wrote = time.perf_counter() - t0
        size = path.stat().st_size / 1e6
        ours = measure(read_spslidar, path, args.bins, args.repeat)
        peer = measure(read_ptufile, path, args.bins, args.repeat)
        scan = measure(scan_spslidar, path, args.bins, args.repeat)
        scan_peer = measure(scan_ptufile, path, args.bins, args.repeat)
    if not np.array_equal(np.asarray(ours[2], dtype=np.int64), peer[2]):
        raise SystemExit("ptu_read.py: the two readers' histograms differ")
    if scan[2] != scan_peer[2]:
        raise SystemExit("ptu_read.py: the two scans' counts differ")
    rate = n_rec / ours[0] / 1e6
    lines = [
        f"{args.record_type}, {n_rec:,} records ({size:.0f} MB; written in {wrote:.1f} s), "
        f"{args.patterns} blocks x {args.bins} bins; the histograms equal",
        "",
        "| reader | time [s] | records / s | peak memory [MB] |",
        "| --- | --- | --- | --- |",
        f"| spslidar `read_ptu_histograms` | {ours[0]:.2f} | {rate:.0f} M | {ours[1]:.0f} |",
        f"| ptufile `decode_records` + NumPy | {peer[0]:.2f} | {n_rec / peer[0] / 1e6:.0f} M "
        f"| {peer[1]:.0f} |",
        f"| ratio (spslidar / ptufile) | {ours[0] / peer[0]:.2f} | | {ours[1] / peer[1]:.2f} |",
        "",
        "What a file holds (`spslidar inspect`), the counts equal:",
        "",
        "| scan | time [s] | records / s | peak memory [MB] |",
        "| --- | --- | --- | --- |",
        f"| spslidar `scan_ptu` | {scan[0]:.2f} | {n_rec / scan[0] / 1e6:.0f} M | "
        f"{scan[1]:.0f} |",
        f"| ptufile `decode_records` + NumPy counts | {scan_peer[0]:.2f} | "
        f"{n_rec / scan_peer[0] / 1e6:.0f} M | {scan_peer[1]:.0f} |",
        f"| ratio (spslidar / ptufile) | {scan[0] / scan_peer[0]:.2f} | | "
        f"{scan[1] / scan_peer[1]:.2f} |",
    ]
    return _cli.emit(lines, args.out)


if __name__ == "__main__":
    raise SystemExit(_cli.run(main))
