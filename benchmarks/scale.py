"""Scaling of the default chain with image size and pattern kind.

N in {64, 128, 256, 512} x pattern kind (Gaussian and Bernoulli where their dense (M, Q) matrix
fits, Hadamard in sequency / cake-cutting / random order, scrambled Hadamard) x compression
(10 %, 25 %): time per stage, peak memory (the child process's maximum RSS) and depth RMSE,
printed as a Markdown table with a line on how the cost grows with N; ``--out FILE`` also
writes it to ``FILE`` and the rows to ``FILE`` with the suffix ``.json`` (by default nothing is
written: a plain run overwrote the committed ``benchmarks/scale.md`` until an audit of
2026-11-28; ``--out benchmarks/scale.md`` regenerates it).

Each point runs in its own subprocess under an address-space limit (``--limit-gb``, default
10, lowered to the limit this process runs under if that is lower), one at a time (the big
points need the whole machine); a point the memory guard refuses is listed as refused with the
guard's reason, a point killed by the limit as such. Sizes, kinds and compressions that no
point could run with (``--sizes 100 --kinds hadamard``, ``--compressions 2``) are refused
before the first point.

    python benchmarks/scale.py                 # the full grid (~20 min on 2 cores)
    python benchmarks/scale.py --quick         # 64 and 128 only
    python benchmarks/scale.py --sizes 256 --kinds hadamard scrambled-hadamard
    python benchmarks/scale.py --out benchmarks/scale.md   # the committed table
"""

from __future__ import annotations

import json
import math
import os
import resource
import subprocess
import sys
import time
from pathlib import Path

import _cli

#: (label, config overrides)
KINDS = {
    "gaussian": {"patterns": "gaussian"},
    "bernoulli": {"patterns": "bernoulli"},
    "hadamard": {"patterns": "hadamard", "hadamard_order": "sequency"},
    "hadamard-cake": {"patterns": "hadamard", "hadamard_order": "cake-cutting"},
    "hadamard-random": {"patterns": "hadamard", "hadamard_order": "random"},
    # (sequency, as the "hadamard" row: it took the default order, cake-cutting, and differed
    # from that row in more than the realisation, an audit of 2026-11-29)
    "hadamard-diff": {"patterns": "hadamard", "hadamard_order": "sequency",
                      "hadamard_realisation": "differential"},
    "scrambled-hadamard": {"patterns": "scrambled-hadamard"},
}
DEFAULT_KINDS = ("gaussian", "bernoulli", "hadamard", "hadamard-cake", "hadamard-random",
                 "scrambled-hadamard")
#: largest N at which the dense kinds run by default (256 at 10 %: 82 s and 5.6 GB measured)
DENSE_MAX = 128
#: the kinds run at 512 (the others add nothing there but minutes)
BIG_KINDS = ("hadamard", "scrambled-hadamard")

CHILD = r"""
import json, resource, sys, time
t0 = time.perf_counter()
from spslidar.errors import SpslidarError
from spslidar.pipeline.chain import measure, reconstruct
cfg = json.loads(sys.argv[1])
try:
    meas = measure(**cfg)
    res = reconstruct(meas)
except SpslidarError as exc:
    print(json.dumps({"status": "refused", "message": str(exc)}))
    sys.exit(0)
t = res.timing
print(json.dumps({
    "status": "ok", "rmse": res.metrics["depth_rmse_m"],
    "setup": t["scene"] + t["setup"], "simulate": t["simulate"], "qcr": t["qcr"],
    "solve": t["solve"], "depth": t["depth"], "total": time.perf_counter() - t0,
    "peak_gb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024 / 1e9,
    "estimate_gb": res.metrics["estimate"].get("memory_gb"),
    "iterations": res.metrics["solver_info"].get("iterations")}))
"""


def address_limit(limit_gb: float) -> int:
    """``limit_gb`` in bytes, lowered to this process's own address-space limits (soft and
    hard), which a child cannot raise (under a shell's ``ulimit -v 4000000`` the 10 GB default
    made every point fail with ``SubprocessError: Exception occurred in preexec_fn``)."""
    lim = int(limit_gb * 1e9)
    for cur in resource.getrlimit(resource.RLIMIT_AS):
        if cur != resource.RLIM_INFINITY:
            lim = min(lim, cur)
    return lim


