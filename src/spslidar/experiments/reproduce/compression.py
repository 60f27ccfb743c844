"""Figure 2 (depth maps against the compression ratio M/Q) and Figure 3 (code kinds at m_n = 1)."""

from __future__ import annotations

import math

from spslidar.experiments.report import Claim, md_table
from spslidar.experiments.reproduce.context import PAPER, Context, base_params, run_and_write
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
    compare,
    consistent,
    first_row,
    floor_note,
    in_bins,
    num,
    pct,
    resolved,
    safe_ratio,
    stat,
    time_note,
    time_order,
    unresolved_clause,
)
from spslidar.experiments.sweep import expand_grid

#: Fig. 2's code: the paper's Sec. III, a Bernoulli random code of 2048 bits with ones
#: probability 0.1 (Fig. 3's first too)
FIG2_CODE = {"code": "random", "code_length": 2048, "ones_ratio": 0.1}


def exp_fig2(ctx: Context) -> tuple[str, list[Claim]]:
    """Fig. 2: depth maps of the camera scene against the compression ratio M/Q."""
    name = "fig2"
    comps = [0.05, 0.25, 0.85] if ctx.quick else [0.05, 0.15, 0.25, 0.45, 0.65, 0.85]
    # the paper's Sec. III code for Fig. 2 (the 16383-bit m-sequence of Fig. 4 ran here
    # before 2026-11-29, said nowhere: an outside review against the paper)
    points = [
        p for c in comps for p in expand_grid(base_params(ctx, compression=c, **FIG2_CODE), {},
                                              ctx.n_trials())
    ]
    rows, csv = run_and_write(ctx, name, points)
    scene = scene_of(ctx, "camera")
    lo, hi = truth_range(scene)
    ncols = 4
    nrows = math.ceil((len(comps) + 2) / ncols)
    fig = new_figure(nrows, ncols)
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    panel(fig, axes[0], scene.depth, "(a) ground truth", lo, hi)
    for i, c in enumerate(comps):
        row = first_row(rows, compression=c)
        label = f"({chr(98 + i)}) {100 * c:g} % ({row['n_patterns'] if row else '?'} patterns)"
        map_panel(ctx, fig, axes[i + 1], row, label, lo, hi)
    ax = axes[len(comps) + 1]
    rm = [stat(rows, compression=c).mean for c in comps]
    tm = [stat(rows, "time_total_s", compression=c).mean for c in comps]
    ax.plot([100 * c for c in comps], rm, "o-", color="C0")
    ax.set_xlabel("compression M/Q [%]", fontsize=8)
    ax.set_ylabel("depth RMSE [m]", color="C0", fontsize=8)
    ax2 = ax.twinx()
    ax2.plot([100 * c for c in comps], tm, "s--", color="C1")
    ax2.set_ylabel("time [s]", color="C1", fontsize=8)
    ax.set_title("RMSE and time vs compression", fontsize=8)
    for extra in axes[len(comps) + 2 :]:
        extra.set_visible(False)
    png = save_figure(
        ctx,
        name,
        fig,
        f"Fig. 2: camera {ctx.size}x{ctx.size}, PSST random code {FIG2_CODE['code_length']} bits "
        f"R_a={FIG2_CODE['ones_ratio']:g}, m_s=5, m_n=10, QCR, FISTA",
    )

    table_rows = []
    for i, c in enumerate(comps):
        paper_t = "—"
        if c == 0.05:
            paper_t = f"{PAPER['fig2_time_s'][0]:g}"
        elif c == 0.85:
            paper_t = f"{PAPER['fig2_time_s'][1]:g}"
        row = first_row(rows, compression=c)
        table_rows.append(
            (
                f"{100 * c:g} %",
                row["n_patterns"] if row else "—",
                stat(rows, compression=c).fmt(),
                pct(stat(rows, "missing_fraction", compression=c).mean),
                num(tm[i], 1),
                num(stat(rows, "time_solve_s", compression=c).mean, 1),
                paper_t,
            )
        )
    table = md_table(
        (
            "compression",
            "patterns M",
            "RMSE [m]",
            "missing",
            "time [s]",
            "solve [s]",
            "paper time [s]",
        ),
        table_rows,
    )
    r_lo, r_hi = rm[0], rm[-1]
    ups = sum(1 for a, b in zip(rm, rm[1:], strict=False) if b > a * 1.05)
    # told apart by the report's one rule (resolved: beyond x2, else beyond the trials'
    # scatter), which this verdict had skipped: one trial each read "consistent" at any gap
    q_lo, q_hi = stat(rows, compression=comps[0]), stat(rows, compression=comps[-1])
    quality_told = resolved(q_hi, q_lo)
    quality_ok = math.isfinite(r_lo) and math.isfinite(r_hi) and r_hi < r_lo
    quality_v = consistent(quality_ok) if quality_told else "inconclusive"
    t_ratio = safe_ratio(tm[-1], tm[0])
    paper_t_ratio = PAPER["fig2_time_s"][1] / PAPER["fig2_time_s"][0]
    # one verdict for the section, the summary and claims.json (the section said "consistent
    # in trend" where the others said "consistent"); single timings on a shared machine decide
    # only beyond x2, repeated ones beyond their scatter (time_order: single runs of 0.8 and
    # 0.6 s read "not consistent")
    t_lo = stat(rows, "time_total_s", compression=comps[0])
    t_hi = stat(rows, "time_total_s", compression=comps[-1])
    t_order = time_order(t_hi, t_lo)
    time_v = {1: "consistent", -1: "not consistent", None: "inconclusive"}[t_order]
    why_time = ""
    if math.isfinite(t_ratio) and t_ratio < paper_t_ratio / 2:
        ts = [stat(rows, "time_solve_s", compression=c).mean for c in comps]
        its = [stat(rows, "iterations", compression=c).mean for c in comps]
        solve_ratio = safe_ratio(ts[-1], ts[0])
        if math.isfinite(solve_ratio) and 0.67 <= solve_ratio <= 1.5:
            why_time = (
                f" Ours grow less: the solver runs {num(its[0], 0)}-{num(its[-1], 0)} iterations "
                f"whatever M and its time changes only x{solve_ratio:.1f} from "
                f"{first_row(rows, compression=comps[0])['n_patterns']} to "
                f"{first_row(rows, compression=comps[-1])['n_patterns']} patterns, so each "
                f"iteration's cost is dominated by work that does not scale with M (the "
                f"regulariser over {ctx.size**2} pixels x range slices), not by the pattern "
                f"products."
            )
        elif t_ratio < 1.0 and t_order is not None:
            why_time = (
                " Here the smaller settings even ran slower, which only timing noise explains "
                "(runs timed on a shared machine; the first run of a session also pays for "
                "imports)."
            )
    if t_order is None:
        why_time += (f" The two timings cannot be told apart"
                     f"{time_note(min(t_lo.n, t_hi.n))}.")
    falls = [(comps[i], comps[i + 1]) for i in range(len(tm) - 1)
             if math.isfinite(tm[i]) and math.isfinite(tm[i + 1]) and tm[i + 1] < tm[i]]
    mono = ("; the mean time rises at every step" if not falls else
            f"; the mean time is not monotone in the compression: it falls at {len(falls)} of "
            f"{len(tm) - 1} steps ("
            + ", ".join(f"{100 * a:g} -> {100 * b:g} %" for a, b in falls) + ")")
    findings = [
        f"The paper reports better depth maps with more measurements: here the RMSE goes from "
        f"{num(r_lo)} m at {100 * comps[0]:g} % to {num(r_hi)} m at {100 * comps[-1]:g} %"
        f"{' and never rises by more than 5 % from one step to the next' if ups == 0 else ''}"
        f"{f' but rises at {ups} step(s)' if ups else ''}: "
        f"{quality_v}.{'' if quality_told else unresolved_clause(q_hi, q_lo)}"
        f"{floor_note(r_hi)}",
        f"The paper's detection plus reconstruction takes {PAPER['fig2_time_s'][0]:g}-"
        f"{PAPER['fig2_time_s'][1]:g} s (x{paper_t_ratio:.1f} from 5 % to 85 %, MATLAB); here "
        f"{num(tm[0], 1)}-{num(tm[-1], 1)} s (x{num(t_ratio, 1)}): "
        f"{time_v} for the direction from {100 * comps[0]:g} to {100 * comps[-1]:g} %{mono}. "
        f"Absolute times compare different software and machines.{why_time}",
        FIG2_CODE_NOTE,
    ]
    if 0.25 in comps:
        r25 = stat(rows, compression=0.25).mean
        findings.append(
            f"The paper calls 25 % 'almost acceptable': here 25 % gives {num(r25)} m "
            f"({in_bins(r25)}) against {num(r_hi)} m at {100 * comps[-1]:g} %."
        )
    claims = [
        Claim(
            name,
            "more measurements, better depth",
            "qualitative (Fig. 2b-g)",
            f"RMSE {num(r_lo)} -> {num(r_hi)} m",
            quality_v,
        ),
        Claim(
            name,
            "time grows with compression",
            "8-78 s",
            f"{num(tm[0], 1)}-{num(tm[-1], 1)} s"
            + (f" (not monotone: falls at {len(falls)} of {len(tm) - 1} steps)" if falls else ""),
            time_v,
        ),
    ]
    what = (
        f"{common_text(ctx)}, PSST Bernoulli random code of {FIG2_CODE['code_length']} bits with "
        f"ones ratio R_a = {FIG2_CODE['ones_ratio']:g} (the paper's Sec. III; zero-mean "
        f"replica, the default for a code with fewer ones than zeros), m_n = 10 (the "
        f"paper does not give m_n for Fig. 2; this is the default of Fig. 4), QCR, FISTA with "
        f"default settings; compression M/Q = {', '.join(f'{100 * c:g}' for c in comps)} %; "
        f"{ctx.n_trials()} trial(s) per setting."
    )
    text = section(
        ctx,
        "Fig. 2: depth maps against the compression ratio",
        what,
        table,
        findings,
        rows=rows,
        figures=[("Fig. 2: ground truth and depth maps against compression", png)],
        data=[csv],
    )
    return text, claims


