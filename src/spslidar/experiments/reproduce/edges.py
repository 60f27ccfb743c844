"""Figures 5 and 7: Sobel edge maps of Figure 4's and Figure 6's depth maps (no QCR, QCR,
conventional), scored against the truth's edges; the runs are Figure 4's and Figure 6's, cached.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from spslidar.experiments.report import Claim, md_table
from spslidar.experiments.reproduce.code_length import conventional_params
from spslidar.experiments.reproduce.context import (
    Context,
    base_params,
    load_map,
    run_points,
    write_rows,
)
from spslidar.experiments.reproduce.plotting import new_figure, panel, save_figure, scene_of
from spslidar.experiments.reproduce.prose import section
from spslidar.experiments.reproduce.stats import (
    Stat,
    best_verdict,
    first_row,
    match_rows,
    num,
    stat,
    tally_verdict,
)
from spslidar.experiments.sweep import expand_grid


def edge_stats(depth: np.ndarray | None, truth: np.ndarray, valid: np.ndarray) -> dict:
    """Sobel map of ``depth``, its correlation with the truth's and its mean in flat areas."""
    from spslidar.metrics import edge_agreement, sobel_edges, truth_edge_mask

    if depth is None:
        return {"edge_correlation": math.nan, "spurious_edge_m": math.nan, "edges": None}
    e = sobel_edges(depth)
    t = sobel_edges(truth)
    flat = (t <= np.median(t[valid])) & valid
    return {
        "edge_correlation": edge_agreement(e, t, truth_edge_mask(valid)),
        "spurious_edge_m": float(np.mean(e[flat])),
        "edges": e,
    }


def _mm(s: Stat) -> str:
    """A flat-area edge magnitude in mm (mean ± std over trials)."""
    return Stat(1000 * s.mean, 1000 * s.std, s.n).fmt(2)


def edges_experiment(
    ctx: Context,
    name: str,
    source: str,
    scene_name: str,
    points: list[dict[str, Any]],
    cases: Sequence[tuple[str, dict[str, Any]]],
    fig_label: str,
    params_text: str,
    paper_fig: str,
) -> tuple[str, list[Claim]]:
    """An edge-map experiment: Sobel maps of another experiment's depth maps (the figure
    shows trial 0's; the scores are means over the trials, and "QCR best" needs a lead beyond
    their scatter and :data:`~spslidar.experiments.reproduce.stats.MARGIN`).

    Parameters
    ----------
    ctx : Context
        The reproduction.
    name : str
        This experiment (``fig5``, ``fig7``).
    source : str
        The experiment whose runs are reused (for the text).
    scene_name : str
        Its scene.
    points : list of dict
        Its runs (served from the cache when it ran first).
    cases : sequence of (str, dict)
        Label and row selection of each map: no QCR, QCR, conventional, in that order.
    fig_label, params_text, paper_fig : str
        Figure label, parameters and the paper's figure, for titles and text.

    Returns
    -------
    tuple of (str, list of Claim)
        The report section and its claim.
    """
    rows = run_points(ctx, points)
    scene = scene_of(ctx, scene_name)
    stats = {}  # trial 0's maps, shown in the figure
    over = {}  # each score over the trials, for the verdicts
    sel_rows = []
    for label, kw in cases:
        row = first_row(rows, **kw)
        stats[label] = edge_stats(load_map(ctx, row), scene.depth, scene.valid)
        scores = []
        for r in match_rows(rows, **kw):
            st = stats[label] if r is row else edge_stats(load_map(ctx, r), scene.depth,
                                                          scene.valid)
            scores.append({"edge_correlation_truth": st["edge_correlation"],
                           "spurious_edge_m": st["spurious_edge_m"]})
            sel_rows.append({**r, "case": label, **scores[-1]})
        over[label] = {k: stat(scores, k) for k in ("edge_correlation_truth",
                                                     "spurious_edge_m")}
    csv = write_rows(ctx, name, sel_rows)
    t_edges = edge_stats(scene.depth, scene.depth, scene.valid)["edges"]
    vmax = float(np.percentile(t_edges, 99.5))
    fig = new_figure(1, len(cases) + 1)
    axes = fig.subplots(1, len(cases) + 1).ravel()
    panel(
        fig, axes[0], t_edges, "Sobel of ground truth", 0, vmax, "Sobel magnitude [m]", cmap="gray"
    )
    for i, (label, _) in enumerate(cases):
        st = stats[label]
        title = (
            f"({chr(97 + i)}) {label}\ncorr. with truth {num(st['edge_correlation'], 3)}, "
            f"flat-area {num(1000 * st['spurious_edge_m'], 1)} mm"
        )
        panel(fig, axes[i + 1], st["edges"], title, 0, vmax, "Sobel magnitude [m]", cmap="gray")
    png = save_figure(ctx, name, fig, f"{fig_label}: Sobel edge maps, {params_text}")
    n_trials = min((over[label]["spurious_edge_m"].n for label, _ in cases), default=0)
    table = md_table(
        (
            "reconstruction",
            "edge correlation with truth",
            "mean edge magnitude in flat areas [mm]",
            "depth RMSE [m]",
        ),
        [
            (
                label,
                over[label]["edge_correlation_truth"].fmt(3),
                _mm(over[label]["spurious_edge_m"]),
                stat(rows, **kw).fmt(),
            )
            for label, kw in cases
        ],
    )
    labels = [label for label, _ in cases]
    qcr_label = labels[1]
    # "QCR best" on each score, told apart from the nearest rival only beyond the trials'
    # scatter and the margin (a 0.7 % lead in one trial was called "much smoother")
    v_corr, why_corr = best_verdict({k: over[k]["edge_correlation_truth"] for k in labels},
                                    qcr_label, higher=True)
    v_flat, why_flat = best_verdict({k: over[k]["spurious_edge_m"] for k in labels}, qcr_label)
    vs = (v_corr, v_flat)
    verdict = tally_verdict(vs.count("consistent"), vs.count("not consistent"), 2)

    def corr(k: str) -> str:
        return num(over[k]["edge_correlation_truth"].mean, 3)

    def flat(k: str) -> str:
        return num(1000 * over[k]["spurious_edge_m"].mean, 2)

    # each score's verdict says why it is not "consistent" (Fig. 5's "not consistent" rested
    # on the flat-area score, which the finding did not name: an outside review, 2026-12-01)
    why = ""
    for score, key, higher, show, v, clause in (
            ("Edge correlation", "edge_correlation_truth", True, corr, v_corr, why_corr),
            ("Flat-area edges", "spurious_edge_m", False, lambda k: f"{flat(k)} mm", v_flat,
             why_flat)):
        if v == "inconclusive":
            why += f" {score}:{clause}"
        elif v == "not consistent":
            best = sorted(labels, key=lambda k: over[k][key].mean, reverse=higher)[0]
            why += (f" {score}: not consistent, the {'highest' if higher else 'smoothest'} is "
                    f"{show(best)} ({best}) against {show(qcr_label)} ({qcr_label}).")

    findings = [
        f"The paper finds the QCR edge map 'more robust to noise and much smoother' ({paper_fig})."
        f" Here its Sobel map correlates with the truth's at {corr(qcr_label)} (no QCR "
        f"{corr(labels[0])}, conventional {corr(labels[2])}) and its mean edge magnitude in the "
        f"truth's flat half is {flat(qcr_label)} mm (no QCR {flat(labels[0])}, conventional "
        f"{flat(labels[2])} mm), over {n_trials} trial(s): {verdict}.{why}"
    ]
    claims = [
        Claim(
            name,
            "QCR edges closest to truth and smoothest",
            f"qualitative ({paper_fig})",
            f"corr. {corr(qcr_label)} vs {corr(labels[0])} / {corr(labels[2])}",
            verdict,
        )
    ]
    what = (
        f"Sobel gradient magnitude (`spslidar.metrics.sobel_edges`) of the depth maps of "
        f"{source} ({params_text}), reused from its cached runs; scored by the Pearson "
        f"correlation with the truth's Sobel map and by the mean edge magnitude over the pixels "
        f"where the truth's is below its median (spurious edges: lower is smoother); "
        f"{n_trials} trial(s) per map, mean ± sample std (the figure: trial 0)."
    )
    text = section(
        ctx,
        f"{fig_label}: edge maps",
        what,
        table,
        findings,
        rows=rows,
        figures=[(f"{fig_label}: Sobel edge maps", png)],
        data=[csv],
    )
    return text, claims