def run_point(cfg: dict, limit_gb: float, timeout: float) -> dict:
    """One configuration in a fresh interpreter under ``RLIMIT_AS = limit_gb`` (at most this
    process's own limit)."""
    lim = address_limit(limit_gb)

    def limit():  # pragma: no cover - runs in the child
        resource.setrlimit(resource.RLIMIT_AS, (lim, lim))

    t0 = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, "-c", CHILD, json.dumps(cfg)], capture_output=True,
                              text=True, preexec_fn=limit, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"status": f"timeout {timeout:.3g} s"}  # (0.5 read "timeout 0 s")
    wall = time.perf_counter() - t0
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
    if proc.returncode != 0 or not lines:
        tail = (proc.stderr.strip().splitlines() or ["?"])[-1]
        # (a BLAS library that cannot map its buffers under the limit is out of memory too)
        short = ("MemoryError" in proc.stderr or "OpenBLAS" in proc.stderr
                 or "cannot allocate" in proc.stderr.lower())
        why = "out of memory" if short or proc.returncode < 0 else tail
        return {"status": f"failed ({why[:60]})", "wall": wall}
    out = json.loads(lines[-1])
    out["wall"] = wall
    return out


def points(sizes, kinds, compressions):
    for n in sizes:
        for kind in kinds:
            spec = KINDS[kind]
            if spec["patterns"] in ("gaussian", "bernoulli") and n > DENSE_MAX:
                continue
            if n >= 512 and kind not in BIG_KINDS:
                continue
            for c in compressions:
                if n >= 512 and c > 0.1 and kind != "hadamard":
                    continue
                yield n, kind, c, {"size": n, "compression": c, **spec}


def table(rows: list[dict]) -> str:
    head = ("| N | patterns | M/Q | setup s | simulate s | QCR s | solve s | process s | "
            "peak GB | est. GB | RMSE m |")
    lines = [head, "|" + " --- |" * 11]
    for r in rows:
        if r["status"] != "ok":
            why = f" ({_one_line(r['message'])})" if r.get("message") else ""
            lines.append(f"| {r['N']} | {r['kind']} | {r['c']:.0%} | {r['status']}{why} |"
                         + " |" * 7)
            continue
        lines.append(
            f"| {r['N']} | {r['kind']} | {r['c']:.0%} | {r['setup']:.2f} | {r['simulate']:.2f} | "
            f"{r['qcr']:.2f} | {r['solve']:.2f} | {r['wall']:.1f} | {r['peak_gb']:.2f} | "
            f"{r['estimate_gb']:.2f} | {r['rmse']:.4f} |")
    return "\n".join(lines)


def _one_line(text: str) -> str:
    """A message fit for a table cell: one line, no ``|``."""
    return " ".join(str(text).split()).replace("|", "/")


def check_points(grid: list[tuple]) -> None:
    """Refuse, before the first point, a grid whose configurations spslidar's ``Config``
    refuses (a size that is not a power of two for the Hadamard kinds, a compression outside
    (0, 1], ...) or that is empty; raises ``ValueError`` (a ``ConfigError``)."""
    from spslidar.config import Config

    if not grid:
        raise ValueError("no point to run: every size is above what the chosen kinds run at "
                         f"(Gaussian and Bernoulli up to {DENSE_MAX}, at 512 only "
                         f"{', '.join(BIG_KINDS)}), or --quick left no size (64 and 128 only)")
    for n, kind, c, cfg in grid:
        try:
            Config(**cfg)
        except ValueError as exc:
            raise ValueError(f"N={n} {kind} {c:.0%}: {exc}") from None


