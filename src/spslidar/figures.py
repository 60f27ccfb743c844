"""Figures: ``depth.png`` of a run, drawn with Pillow (fast), or with matplotlib on request.

``spslidar run`` writes ``depth.png`` after every run, so it must be cheap: importing
``matplotlib.pyplot`` alone takes 0.4-2 s on a 2-core machine (2.2 s measured under load)
against ~30 ms for Pillow, and rendering a 13 x 4 inch figure another ~0.2 s. The default
:func:`depth_figure` therefore composes the three panels (truth | estimate | error) as
colour-mapped images with Pillow (colour bars with their ranges, the title with the RMSE);
``engine='matplotlib'`` gives the publication version with axes and tick labels.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: matplotlib's ``viridis`` and ``RdBu_r`` at 17 evenly spaced points (interpolated linearly)
_VIRIDIS = ((68, 1, 84), (72, 24, 106), (71, 45, 123), (66, 64, 134), (59, 82, 139),
            (51, 99, 141), (44, 114, 142), (38, 130, 142), (33, 145, 140), (31, 160, 136),
            (40, 174, 128), (63, 188, 115), (94, 201, 98), (132, 212, 75), (173, 220, 48),
            (216, 226, 25), (253, 231, 37))
_RDBU_R = ((5, 48, 97), (23, 82, 144), (42, 113, 178), (63, 142, 192), (107, 172, 209),
           (155, 201, 224), (194, 221, 236), (224, 236, 243), (247, 246, 246), (251, 229, 216),
           (251, 204, 180), (245, 170, 137), (228, 128, 102), (208, 85, 72), (186, 40, 50),
           (147, 14, 38), (103, 0, 31))
#: panel size (pixels) of the Pillow figure
_PANEL = 320


def _plt():
    import matplotlib

    matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    return plt


def _colorbar(fig, ax, im, label="depth [m]"):
    cb = fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04)
    cb.set_label(label)
    return cb


def _colormap(values: np.ndarray, lo: float, hi: float, table, bad) -> np.ndarray:
    """``(H, W, 3)`` uint8 colours of ``values`` over ``[lo, hi]`` (NaN -> ``bad``)."""
    lut = np.asarray(table, dtype=np.float64)
    t = (np.asarray(values, dtype=np.float64) - lo) / (hi - lo if hi > lo else 1.0)
    finite = np.isfinite(t)
    t = np.clip(np.where(finite, t, 0.0), 0.0, 1.0) * (len(lut) - 1)
    i = np.minimum(t.astype(int), len(lut) - 2)
    f = (t - i)[..., None]
    rgb = lut[i] * (1 - f) + lut[i + 1] * f
    rgb[~finite] = bad
    return np.round(rgb).astype(np.uint8)


def _panel(draw_img, x0: int, y0: int, rgb: np.ndarray, title: str, lo: float, hi: float,
           table, unit: str) -> None:
    """Paste one colour-mapped panel with its title and a colour bar labelled lo .. hi."""
    from PIL import Image, ImageDraw

    img = Image.fromarray(rgb).resize((_PANEL, _PANEL), Image.NEAREST)
    draw_img.paste(img, (x0, y0 + 22))
    d = ImageDraw.Draw(draw_img)
    d.text((x0, y0 + 4), title, fill=(0, 0, 0))
    bar = _colormap(np.linspace(hi, lo, _PANEL)[:, None] * np.ones((1, 12)), lo, hi, table, 0)
    draw_img.paste(Image.fromarray(bar), (x0 + _PANEL + 6, y0 + 22))
    d.text((x0 + _PANEL + 22, y0 + 22), f"{hi:.3g}", fill=(0, 0, 0))
    d.text((x0 + _PANEL + 22, y0 + 22 + _PANEL // 2 - 6), unit, fill=(0, 0, 0))
    d.text((x0 + _PANEL + 22, y0 + 10 + _PANEL), f"{lo:.3g}", fill=(0, 0, 0))


#: colours (RGB) of the pixels a depth map cannot show, one per reason, named in the legend
NO_TRUTH = (150, 150, 150)  # grey: the scene has no ground truth there (e.g. a stereo hole)
NO_RETURN = (255, 255, 255)  # white: the estimator found no return
LOW_CONFIDENCE = (230, 0, 200)  # magenta dot: a depth the estimator itself does not trust


def _classes(result) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Masks of the pixels without ground truth, without a return, and with a low-confidence
    depth (a return the depth estimator flags)."""
    valid = np.asarray(result.scene.valid, dtype=bool)
    no_return = ~np.isfinite(result.depth)
    low = result.low_confidence
    low = (np.zeros_like(valid) if low is None
           else np.asarray(low, dtype=bool).reshape(valid.shape) & ~no_return)
    return ~valid, no_return, low


