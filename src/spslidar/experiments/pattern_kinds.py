"""Which DMD patterns to use: pattern kinds compared at 128x128 and 256x256.

An experiment of ``spslidar reproduce pattern_kinds`` (registered with ``in_all=False``: not
run by ``reproduce all``): depth RMSE and reconstruction time against the compression M/Q for
dense Gaussian and Bernoulli patterns (at 128x128 only: their (M, Q) matrix makes 256x256 cost
82 s and 5.6 GB per run) and Walsh-Hadamard patterns applied by a fast transform (sequency and
cake-cutting orders, scrambled), at the paper's other settings (camera scene, 16383-bit
m-sequence, m_s = 5, m_n = 10, QCR, FISTA + TV).

    from spslidar.experiments.pattern_kinds import run_pattern_kinds
    print(run_pattern_kinds("out", quick=True))     # 32x32 and 64x64, ~1-2 min on 2 cores

Runs go through the sweep engine's cache (``DIR/cache``), so a second call is served from it.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from spslidar.experiments.report import QUICK_MARK, Claim, md_table
from spslidar.experiments.reproduce import Context, base_params, reproduce_point
from spslidar.experiments.sweep import ERROR_KEY, run_sweep, write_csv

NAME = "pattern_kinds"

#: (label, config keys) of the kinds compared
KINDS: tuple[tuple[str, dict[str, Any]], ...] = (
    ("Gaussian", {"patterns": "gaussian"}),
    ("Bernoulli", {"patterns": "bernoulli"}),
    ("Hadamard, sequency", {"patterns": "hadamard", "hadamard_order": "sequency"}),
    ("Hadamard, cake-cutting", {"patterns": "hadamard", "hadamard_order": "cake-cutting"}),
    ("scrambled Hadamard", {"patterns": "scrambled-hadamard"}),
)
DENSE = ("gaussian", "bernoulli")


def _sizes(ctx: Context) -> tuple[int, int]:
    return (32, 64) if ctx.quick else (128, 256)


def _compressions(ctx: Context) -> tuple[float, ...]:
    return (0.1, 0.25) if ctx.quick else (0.05, 0.1, 0.25)


def pattern_kind_points(ctx: Context) -> list[dict[str, Any]]:
    """The runs: every kind at every compression and size (dense kinds at the smaller size)."""
    small, _ = _sizes(ctx)
    points = []
    for n in _sizes(ctx):
        for _, keys in KINDS:
            if keys["patterns"] in DENSE and n > small:
                continue
            for c in _compressions(ctx):
                points.append({**base_params(ctx, size=n, compression=c, **keys), "trial": 0})
    return points


def _label(row: dict[str, Any]) -> str:
    for label, keys in KINDS:
        if all(row.get(k) == v for k, v in keys.items()):
            return label
    return str(row.get("patterns"))


def readable_log_ticks(ax) -> None:
    """Label a log y axis at 1, 2, 5 (1, 2, 3, 5, 7 under a decade) times the powers of ten,
    in plain numbers: the 64x64 time axis (0.6-2.1 s) had a single label, 10^0."""
    from matplotlib.ticker import FormatStrFormatter, LogLocator, NullFormatter

    lo, hi = ax.get_ylim()
    if not (lo > 0 and hi > lo):
        return
    subs = (1.0, 2.0, 3.0, 5.0, 7.0) if hi / lo < 10 else (1.0, 2.0, 5.0)
    ax.yaxis.set_major_locator(LogLocator(base=10, subs=subs))
    ax.yaxis.set_major_formatter(FormatStrFormatter("%g"))
    ax.yaxis.set_minor_formatter(NullFormatter())


def _figure(rows: Sequence[dict[str, Any]], sizes: Sequence[int], path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(sizes), figsize=(4.2 * len(sizes), 6.4), squeeze=False,
                             constrained_layout=True)
    for j, n in enumerate(sizes):
        for i, (label, _) in enumerate(KINDS):
            pts = sorted((r for r in rows if r["size"] == n and r["label"] == label),
                         key=lambda r: r["compression"])
            if not pts:
                continue
            c = [100 * r["compression"] for r in pts]
            style = {"color": f"C{i}", "label": label}  # one colour per kind in every panel
            axes[0, j].plot(c, [r["depth_rmse_m"] for r in pts], "o-", **style)
            axes[1, j].plot(c, [r["time_total_s"] for r in pts], "o-", **style)
        axes[0, j].set_title(f"{n}x{n}")
        axes[0, j].set_ylabel("depth RMSE [m]")
        axes[0, j].set_yscale("log")
        axes[1, j].set_ylabel("run time (whole run) [s]")
        axes[1, j].set_yscale("log")
        for ax in axes[:, j]:
            ax.set_xlabel("compression M/Q [%]")
            ax.grid(alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    for ax in axes.ravel():
        ax.set_xlim(0, None)
        readable_log_ticks(ax)
    from spslidar.experiments.reproduce.plotting import save_png

    try:
        save_png(fig, path, dpi=110)  # (all or nothing: an interrupt leaves no partial PNG)
    finally:  # (a write that failed left the figure in pyplot, one a call: an audit)
        plt.close(fig)
    return path


#: a lead in depth RMSE smaller than this share of the runner-up's is not called a lead: each
#: point is one realisation (trial-to-trial spreads of 15 % were measured in Fig. 3)
LEAD_MARGIN = 0.15


def _lowest(pts: Sequence[dict[str, Any]]) -> str:
    """"K (x m)" for the lowest RMSE of ``pts``, with the kinds within :data:`LEAD_MARGIN`."""
    pts = sorted(pts, key=lambda r: r["depth_rmse_m"])
    best = pts[0]
    close = [r for r in pts[1:]
             if r["depth_rmse_m"] <= best["depth_rmse_m"] * (1 + LEAD_MARGIN)]
    text = f"{best['label']} ({best['depth_rmse_m']:.4f} m)"
    if close:
        text += (" tied with " + ", ".join(f"{r['label']} ({r['depth_rmse_m']:.4f} m)"
                                           for r in close)
                 + f" (within {100 * LEAD_MARGIN:g} %, one realisation each)")
    return text


def _advice(rows: Sequence[dict[str, Any]], sizes: Sequence[int]) -> str:
    """The paragraph on what to pick, read from the measured rows only: the lowest RMSE at
    each size and compression (a lead within :data:`LEAD_MARGIN` is a tie), how cake-cutting
    compares with sequency order, and the dense kinds' time against the Hadamard kinds' as
    measured (an audit found a fixed sentence here that contradicted the table above it)."""
    comps = sorted({r["compression"] for r in rows})
    sentences = []
    for n in sorted(set(sizes), reverse=True):
        parts = []
        for c in comps:
            pts = [r for r in rows if r["size"] == n and r["compression"] == c
                   and math.isfinite(r["depth_rmse_m"])]
            if pts:
                parts.append(f"at {100 * c:g} % {_lowest(pts)}")
        if parts:
            sentences.append(f"Lowest depth RMSE at {n}x{n}: " + "; ".join(parts) + ".")
    seq = {(r["size"], r["compression"]): r["depth_rmse_m"] for r in rows
           if r["label"] == "Hadamard, sequency"}
    cake = {(r["size"], r["compression"]): r["depth_rmse_m"] for r in rows
            if r["label"] == "Hadamard, cake-cutting"}
    both = sorted(set(seq) & set(cake))
    if both:
        below = sum(cake[k] < seq[k] for k in both)
        sentences.append(f"Cake-cutting order is below sequency order at {below} of "
                         f"{len(both)} (size, compression) points.")
    small = min(sizes)
    dense = [r for r in rows if r["size"] == small and r["patterns"] in DENSE]
    fast = [r for r in rows if r["size"] == small and r["patterns"] not in DENSE]
    if dense and fast:
        ratio = np.median([r["time_total_s"] for r in dense]) / np.median(
            [r["time_total_s"] for r in fast])
        sentences.append(
            f"At {small}x{small} the dense kinds took {ratio:.1f}x the time of the Hadamard "
            f"kinds (medians of single runs over the compressions).")
    big = max(sizes)
    if big > small:
        sentences.append(
            f"The dense kinds were not run at {big}x{big}: their M x Q matrix grows as the "
            f"square of the pixel count.")
    return ("What to pick, from this table: " + " ".join(sentences)) if sentences else ""


def _mode(ctx: Context) -> str:
    n0, n1 = _sizes(ctx)
    if ctx.quick:
        return (f"{QUICK_MARK} ({n0}x{n0} and {n1}x{n1}, two compressions): a smoke test, "
                f"not the sizes this comparison is about.")
    return f"Full mode ({n0}x{n0} and {n1}x{n1})."


def exp_pattern_kinds(ctx: Context) -> tuple[str, list[Claim]]:
    """Pattern kinds: depth RMSE and time against compression at two sizes.

    Returns
    -------
    text : str
        A Markdown section: the table, the figure and what a user should pick.
    claims : list of Claim
        Empty (the paper compares no pattern kinds).
    """
    from spslidar.pipeline.measurement import processing_keys

    ctx.maps.mkdir(parents=True, exist_ok=True)
    func = functools.partial(reproduce_point, maps_dir=str(ctx.maps))
    points = pattern_kind_points(ctx)
    # priced as run_points prices the other experiments' runs (it ran 243 s under
    # --max-time 5, an audit)
    if ctx.max_time is not None:
        from spslidar.experiments.reproduce.context import _check_batch_time

        _check_batch_time(ctx, points)
    rows = run_sweep(func, points, ctx.cache, seed=ctx.seed, jobs=ctx.jobs,
                     scheduler=ctx.scheduler, progress=ctx.progress, seed_ignore=processing_keys(),
                     code=ctx.code)
    ctx.failed += sum(ERROR_KEY in r for r in rows)
    full = [{**p, **r, "label": _label(p)} for p, r in zip(points, rows, strict=True)]
    ok = [r for r in full if ERROR_KEY not in r]
    folder = ctx.folder(NAME)
    csv = write_csv([{"experiment": NAME, **r} for r in full], folder / f"{NAME}.csv")
    sizes = _sizes(ctx)
    png = _figure(ok, sizes, folder / f"{NAME}.png")
    table = md_table(
        ("N", "patterns", "M/Q", "depth RMSE [m]", "simulate [s]", "solve [s]", "total [s]"),
        [(r["size"], r["label"], f"{100 * r['compression']:g} %", f"{r['depth_rmse_m']:.4f}",
          f"{r['time_simulate_s']:.1f}", f"{r['time_solve_s']:.1f}", f"{r['time_total_s']:.1f}")
         for r in ok])
    failed = len(full) - len(ok)
    text = (
        f"## Pattern kinds\n\n{_mode(ctx)}\n\n"
        f"Camera scene, m-sequence of 16383 bits, m_s = 5, m_n = 10, QCR, FISTA + TV; dense "
        f"Gaussian and Bernoulli patterns at {sizes[0]}x{sizes[0]} only, Walsh-Hadamard "
        f"patterns (fast transform, shown as (1 + h)/2 with the DC removed by the QCR "
        f"centring) at both sizes. One realisation per point.\n\n"
        f"![pattern kinds]({NAME}/{png.name})\n\n{table}\n"
        f"{_advice(ok, sizes)}\n\n"
        + (f"{failed} run(s) failed (see the CSV's error column).\n\n" if failed else "")
        + f"Data: `{NAME}/{csv.name}`.\n")
    from spslidar.experiments.reproduce.context import write_text

    write_text(folder / f"{NAME}.md", text)
    return text, []


def run_pattern_kinds(out_dir: str | Path, quick: bool = False, jobs: int = 1) -> str:
    """Run :func:`exp_pattern_kinds` into ``out_dir`` (CSV, PNG and Markdown under
    ``out_dir/pattern_kinds``) and return its Markdown section."""
    ctx = Context(Path(out_dir), quick=quick, jobs=jobs, progress=False)
    return exp_pattern_kinds(ctx)[0]
