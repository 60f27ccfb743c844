"""Figures (matplotlib, imported lazily so the command-line tool starts fast)."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _colorbar(fig, ax, im, label="depth [m]"):
    cb = fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04)
    cb.set_label(label)
    return cb


def depth_figure(result, path: str | Path) -> Path:
    """``depth.png``: ground truth | estimate | error, colour bars in metres, RMSE in the title."""
    plt = _plt()
    truth = result.truth
    est = result.depth
    valid = result.scene.valid
    lo = float(np.min(truth[valid])) if valid.any() else float(np.nanmin(truth))
    hi = float(np.max(truth[valid])) if valid.any() else float(np.nanmax(truth))
    if hi <= lo:
        hi = lo + 1e-3
    err = est - truth
    err_masked = np.where(valid, err, np.nan)
    lim = float(np.nanpercentile(np.abs(err_masked), 99)) if np.isfinite(err_masked).any() else 0
    lim = max(lim, result.metrics["bin_depth_m"])
    fig, axes = plt.subplots(1, 3, figsize=(13, 4.2), constrained_layout=True)
    cmap = plt.get_cmap("viridis").with_extremes(bad="white")
    im = axes[0].imshow(truth, cmap=cmap, vmin=lo, vmax=hi)
    axes[0].set_title(f"ground truth: {result.scene.name}")
    _colorbar(fig, axes[0], im)
    im = axes[1].imshow(np.ma.masked_invalid(est), cmap=cmap, vmin=lo, vmax=hi)
    m = result.metrics
    axes[1].set_title(f"estimate ({100 * m['missing_fraction']:.1f}% no return, white)")
    _colorbar(fig, axes[1], im)
    ecmap = plt.get_cmap("RdBu_r").with_extremes(bad="0.6")
    im = axes[2].imshow(np.ma.masked_invalid(err_masked), cmap=ecmap, vmin=-lim, vmax=lim)
    axes[2].set_title("error: estimate - truth")
    _colorbar(fig, axes[2], im, "depth error [m]")
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    c = result.config
    fig.suptitle(
        f"{c.lidar.upper()} {m['code_description']}, {m['n_patterns']} {c.patterns} patterns "
        f"({100 * c.compression:g}%), m_s={c.signal:g}, m_n={c.noise:g}, "
        f"{'QCR' if c.qcr else 'no QCR'}, {c.solver}: depth RMSE = {m['depth_rmse_m']:.4f} m")
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