def exp_fig5(ctx: Context) -> tuple[str, list[Claim]]:
    """Fig. 5: Sobel edges of Fig. 4's no-QCR, QCR (16383 bits) and conventional maps."""
    trials = ctx.n_trials(full=3)  # Fig. 4's runs (its default), served from its cache
    points = []
    for qcr in (False, True):
        points += expand_grid(base_params(ctx, code_length=16383, qcr=qcr), {}, trials)
    points += expand_grid(conventional_params(ctx, "camera", 10.0, False), {}, trials)
    cases = (
        ("no QCR, 16383 bits", {"lidar": "psst", "code_length": 16383, "qcr": False}),
        ("QCR, 16383 bits", {"lidar": "psst", "code_length": 16383, "qcr": True}),
        ("conventional", {"lidar": "conventional", "qcr": False}),
    )
    return edges_experiment(
        ctx,
        "fig5",
        "Fig. 4",
        "camera",
        points,
        cases,
        "Fig. 5",
        f"camera {ctx.size}x{ctx.size}, m_n=10, m-sequence 16383 bits / conventional, FISTA",
        "Fig. 5",
    )



def exp_fig7(ctx: Context) -> tuple[str, list[Claim]]:
    """Fig. 7: Sobel edges of Fig. 6's m_n = 10 maps (no QCR, QCR, conventional)."""
    trials = ctx.n_trials()  # Fig. 6's runs (its default), served from its cache
    points = []
    for qcr in (False, True):
        points += expand_grid(base_params(ctx, scene="motorcycle", noise=10.0, qcr=qcr), {},
                              trials)
    points += expand_grid(conventional_params(ctx, "motorcycle", 10.0, False), {}, trials)
    cases = (
        ("no QCR", {"lidar": "psst", "noise": 10.0, "qcr": False}),
        ("QCR", {"lidar": "psst", "noise": 10.0, "qcr": True}),
        ("conventional", {"lidar": "conventional", "noise": 10.0, "qcr": False}),
    )
    return edges_experiment(
        ctx,
        "fig7",
        "Fig. 6",
        "motorcycle",
        points,
        cases,
        "Fig. 7",
        f"motorcycle {ctx.size}x{ctx.size}, m_n=10, m-sequence 16383 bits / conventional, FISTA",
        "Fig. 7",
    )