FIG3_CODES = (
    ("random 0.1", FIG2_CODE),
    ("random 0.3", {"code": "random", "code_length": 2048, "ones_ratio": 0.3}),
    ("gold", {"code": "gold", "code_length": 2047}),
    ("mseq", {"code": "mseq", "code_length": 2047}),
)


#: trials per code of Fig. 3 in full mode: its verdicts rest on differences of 8-21 %, and
#: one trial's spread is about 15 % (five trials: a few seconds more in all)
FIG3_TRIALS = 5


def exp_fig3(ctx: Context) -> tuple[str, list[Claim]]:
    """Fig. 3: Bernoulli codes (R_a = 0.1, 0.3), Gold code and m-sequence at m_n = 1."""
    name = "fig3"
    labels = {
        "random 0.1": "(a) Bernoulli R_a=0.1, 2048 bits",
        "random 0.3": "(b) Bernoulli R_a=0.3, 2048 bits",
        "gold": "(c) Gold, 2047 bits",
        "mseq": "(d) m-sequence, 2047 bits",
    }
    points = []
    trials = ctx.n_trials(full=FIG3_TRIALS)
    for _, kw in FIG3_CODES:
        points += expand_grid(base_params(ctx, noise=1.0, **kw), {}, trials)
    rows, csv = run_and_write(ctx, name, points)
    scene = scene_of(ctx, "camera")
    lo, hi = truth_range(scene)
    fig = new_figure(1, 5)
    axes = fig.subplots(1, 5).ravel()
    panel(fig, axes[0], scene.depth, "ground truth", lo, hi)
    sel = {}
    for i, (key, kw) in enumerate(FIG3_CODES):
        match = {k: v for k, v in base_params(ctx, noise=1.0, **kw).items() if k in kw}
        sel[key] = match
        row = first_row(rows, **match)
        map_panel(ctx, fig, axes[i + 1], row, labels[key], lo, hi)
    title = f"Fig. 3: camera {ctx.size}x{ctx.size}, m_s=5, m_n=1, 25 % patterns, QCR, FISTA"
    png = save_figure(ctx, name, fig, title)
    st = {k: stat(rows, **sel[k]) for k in sel}
    miss = {k: stat(rows, "missing_fraction", **sel[k]).mean for k in sel}
    table = md_table(
        ("code", "bits", "R_a (share of ones)", "RMSE [m]", "missing", "paper"),
        [
            (
                "Bernoulli",
                2048,
                0.1,
                st["random 0.1"].fmt(),
                pct(miss["random 0.1"]),
                "worse than R_a = 0.3",
            ),
            (
                "Bernoulli",
                2048,
                0.3,
                st["random 0.3"].fmt(),
                pct(miss["random 0.3"]),
                "better than R_a = 0.1",
            ),
            ("Gold", 2047, "~0.5", st["gold"].fmt(), pct(miss["gold"]), "worse than m-sequence"),
            ("m-sequence", 2047, "~0.5", st["mseq"].fmt(), pct(miss["mseq"]), "better than Gold"),
        ],
    )
    # (each verdict "inconclusive" where the trials' scatter cannot resolve the difference:
    # both single-trial verdicts of the committed report reversed at five trials)
    ra_v, ra_why = compare(
        st["random 0.3"].mean, st["random 0.1"].mean, miss["random 0.3"], miss["random 0.1"],
        stats=(st["random 0.3"], st["random 0.1"]))
    ms_v, ms_why = compare(st["mseq"].mean, st["gold"].mean, miss["mseq"], miss["gold"],
                           stats=(st["mseq"], st["gold"]))
    why_ms = ms_why
    if ms_v != "consistent":
        why_ms += (
            " Through their replicas both codes have near-ideal periodic autocorrelation "
            "(m-sequence sidelobes -1, Gold three-valued and small) and nearly the same share "
            "of ones, so eq. (10) predicts nearly the same SNR.")
    why_ra = ra_why
    if ra_v != "consistent":
        why_ra += (" Eq. (10) predicts what the paper reports (SNR proportional to R_a T); at "
                   "m_n = 1 both codes read the depth to within a bin, where the prediction "
                   "shows little.")
    r0 = {k: first_row(rows, **sel[k]) for k in sel}
    shown = ""
    if r0["random 0.3"] is not None and r0["random 0.1"] is not None:
        a0, b0 = r0["random 0.3"]["depth_rmse_m"], r0["random 0.1"]["depth_rmse_m"]
        against = (a0 < b0) != (st["random 0.3"].mean < st["random 0.1"].mean)
        shown = (f" The figure shows trial {r0['random 0.3'].get('trial', 0)} of "
                 f"{st['random 0.3'].n}, where R_a = 0.3 scores {num(a0)} m and 0.1 {num(b0)} m"
                 + (": it goes against the mean over the trials." if against else
                    ", in the same order as the mean over the trials."))
    findings = [
        f"The paper reports R_a = 0.3 better than 0.1: here RMSE {st['random 0.3'].fmt()} m vs "
        f"{st['random 0.1'].fmt()} m (missing {pct(miss['random 0.3'])} vs "
        f"{pct(miss['random 0.1'])}): {ra_v}.{why_ra}{shown}",
        f"The paper reports the m-sequence better than the Gold code: here RMSE "
        f"{st['mseq'].fmt()} m vs {st['gold'].fmt()} m: "
        f"{ms_v}.{why_ms}",
    ]
    claims = [
        Claim(
            name,
            "R_a = 0.3 better than 0.1 (m_n = 1)",
            "qualitative (Fig. 3a, b)",
            f"{num(st['random 0.3'].mean)} vs {num(st['random 0.1'].mean)} m",
            ra_v,
        ),
        Claim(
            name,
            "m-sequence better than Gold",
            "qualitative (Fig. 3c, d)",
            f"{num(st['mseq'].mean)} vs {num(st['gold'].mean)} m",
            ms_v,
        ),
    ]
    what = (
        f"{common_text(ctx)}, m_n = 1, 25 % patterns, QCR, FISTA; codes: Bernoulli random codes "
        f"of 2048 bits with R_a = 0.1 and 0.3, a Gold code and an m-sequence of 2047 bits (the "
        f"paper's 'length 2048': Gold codes and m-sequences exist only for 2^n - 1 bits); "
        f"PSST with the default replica (2s - 1 for a code with as many ones as zeros, the "
        f"m-sequence; s - mean(s) for the others, the Bernoulli codes and this Gold code); "
        f"{trials} trial(s) per code (the maps: trial 0)."
    )
    text = section(
        ctx,
        "Fig. 3: code kinds at m_n = 1",
        what,
        table,
        findings,
        rows=rows,
        figures=[("Fig. 3: depth maps by code kind", png)],
        data=[csv],
    )
    return text, claims


#: Fig. 2's code against the paper's, and an outside measurement of the paper's code
FIG2_CODE_NOTE = (
    "Code: the paper's Sec. III runs Fig. 2 with a random code of 2048 bits whose ones "
    "probability is 0.1, and so does this report (until 2026-11-29 it ran the 16383-bit "
    "m-sequence of Fig. 4's operating point, whose 8192 pulses per period against about 205 "
    "took every compression from 45 % on to the 1.5 cm bin's quantisation floor, 0.0043 m, "
    "and 25 % to 0.0057 m; docs/reading.md, 'Fig. 2's code'). Fig. 4 gives the longer "
    "codes."
)