def _legend_items(result) -> list[tuple[tuple[int, int, int], str]]:
    no_truth, no_return, low = _classes(result)
    return [(NO_TRUTH, f"no ground truth ({100 * no_truth.mean():.0f}%)"),
            (NO_RETURN, f"no return ({100 * no_return.mean():.1f}%)"),
            (LOW_CONFIDENCE, f"low-confidence depth ({100 * low.mean():.0f}%, dot)")]


def _limits(result):
    truth, valid = result.truth, result.scene.valid
    lo = float(np.min(truth[valid])) if valid.any() else float(np.nanmin(truth))
    hi = float(np.max(truth[valid])) if valid.any() else float(np.nanmax(truth))
    if hi <= lo:
        hi = lo + 1e-3
    err_masked = np.where(valid, result.depth - truth, np.nan)
    lim = float(np.nanpercentile(np.abs(err_masked), 99)) if np.isfinite(err_masked).any() else 0
    return lo, hi, err_masked, max(lim, result.metrics["bin_depth_m"])


def _title(result) -> str:
    c, m = result.config, result.metrics
    return (f"{c.lidar.upper()} {m['code_description']}, {m['n_patterns']} {c.patterns} patterns "
            f"({100 * c.compression:g}%), m_s={c.signal:g}, m_n={c.noise:g}, "
            f"{'QCR' if c.qcr else 'no QCR'}, {c.solver}, {c.depth} depth: RMSE = "
            f"{m['depth_rmse_m']:.4f} m over {100 * m.get('coverage', float('nan')):.0f}% "
            f"of pixels")


def depth_figure(result, path: str | Path, engine: str = "pil") -> Path:
    """``depth.png``: ground truth | estimate | error, colour bars in metres.

    Every pixel without a number has the colour of its reason, named in a legend: grey where
    the scene has no ground truth (truth and error panels), white where the estimator found no
    return (estimate and error panels), and a magenta dot on the depths the estimator flags
    as low-confidence (estimate panel). The title gives the RMSE with the share of pixels it
    covers (ground truth and a return).

    Parameters
    ----------
    result : Result
    path : str or Path
    engine : {'pil', 'matplotlib'}
        ``'pil'`` (default): Pillow, ~30 ms with its import (module docstring);
        ``'matplotlib'``: the figure with axes, 0.5-2.5 s with the import.
    """
    if engine == "matplotlib":
        return _depth_figure_mpl(result, path)
    from PIL import Image, ImageDraw

    lo, hi, err_masked, lim = _limits(result)
    no_truth, no_return, low = _classes(result)
    m = result.metrics
    width, height = 3 * (_PANEL + 70) + 20, _PANEL + 100
    fig = Image.new("RGB", (width, height), (255, 255, 255))
    draw = ImageDraw.Draw(fig)
    draw.text((10, 4), _title(result), fill=(0, 0, 0))
    y0 = 20
    truth_rgb = _colormap(result.truth, lo, hi, _VIRIDIS, NO_TRUTH)
    truth_rgb[no_truth] = NO_TRUTH
    _panel(fig, 10, y0, truth_rgb, f"ground truth: {result.scene.name}", lo, hi, _VIRIDIS, "m")
    x1 = 10 + _PANEL + 70
    _panel(fig, x1, y0, _colormap(result.depth, lo, hi, _VIRIDIS, NO_RETURN),
           f"estimate: {100 * m['missing_fraction']:.1f}% no return, "
           f"{100 * low.mean():.0f}% low-confidence", lo, hi, _VIRIDIS, "m")
    if low.any():  # a dot in the middle of each low-confidence pixel
        cell = _PANEL / low.shape[0]
        r = max(1.0, cell / 5)
        for yy, xx in zip(*np.nonzero(low), strict=True):
            cx, cy = x1 + (xx + 0.5) * cell, y0 + 22 + (yy + 0.5) * cell
            draw.ellipse((cx - r, cy - r, cx + r, cy + r), fill=LOW_CONFIDENCE)
    err_rgb = _colormap(err_masked, -lim, lim, _RDBU_R, NO_RETURN)
    err_rgb[no_truth] = NO_TRUTH
    _panel(fig, 10 + 2 * (_PANEL + 70), y0, err_rgb, "error: estimate - truth", -lim, lim,
           _RDBU_R, "m")
    x, y = 10, y0 + _PANEL + 50
    for colour, text in _legend_items(result):
        draw.rectangle((x, y, x + 14, y + 12), fill=colour, outline=(80, 80, 80))
        draw.text((x + 20, y + 1), text, fill=(0, 0, 0))
        x += 28 + 7 * len(text)
    path = Path(path)
    fig.save(path, format="PNG", compress_level=1)
    return path


