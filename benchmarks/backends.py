"""Every backend and device on the GPU issue's workloads: time per stage, depth RMSE, speed-up.

Workloads (issue 13):

* ``64``: the default run (camera 64x64, 25 % Gaussian patterns, 16383-bit m-sequence, QCR,
  FISTA + TV 60 iterations, argmax);
* ``256``: 256x256, 10 % Gaussian patterns, otherwise the defaults;
* ``512h``: 512x512, 10 % Walsh-Hadamard patterns (skipped when no ``hadamard`` pattern kind
  is registered);
* ``sweep``: 64x64 default runs one after the other, seeds 0, 1, 2, ...: runs per second.

Each backend runs each workload with the same seed: once to warm up (imports, CUDA context,
kernel caches, the scene cache), then ``--repeat`` timed runs; the table gives the stage times
of the median run, its depth RMSE and its speed-up over the NumPy CPU run of the same workload.
NumPy is timed once without warm-up on the large workloads (``--numpy-repeat``). Random
streams differ between NumPy and the device backends (see :mod:`spslidar.backends`), so the
RMSEs agree statistically, not exactly. Every option is checked before the first run (a bad
one is one line on stderr and exit status 2), and a backend that cannot run here (no CUDA
device, torch or CuPy missing) is skipped with one line on stderr saying why.

Run::

    python benchmarks/backends.py [--backends numpy:cpu,torch:cuda,cupy:cuda]
        [--workloads 64,256,512h,sweep] [--repeat 5] [--sweep-runs 40] [--depth argmax]
        [--out table.md]
"""

from __future__ import annotations

import json
import os
import platform
import statistics
import sys
import time

import _cli

STAGES = ("scene", "setup", "simulate", "qcr", "solve", "depth", "to_host", "metrics")
WORKLOADS = {
    "64": {"size": 64},
    "256": {"size": 256, "compression": 0.1},
    "512h": {"size": 512, "compression": 0.1, "patterns": "hadamard"},
}


def _device_name() -> str:
    try:
        import torch

        if torch.cuda.is_available():
            return torch.cuda.get_device_name(0)
    except ImportError:
        pass
    return "no CUDA device"


def _one(backend: str, device: str, seed: int, **kw):
    from spslidar.pipeline.chain import run

    t0 = time.perf_counter()
    r = run(backend=backend, device=device, seed=seed, **kw)
    return r, time.perf_counter() - t0


