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
            f"{'QCR' if c.qcr else 'no QCR'}, {c.solver}: depth RMSE = {m['depth_rmse_m']:.4f} m")


def depth_figure(result, path: str | Path, engine: str = "pil") -> Path:
    """``depth.png``: ground truth | estimate | error, colour bars in metres, RMSE in the title.

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
    m = result.metrics
    width, height = 3 * (_PANEL + 70) + 20, _PANEL + 80
    fig = Image.new("RGB", (width, height), (255, 255, 255))
    ImageDraw.Draw(fig).text((10, 4), _title(result), fill=(0, 0, 0))
    y0 = 20
    _panel(fig, 10, y0, _colormap(result.truth, lo, hi, _VIRIDIS, (255, 255, 255)),
           f"ground truth: {result.scene.name}", lo, hi, _VIRIDIS, "m")
    _panel(fig, 10 + _PANEL + 70, y0,
           _colormap(result.depth, lo, hi, _VIRIDIS, (255, 255, 255)),
           f"estimate ({100 * m['missing_fraction']:.1f}% no return, white)", lo, hi, _VIRIDIS,
           "m")
    _panel(fig, 10 + 2 * (_PANEL + 70), y0,
           _colormap(err_masked, -lim, lim, _RDBU_R, (153, 153, 153)),
           "error: estimate - truth", -lim, lim, _RDBU_R, "m")
    path = Path(path)
    fig.save(path, format="PNG", compress_level=1)
    return path


def _depth_figure_mpl(result, path: str | Path) -> Path:
    """The matplotlib version of :func:`depth_figure`."""
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
