"""Figures of the reproduction: depth-map panels with colour bars in metres, titles that say
each run's RMSE and time, and the saved PNG of an experiment.

Matplotlib is used through its object-oriented API (no pyplot state) and imported only here.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from spslidar.experiments.reproduce.context import Context, load_map
from spslidar.experiments.reproduce.stats import pct

__all__ = [
    "map_panel",
    "new_figure",
    "panel",
    "run_title",
    "save_figure",
    "save_png",
    "scene_of",
    "truth_range",
]


def new_figure(nrows: int, ncols: int, w: float = 3.2, h: float = 2.9):
    """A constrained-layout figure of ``nrows x ncols`` panels of ``w x h`` inches."""
    from matplotlib.figure import Figure

    return Figure(figsize=(ncols * w, nrows * h + 0.5), layout="constrained")


def scene_of(ctx: Context, name: str):
    """The built-in scene ``name`` at the context's image size."""
    from spslidar.scenes import load_scene

    return load_scene(name, ctx.size)


def truth_range(scene) -> tuple[float, float]:
    """Colour range of a scene's valid true depths (at least 1 mm wide)."""
    d = scene.depth[scene.valid]
    lo, hi = float(d.min()), float(d.max())
    return lo, max(hi, lo + 1e-3)


def panel(
    fig,
    ax,
    image: np.ndarray | None,
    title: str,
    lo: float | None = None,
    hi: float | None = None,
    label: str = "depth [m]",
    cmap: str = "viridis",
) -> None:
    """Draw ``image`` (NaN white) with a colour bar, or "run failed" when it is None."""
    import matplotlib

    ax.set_xticks([])
    ax.set_yticks([])
    ax.set_title(title, fontsize=8)
    if image is None:
        ax.text(0.5, 0.5, "run failed", ha="center", va="center", transform=ax.transAxes)
        return
    colours = matplotlib.colormaps[cmap].with_extremes(bad="white")
    im = ax.imshow(np.ma.masked_invalid(image), cmap=colours, vmin=lo, vmax=hi)
    cb = fig.colorbar(im, ax=ax, fraction=0.046, pad=0.03)
    cb.set_label(label, fontsize=8)
    cb.ax.tick_params(labelsize=7)


def save_png(fig, path: Path, dpi: int = 100) -> Path:
    """Save ``fig`` at ``dpi`` (100) as ``path``, all or nothing: written under a temporary
    name in its folder and moved into place once complete (Ctrl-C while matplotlib writes
    left a truncated PNG)."""
    from spslidar.outwrite import atomic_path

    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, format=Path(path).suffix.lstrip(".") or "png")
    return Path(path)


def run_title(row: dict[str, Any] | None, label: str) -> str:
    """``label`` and the run's RMSE, time and share of missing pixels (any: Fig. 6's panel (e)
    showed a white pixel, 0.3 % of them, under a title that did not say so)."""
    if row is None:
        return f"{label}\n(run failed)"
    extra = ""
    miss = row["missing_fraction"]
    if miss > 0:
        extra = f", {pct(miss) if miss >= 0.0005 else '< 0.1 %'} missing (white)"
    return f"{label}\nRMSE {row['depth_rmse_m']:.4f} m, {row['time_total_s']:.1f} s{extra}"


def map_panel(
    ctx: Context, fig, ax, row: dict[str, Any] | None, label: str, lo: float, hi: float
) -> None:
    """The depth map of one run as a panel titled with ``label`` and the run's numbers (of
    trial 0, said where the experiment ran more: Fig. 3's panels read 0.0094 against the
    table's 0.0119 +- 0.0015 m over five trials, without a word)."""
    if row is not None and getattr(ctx, "last_trials", 1) > 1:
        label = f"{label} (trial {row.get('trial', 0)})"
    panel(fig, ax, load_map(ctx, row), run_title(row, label), lo, hi)


def save_figure(ctx: Context, name: str, fig, title: str) -> Path:
    """Title ``fig`` and save it as the experiment's figure ``DIR/<name>/<name>.png``."""
    fig.suptitle(title)
    return save_png(fig, ctx.folder(name) / f"{name}.png")