def growth(rows: list[dict], kind: str = "hadamard", c: float = 0.1) -> str:
    """Fitted exponent of the solve time and peak memory in N for one kind."""
    pts = [r for r in rows if r["kind"] == kind and r["c"] == c and r["status"] == "ok"]
    if len(pts) < 2:
        return ""
    pts.sort(key=lambda r: r["N"])
    a, b = pts[0], pts[-1]
    ln = math.log(b["N"] / a["N"])
    e_t = math.log(b["solve"] / a["solve"]) / ln
    e_s = math.log(b["simulate"] / a["simulate"]) / ln
    e_m = math.log(b["peak_gb"] / a["peak_gb"]) / ln
    return (f"{kind} at {c:.0%}, N {a['N']} -> {b['N']}: solve time ~ N^{e_t:.2f}, simulation "
            f"~ N^{e_s:.2f}, peak memory ~ N^{e_m:.2f} (Q = N^2; Q log Q per column would be "
            f"N^2.0-2.2)")


def main(argv=None) -> int:
    ap = _cli.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sizes", type=_cli.positive_int, nargs="+", default=[64, 128, 256, 512],
                    metavar="N", help="image sides N (default: 64 128 256 512; the Hadamard "
                    "kinds need powers of two)")
    ap.add_argument("--kinds", nargs="+", default=list(DEFAULT_KINDS), choices=sorted(KINDS),
                    metavar="KIND", help=f"pattern kinds, of {', '.join(sorted(KINDS))} "
                    f"(default: {' '.join(DEFAULT_KINDS)})")
    ap.add_argument("--compressions", type=_cli.fraction, nargs="+", default=[0.1, 0.25],
                    metavar="M/Q", help="pattern ratios in (0, 1] (default: 0.1 0.25)")
    ap.add_argument("--quick", action="store_true", help="N = 64 and 128 only")
    ap.add_argument("--limit-gb", type=_cli.positive_float, default=10.0,
                    help="address-space limit per point in GB (default 10; at most the limit "
                         "this process runs under)")
    ap.add_argument("--timeout", type=_cli.positive_float, default=600.0,
                    help="seconds per point (default 600)")
    ap.add_argument("--out", type=_cli.out_file, default=None, metavar="FILE",
                    help="also write the Markdown table to FILE and the rows to FILE's .json "
                         "(default: none, the table is printed only; --out benchmarks/scale.md "
                         "regenerates the committed table)")
    args = ap.parse_args(argv)
    sizes = [s for s in args.sizes if s <= 128] if args.quick else args.sizes
    grid = list(points(sizes, args.kinds, args.compressions))
    check_points(grid)
    lim = address_limit(args.limit_gb)
    if lim < int(args.limit_gb * 1e9):
        print(f"{Path(sys.argv[0]).name}: the address-space limit per point is {lim / 1e9:.2f} "
              f"GB, this process's own, below --limit-gb {args.limit_gb:g}", file=sys.stderr)
    rows = []
    t_all = time.perf_counter()
    for n, kind, c, cfg in grid:
        r = run_point(cfg, args.limit_gb, args.timeout)
        r.update(N=n, kind=kind, c=c)
        rows.append(r)
        state = (f"{r['wall']:.1f} s, {r['peak_gb']:.2f} GB, RMSE {r['rmse']:.4f} m"
                 if r["status"] == "ok" else r["status"])
        if r.get("message"):
            state += f" ({_one_line(r['message'])})"
        print(f"N={n} {kind} {c:.0%}: {state}", file=sys.stderr, flush=True)
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    grown = growth(rows)  # (blank with one size or no sequency Hadamard: then left out)
    text = (f"{table(rows)}\n\n" + (f"{grown}\n\n" if grown else "")
            + f"spslidar defaults otherwise (camera scene, "
            f"m-sequence of 16383 bits, QCR, FISTA + TV); 'process s' is the whole child process "
            f"(imports included); peak = maximum RSS; {os.cpu_count()} CPUs, load average "
            f"{load:.1f} at the end; grid time {time.perf_counter() - t_all:.0f} s.\n")
    print(text)
    if args.out:
        Path(args.out).write_text(text)
        with open(Path(args.out).with_suffix(".json"), "w") as fh:
            json.dump(rows, fh, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(_cli.run(main))
