"""Figure 8 and Table I: the four reconstruction methods (TVAL3, GPSR, FISTA, TwIST) on the
motorcycle scene with QCR; Table I's runs at m_n = 10 are Figure 8's.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from spslidar.experiments.report import Claim, md_table
from spslidar.experiments.reproduce.context import (
    PAPER,
    SOLVER_NAMES,
    Context,
    base_params,
    run_and_write,
    write_text,
)
from spslidar.experiments.reproduce.plotting import (
    map_panel,
    new_figure,
    panel,
    save_figure,
    scene_of,
    truth_range,
)
from spslidar.experiments.reproduce.prose import common_text, section
from spslidar.experiments.reproduce.stats import (
    MARGIN,
    TVAL3_NOTE,
    Stat,
    below_margin,
    best_verdict,
    consistent,
    first_row,
    num,
    resolved,
    safe_ratio,
    stat,
    tally_verdict,
    time_note,
    time_order,
    within_scatter,
)
from spslidar.experiments.sweep import expand_grid, write_csv

SOLVERS = ("tval3", "gpsr", "fista", "twist")


def solver_points(ctx: Context, noises: Sequence[float], trials: int) -> list[dict[str, Any]]:
    """The four solvers on the motorcycle scene with QCR at each noise level."""
    points = []
    for mn in noises:
        for s in SOLVERS:
            points += expand_grid(
                base_params(ctx, scene="motorcycle", noise=mn, qcr=True, solver=s), {}, trials
            )
    return points


def exp_fig8(ctx: Context) -> tuple[str, list[Claim]]:
    """Fig. 8: the four solvers on the motorcycle scene at m_n = 10 with QCR."""
    name = "fig8"
    trials = ctx.n_trials()  # Table I's: the same runs
    rows, csv = run_and_write(ctx, name, solver_points(ctx, [10.0], trials))
    scene = scene_of(ctx, "motorcycle")
    lo, hi = truth_range(scene)
    fig = new_figure(1, 5)
    axes = fig.subplots(1, 5).ravel()
    panel(fig, axes[0], np.where(scene.valid, scene.depth, np.nan),
          "ground truth (white: unknown)", lo, hi)
    for i, s in enumerate(SOLVERS):
        row = first_row(rows, solver=s)
        label = f"({chr(97 + i)}) {SOLVER_NAMES[s]}"
        if row is not None:
            label += f", {row['iterations']} it."
        map_panel(ctx, fig, axes[i + 1], row, label, lo, hi)
    png = save_figure(
        ctx,
        name,
        fig,
        f"Fig. 8: motorcycle {ctx.size}x{ctx.size}, m_s=5, m_n=10, m-sequence 16383 bits, "
        f"QCR, 25 % patterns: four solvers",
    )
    st = {s: stat(rows, solver=s) for s in SOLVERS}
    rm = {s: st[s].mean for s in SOLVERS}
    best = min(SOLVERS, key=lambda s: np.nan_to_num(rm[s], nan=9e9))
    verdict, why = best_verdict(st, "tval3")
    ok = verdict == "consistent"
    table = md_table(
        ("solver", "regulariser", "RMSE [m]", "time [s]", "iterations", "paper (Table I, 'cm')"),
        [
            (
                SOLVER_NAMES[s],
                "Haar-wavelet l1" if s == "gpsr" else "TV",
                st[s].fmt(),
                num(stat(rows, "time_total_s", solver=s).mean, 1),
                num(stat(rows, "iterations", solver=s).mean, 0),
                "—" if PAPER["table1"][s][10][0] is None else f"{PAPER['table1'][s][10][0]:g}",
            )
            for s in SOLVERS
        ],
    )
    findings = [
        f"The paper finds TVAL3 best: here the lowest RMSE is {SOLVER_NAMES[best]}'s "
        f"({num(rm[best])} m; TVAL3 {num(rm['tval3'])} m): "
        f"{verdict}"
        f"{'' if ok else TVAL3_NOTE}.{why}"
    ]
    claims = [
        Claim(
            name,
            "TVAL3 best of the solvers (m_n = 10)",
            "TVAL3 0.011 'cm'",
            f"best: {SOLVER_NAMES[best]} {num(rm[best])} m; TVAL3 {num(rm['tval3'])} m",
            verdict,
        ),
    ]
    what = (
        f"{common_text(ctx, 'motorcycle')}, m_n = 10, PSST m-sequence of 16383 bits, QCR, 25 % "
        f"patterns; TVAL3, GPSR, FISTA and TwIST with the pipeline's default iteration caps "
        f"and regularisation weights (TV for TVAL3, FISTA and TwIST; Haar-wavelet l1 for "
        f"GPSR); {trials} trial(s) (the runs of Table I at m_n = 10; the maps: trial 0)."
    )
    text = section(
        ctx,
        "Fig. 8: reconstruction methods",
        what,
        table,
        findings,
        rows=rows,
        figures=[("Fig. 8: the four solvers at m_n = 10", png)],
        data=[csv],
    )
    return text, claims


#: why a "best solver" verdict is inconclusive
SCATTER_NOTE = (" (the lead over the nearest rival is within two standard errors of the "
                "trials' scatter, or rests on one trial: --trials 5 can tell)")


def exp_table1(ctx: Context) -> tuple[str, list[Claim]]:
    """Table I: RMSE, time and iterations of the four solvers at m_n = 5 and 10."""
    name = "table1"
    trials = ctx.n_trials()
    noises = [5.0, 10.0]
    rows, csv = run_and_write(ctx, name, solver_points(ctx, noises, trials))
    summary = []
    for s in SOLVERS:
        for mn in noises:
            p_rmse, p_time = PAPER["table1"][s][int(mn)]
            r = stat(rows, solver=s, noise=mn)
            summary.append(
                {
                    "solver": s,
                    "noise": mn,
                    "trials": r.n,
                    "rmse_m": r.mean,
                    "rmse_std_m": r.std,
                    "rmse_cm": 100 * r.mean,
                    "paper_mse_printed_cm": p_rmse,
                    "time_total_s": stat(rows, "time_total_s", solver=s, noise=mn).mean,
                    "time_solve_s": stat(rows, "time_solve_s", solver=s, noise=mn).mean,
                    "paper_time_s": p_time,
                    "iterations": stat(rows, "iterations", solver=s, noise=mn).mean,
                    "missing_fraction": stat(rows, "missing_fraction", solver=s, noise=mn).mean,
                }
            )
    sum_csv = write_csv(summary, ctx.folder(name) / f"{name}_summary.csv")

    def paper_rmse(s: str, mn: float) -> str:
        v = PAPER["table1"][s][int(mn)][0]
        return "0.005-0.017 m (Fig. 6)" if v is None else f"{v:g} 'cm'"

    table = md_table(
        (
            "method",
            "m_n",
            "RMSE [m]",
            "RMSE [cm]",
            "paper's argmax depth [m]",
            "paper MSE (as printed)",
            "time [s]",
            "solve [s]",
            "paper time [s]",
            "iterations",
        ),
        [
            (
                SOLVER_NAMES[d["solver"]],
                f"{d['noise']:g}",
                stat(rows, solver=d["solver"], noise=d["noise"]).fmt(),
                num(d["rmse_cm"], 2),
                stat(rows, "depth_rmse_argmax_m", solver=d["solver"], noise=d["noise"]).fmt(),
                paper_rmse(d["solver"], d["noise"]),
                num(d["time_total_s"], 1),
                num(d["time_solve_s"], 1),
                f"{d['paper_time_s']:g}",
                num(d["iterations"], 0),
            )
            for d in summary
        ],
    )
    table_md = ctx.folder(name) / f"{name}.md"
    write_text(table_md, table)
    get = {(d["solver"], d["noise"]): d for d in summary}
    best = {
        mn: min(SOLVERS, key=lambda s, mn=mn: np.nan_to_num(get[(s, mn)]["rmse_m"], nan=9e9))
        for mn in noises
    }
    # "not consistent" at either noise decides; else "inconclusive" at either; else TVAL3
    # leads at both
    verdicts = {best_verdict({sv: stat(rows, solver=sv, noise=mn) for sv in SOLVERS},
                             "tval3")[0] for mn in noises}
    best_v = ("not consistent" if "not consistent" in verdicts
              else "inconclusive" if "inconclusive" in verdicts
              else consistent(verdicts == {"consistent"}))
    falls = [s for s in SOLVERS if get[(s, 10.0)]["rmse_m"] < get[(s, 5.0)]["rmse_m"]]
    paper_vals = [v[0] for s in ("tval3", "gpsr", "fista") for v in PAPER["table1"][s].values()]
    ours_cm = [get[(s, mn)]["rmse_cm"] for s in ("tval3", "gpsr", "fista") for mn in noises]
    med_ours_cm = float(np.nanmedian(ours_cm))
    med_paper = float(np.median(paper_vals))
    closer = (
        "metres"
        if abs(np.log(med_ours_cm / (100 * med_paper))) < abs(np.log(med_ours_cm / med_paper))
        else "centimetres"
    )
    # timings told apart only beyond x2 or, with three trials or more, beyond their scatter
    # (time_order): single timings flipped this verdict between two identical runs
    def t_stat(s: str, mn: float) -> Stat:
        return stat(rows, "time_total_s", solver=s, noise=mn)

    order = {s: [time_order(t_stat(s, mn), t_stat("twist", mn)) for mn in noises]
             for s in ("fista", "gpsr")}
    fast = [s for s, o in order.items() if all(x == -1 for x in o)]
    not_fast = [s for s, o in order.items() if any(x == 1 for x in o)]
    fast_v = tally_verdict(len(fast), len(not_fast), 2)
    slow_o = [time_order(t_stat("tval3", mn), t_stat(s, mn)) for mn in noises
              for s in SOLVERS if s != "tval3"]
    slow = ("the" if all(x == 1 for x in slow_o)
            else "not the" if any(x == -1 for x in slow_o) else "not told apart as the")
    undecided = [SOLVER_NAMES[s] for s in order if s not in fast and s not in not_fast]
    parts = [f"{', '.join(undecided)} against TwIST"] if undecided else []
    if slow.startswith("not told"):
        parts.append("TVAL3 against the others")
    time_why = f" Not told apart{time_note(trials)}: {'; '.join(parts)}." if parts else ""
    # the ratios each timing verdict rests on (one read x2.03 against the threshold x2,
    # unsaid: an outside review of 2026-12-01)
    t_ratios = "; ".join(
        f"{SOLVER_NAMES[s]} " + " / ".join(
            f"x{num(safe_ratio(t_stat(s, mn).mean, t_stat('twist', mn).mean), 2)}"
            for mn in noises)
        for s in ("fista", "gpsr"))
    t_ratios = (f" Times over TwIST's at m_n = {' / '.join(f'{mn:g}' for mn in noises)}: "
                f"{t_ratios}.")
    # "FISTA and GPSR produce almost the same quality as the TwIST": each against TwIST at
    # each noise; a ratio beyond x2 is a difference whatever the trials, one within the
    # margin is the same quality, between the two the trials' scatter decides
    q_parts, q_same, q_diff = [], 0, 0
    for sv in ("fista", "gpsr"):
        for mn in noises:
            a, b = stat(rows, solver=sv, noise=mn), stat(rows, solver="twist", noise=mn)
            r = safe_ratio(a.mean, b.mean)
            if not math.isfinite(r):
                continue
            if r > 2 or r < 0.5:
                q_diff += 1
                tag = "worse" if r > 1 else "better"
            elif below_margin(a, b) or (min(a.n, b.n) > 1 and within_scatter(a, b)):
                q_same += 1
                tag = "same"
            elif resolved(a, b):
                q_diff += 1
                tag = "worse" if r > 1 else "better"
            else:
                tag = "not resolved"
            q_parts.append(f"{SOLVER_NAMES[sv]} at m_n = {mn:g} x{num(r, 2)} ({tag})")
    q_total = 2 * len(noises)
    quality_v = ("consistent" if q_same == q_total else
                 "not consistent" if q_diff and not q_same else
                 "partly consistent" if q_diff else "inconclusive")
    findings = [
        f"The paper finds FISTA and GPSR of 'almost the same quality' as TwIST: their RMSE "
        f"over TwIST's here: {'; '.join(q_parts)} (a ratio beyond x2 differs whatever the "
        f"trials, one within {100 * MARGIN:g} % is the same, in between the trials' scatter "
        f"decides): {quality_v}.",
        f"The paper finds TVAL3 the most accurate: here the lowest RMSE is "
        f"{SOLVER_NAMES[best[5.0]]}'s at m_n = 5 and {SOLVER_NAMES[best[10.0]]}'s at m_n = 10: "
        f"{best_v}{SCATTER_NOTE if best_v == 'inconclusive' else ''}.",
        f"Table I's errors fall as the noise rises (every method: m_n = 10 below m_n = 5), "
        f"which a noise-limited estimator should not show; here the RMSE falls with more noise "
        f"for {len(falls)} of 4 methods"
        f"{' (' + ', '.join(SOLVER_NAMES[s] for s in falls) + ')' if falls else ''}"
        f"{': the usual behaviour, unlike the table' if len(falls) < 2 else ''}.",
        f"Table I's values ({min(paper_vals):g}-{max(paper_vals):g}, printed as cm) would be "
        f"0.1-0.6 mm, far below the 1.5 cm range bin; our TVAL3/GPSR/FISTA errors (median "
        f"{med_ours_cm:.2f} cm) are closer to the printed numbers read as {closer}.",
        f"The paper finds FISTA and GPSR faster than TwIST and TVAL3 the slowest: here faster "
        f"than TwIST at both noise levels: {', '.join(SOLVER_NAMES[s] for s in fast) or 'none'}"
        f" ({fast_v}); TVAL3 {slow} slowest.{t_ratios}{time_why} Times are of this "
        f"implementation, "
        f"with per-solver default iteration caps.",
    ]
    claims = [
        Claim(
            name,
            "FISTA, GPSR almost the same quality as TwIST",
            "qualitative (Table I, Fig. 6)",
            "; ".join(p.split(" (")[0] for p in q_parts),
            quality_v,
        ),
        Claim(
            name,
            "TVAL3 most accurate",
            "TVAL3 0.033/0.011 'cm'",
            f"best: {SOLVER_NAMES[best[5.0]]} / {SOLVER_NAMES[best[10.0]]}",
            best_v,
        ),
        # the table's numbers fall as the noise rises, which the paper's text does not
        # claim (an outside review, 2026-12-01, of its "not consistent"): a row that says
        # what ours do, with no verdict
        Claim(
            name,
            "Table I's numbers fall as m_n rises (read off the table; not claimed)",
            "all methods",
            f"{len(falls)}/4 methods",
            "n/a (not a claim)",
        ),
        Claim(
            name,
            "FISTA, GPSR faster than TwIST",
            "16/24, 13/24 vs 20/28 s",
            ", ".join(SOLVER_NAMES[s] for s in fast) or "neither",
            fast_v,
        ),
    ]
    what = (
        f"{common_text(ctx, 'motorcycle')}, PSST m-sequence of 16383 bits, QCR, 25 % patterns, "
        f"m_n = 5 and 10; TVAL3, GPSR, FISTA, TwIST with the pipeline's defaults (the paper "
        f"gives no solver settings); {trials} trial(s). The paper's MSE column is quoted as "
        f"printed, with its doubtful unit 'cm'; its TwIST errors are in Fig. 6."
    )
    text = section(
        ctx,
        "Table I: reconstruction methods",
        what,
        table,
        findings,
        rows=rows,
        data=[csv, sum_csv, table_md],
    )
    return text, claims
