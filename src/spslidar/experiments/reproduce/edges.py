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
from spslidar.experiments.reproduce.stats import count_verdict, first_row, num
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
    """An edge-map experiment: Sobel maps of another experiment's trial-0 depth maps.

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
    stats = {}
    sel_rows = []
    for label, kw in cases:
        row = first_row(rows, **kw)
        st = edge_stats(load_map(ctx, row), scene.depth, scene.valid)
        stats[label] = st
        if row is not None:
            sel_rows.append(
                {
                    **row,
                    "case": label,
                    "edge_correlation_truth": st["edge_correlation"],
                    "spurious_edge_m": st["spurious_edge_m"],
                }
            )
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
                num(stats[label]["edge_correlation"], 3),
                num(1000 * stats[label]["spurious_edge_m"], 2),
                num(first_row(rows, **kw)["depth_rmse_m"]) if first_row(rows, **kw) else "—",
            )
            for label, kw in cases
        ],
    )
    labels = [label for label, _ in cases]
    qcr_label = labels[1]
    best_corr = max(labels, key=lambda k: np.nan_to_num(stats[k]["edge_correlation"], nan=-9))
    best_flat = min(labels, key=lambda k: np.nan_to_num(stats[k]["spurious_edge_m"], nan=9e9))
    ok_corr = best_corr == qcr_label
    ok_flat = best_flat == qcr_label
    verdict = count_verdict(int(ok_corr) + int(ok_flat), 2)
    findings = [
        f"The paper finds the QCR edge map 'more robust to noise and much smoother' ({paper_fig})."
        f" Here its Sobel map correlates with the truth's at "
        f"{num(stats[qcr_label]['edge_correlation'], 3)} (no QCR "
        f"{num(stats[labels[0]]['edge_correlation'], 3)}, conventional "
        f"{num(stats[labels[2]]['edge_correlation'], 3)}) and its mean edge magnitude in the "
        f"truth's flat half is {num(1000 * stats[qcr_label]['spurious_edge_m'], 2)} mm (no QCR "
        f"{num(1000 * stats[labels[0]]['spurious_edge_m'], 2)}, conventional "
        f"{num(1000 * stats[labels[2]]['spurious_edge_m'], 2)} mm): {verdict}."
    ]
    claims = [
        Claim(
            name,
            "QCR edges closest to truth and smoothest",
            f"qualitative ({paper_fig})",
            f"corr. {num(stats[qcr_label]['edge_correlation'], 3)} vs "
            f"{num(stats[labels[0]]['edge_correlation'], 3)} / "
            f"{num(stats[labels[2]]['edge_correlation'], 3)}",
            verdict,
        )
    ]
    what = (
        f"Sobel gradient magnitude (`spslidar.metrics.sobel_edges`) of the trial-0 depth maps of "
        f"{source} ({params_text}), reused from its cached runs; scored by the Pearson "
        f"correlation with the truth's Sobel map and by the mean edge magnitude over the pixels "
        f"where the truth's is below its median (spurious edges: lower is smoother)."
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
    points = []
    for qcr in (False, True):
        points += expand_grid(base_params(ctx, code_length=16383, qcr=qcr), {}, 1)
    points += expand_grid(conventional_params(ctx, "camera", 10.0, False), {}, 1)
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
    points = []
    for qcr in (False, True):
        points += expand_grid(base_params(ctx, scene="motorcycle", noise=10.0, qcr=qcr), {}, 1)
    points += expand_grid(conventional_params(ctx, "motorcycle", 10.0, False), {}, 1)
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