def _depth_figure_mpl(result, path: str | Path) -> Path:
    """The matplotlib version of :func:`depth_figure` (same colours and legend)."""
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    plt = _plt()
    lo, hi, err_masked, lim = _limits(result)
    no_truth, no_return, low = _classes(result)

    def paint(ax, mask, colour):
        if mask.any():
            ax.imshow(np.ma.masked_where(~mask, np.ones(mask.shape)),
                      cmap=ListedColormap([np.asarray(colour) / 255]), vmin=0, vmax=1,
                      interpolation="nearest")

    fig, axes = plt.subplots(1, 3, figsize=(13, 4.6), constrained_layout=True)
    cmap = plt.get_cmap("viridis")
    im = axes[0].imshow(np.ma.masked_where(no_truth, result.truth), cmap=cmap, vmin=lo, vmax=hi)
    paint(axes[0], no_truth, NO_TRUTH)
    axes[0].set_title(f"ground truth: {result.scene.name}")
    _colorbar(fig, axes[0], im)
    im = axes[1].imshow(np.ma.masked_invalid(result.depth), cmap=cmap, vmin=lo, vmax=hi)
    paint(axes[1], no_return, NO_RETURN)
    if low.any():
        yy, xx = np.nonzero(low)
        axes[1].scatter(xx, yy, s=max(1.0, 400.0 / low.shape[0]),
                        color=np.asarray(LOW_CONFIDENCE) / 255, linewidths=0)
    m = result.metrics
    axes[1].set_title(f"estimate: {100 * m['missing_fraction']:.1f}% no return, "
                      f"{100 * low.mean():.0f}% low-confidence")
    _colorbar(fig, axes[1], im)
    im = axes[2].imshow(np.ma.masked_invalid(err_masked), cmap=plt.get_cmap("RdBu_r"),
                        vmin=-lim, vmax=lim)
    paint(axes[2], no_truth, NO_TRUTH)
    paint(axes[2], ~no_truth & no_return, NO_RETURN)
    axes[2].set_title("error: estimate - truth")
    _colorbar(fig, axes[2], im, "depth error [m]")
    for ax in axes:
        ax.set_xticks([])
        ax.set_yticks([])
    fig.legend(handles=[Patch(facecolor=np.asarray(c) / 255, edgecolor="0.3", label=t)
                        for c, t in _legend_items(result)],
               loc="outside lower center", ncol=3, frameon=False)
    fig.suptitle(_title(result))
    path = Path(path)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path