def bench_workload(backend: str, device: str, kw: dict, repeat: int, warm: bool) -> dict:
    """Median of ``repeat`` runs (after one warm-up run when ``warm``)."""
    if warm:
        _one(backend, device, 0, **kw)
    runs = [_one(backend, device, 0, **kw) for _ in range(repeat)]
    runs.sort(key=lambda rt: rt[1])
    r, wall = runs[len(runs) // 2]
    return {"wall": wall, "walls": [w for _, w in runs], "rmse": r.depth_rmse,
            "stages": {s: r.timing.get(s, 0.0) for s in STAGES},
            "iterations": r.metrics["solver_info"]["iterations"]}


def bench_sweep(backend: str, device: str, n: int, **kw) -> dict:
    """Runs per second of ``n`` default 64x64 runs (with ``kw``), seeds 0..n-1 (after one
    warm-up)."""
    _one(backend, device, 0, **kw)
    t0 = time.perf_counter()
    rmse = [_one(backend, device, s, **kw)[0].depth_rmse for s in range(n)]
    dt = time.perf_counter() - t0
    return {"runs_per_s": n / dt, "rmse_mean": statistics.fmean(rmse),
            "rmse_sd": statistics.pstdev(rmse), "n": n}


def markdown(results: dict, sweeps: dict) -> str:
    """The tables: stage times per workload and backend, then the sweep throughput."""
    lines = [f"Machine: {platform.node()}, {os.cpu_count()} CPUs, GPU: {_device_name()}", ""]
    head = "| workload | backend | " + " | ".join(STAGES) + " | total (s) | vs numpy | RMSE (m) |"
    lines += [head, "|" + " --- |" * (len(STAGES) + 5)]
    for wl, per in results.items():
        base = per.get("numpy:cpu", {}).get("wall")
        for name, res in per.items():
            if "error" in res:
                lines.append(f"| {wl} | {name} | " + " | ".join("" for _ in STAGES)
                             + f" | {res['error']} | | |")
                continue
            ratio = f"{base / res['wall']:.2g}x" if base else ""  # (0.59 read "1x")
            st = " | ".join(f"{res['stages'][s]:.3f}" for s in STAGES)
            lines.append(f"| {wl} | {name} | {st} | {res['wall']:.3f} | {ratio} | "
                         f"{res['rmse']:.4f} |")
    if sweeps:
        lines += ["", "| 64x64 sweep | runs/s | vs numpy | RMSE mean +- sd (m) |",
                  "| --- | --- | --- | --- |"]
        base = sweeps.get("numpy:cpu", {}).get("runs_per_s")
        for name, s in sweeps.items():
            ratio = f"{s['runs_per_s'] / base:.2g}x" if base else ""
            lines.append(f"| {name} ({s['n']} runs) | {s['runs_per_s']:.1f} | {ratio} | "
                         f"{s['rmse_mean']:.4f} +- {s['rmse_sd']:.4f} |")
    return "\n".join(lines)


def _backend_list(text: str) -> list[tuple[str, str]]:
    """``type=`` of ``--backends``: ``BACKEND:DEVICE,...``, each a known backend on a device
    it can run on (whether it can run *here* is decided later, and said)."""
    import argparse

    from spslidar.backends import BACKENDS, DEVICES

    out = []
    for item in (b.strip() for b in text.split(",")):
        if not item:
            continue
        name, sep, device = item.partition(":")
        if not sep or name not in BACKENDS or device not in DEVICES:
            raise argparse.ArgumentTypeError(
                f"{item!r} is not BACKEND:DEVICE with BACKEND one of {', '.join(BACKENDS)} "
                f"and DEVICE one of {', '.join(DEVICES)} (e.g. numpy:cpu,torch:cuda)")
        if (name in ("numpy", "array-api-strict") and device != "cpu") or (
                name == "cupy" and device != "cuda"):
            raise argparse.ArgumentTypeError(
                f"{item!r}: {name} runs on {'CUDA' if name == 'cupy' else 'the CPU'} only")
        out.append((name, device))
    if not out:
        raise argparse.ArgumentTypeError("no backend given")
    return out


def _workload_list(text: str) -> list[str]:
    """``type=`` of ``--workloads`` and ``--numpy-workloads``: names of :data:`WORKLOADS` or
    ``sweep``, comma-separated."""
    import argparse

    out = [w.strip() for w in text.split(",") if w.strip()]
    bad = [w for w in out if w not in (*WORKLOADS, "sweep")]
    if bad or not out:
        what = f"unknown workload {bad[0]!r}" if bad else "no workload given"
        raise argparse.ArgumentTypeError(f"{what} (choose from {', '.join(WORKLOADS)}, sweep)")
    return out


def main(argv: list[str] | None = None) -> int:
    ap = _cli.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--backends", type=_backend_list, default="numpy:cpu,torch:cuda,cupy:cuda",
                    metavar="B:D,...", help="backends and devices, BACKEND:DEVICE comma-"
                    "separated (default: numpy:cpu,torch:cuda,cupy:cuda; those that cannot run "
                    "here are skipped, with a line on stderr)")
    ap.add_argument("--workloads", type=_workload_list, default="64,256,512h,sweep",
                    metavar="W,...", help=f"workloads, of {', '.join(WORKLOADS)}, sweep "
                    "(default: 64,256,512h,sweep)")
    ap.add_argument("--repeat", type=_cli.positive_int, default=5,
                    help="timed runs of each workload after a warm-up, the median kept "
                         "(default 5)")
    ap.add_argument("--numpy-repeat", type=_cli.positive_int, default=1,
                    help="timed NumPy runs of the 256 and 512h workloads (no warm-up; "
                         "default 1)")
    ap.add_argument("--numpy-workloads", type=_workload_list, default="64,256,sweep",
                    metavar="W,...",
                    help="workloads NumPy runs (default: 64,256,sweep; 512h takes minutes on "
                         "the CPU)")
    ap.add_argument("--sweep-runs", type=_cli.positive_int, default=40,
                    help="runs of the sweep on a device backend (default 40)")
    ap.add_argument("--numpy-sweep-runs", type=_cli.positive_int, default=5,
                    help="runs of the sweep on NumPy (default 5)")
    ap.add_argument("--out", type=_cli.out_file, default=None, metavar="FILE",
                    help="also write the Markdown table to FILE and the results to FILE's "
                         ".json (default: print only)")
    ap.add_argument("--depth", default="argmax",
                    help="depth estimator of every run (default argmax, the one with a device "
                         "kernel; mrf runs on the host)")
    args = ap.parse_args(argv)
    depth = {"depth": args.depth}  # argmax has a device kernel; mrf runs on the host

    from spslidar.backends import check_backend
    from spslidar.depth import ESTIMATORS
    from spslidar.errors import ConfigError
    from spslidar.patterns import PATTERNS

    if args.depth not in ESTIMATORS.names():
        ap.error(f"argument --depth: unknown depth estimator {args.depth!r}; choose one of "
                 f"{', '.join(ESTIMATORS.names())}")
    backends = []
    for backend, device in dict.fromkeys(args.backends):
        try:
            check_backend(backend, device)
        except ConfigError as exc:
            print(f"{ap.prog}: skip {backend}:{device}: {exc}", file=sys.stderr, flush=True)
            continue
        backends.append((backend, device))
    workloads = args.workloads
    np_work = set(args.numpy_workloads)
    results: dict[str, dict] = {}
    sweeps: dict[str, dict] = {}
    for wl in workloads:
        if wl == "sweep":
            continue
        kw = {**WORKLOADS[wl], **depth}
        if kw.get("patterns", "gaussian") not in PATTERNS.names():
            print(f"skip {wl}: no {kw['patterns']!r} pattern kind registered", flush=True)
            continue
        results[wl] = {}
        for backend, device in backends:
            name = f"{backend}:{device}"
            if backend == "numpy" and wl not in np_work:
                continue
            numpy_big = backend == "numpy" and wl != "64"
            try:
                res = bench_workload(backend, device, kw,
                                     args.numpy_repeat if numpy_big else args.repeat,
                                     warm=not numpy_big)
            except Exception as exc:  # noqa: BLE001 - a row saying what failed
                res = {"error": f"{type(exc).__name__}: {str(exc).splitlines()[0][:80]}"}
            results[wl][name] = res
            print(wl, name, json.dumps(res, default=str)[:300], flush=True)
    if "sweep" in workloads:
        for backend, device in backends:
            n = args.numpy_sweep_runs if backend == "numpy" else args.sweep_runs
            try:
                sweeps[f"{backend}:{device}"] = bench_sweep(backend, device, n, **depth)
            except Exception as exc:  # noqa: BLE001 - reported, the others go on
                print(f"sweep {backend}:{device} failed: {exc!r}", flush=True)
                continue
            print("sweep", backend, device, sweeps[f"{backend}:{device}"], flush=True)
    table = markdown(results, sweeps)
    print(table)
    if args.out:
        with open(args.out, "w") as fh:
            fh.write(table + "\n")
        with open(os.path.splitext(args.out)[0] + ".json", "w") as fh:
            json.dump({"results": results, "sweeps": sweeps}, fh, indent=1, default=str)
    return 0


if __name__ == "__main__":
    raise SystemExit(_cli.run(main))
