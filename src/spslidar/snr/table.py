"""Sweeps of equation (10) against its simulation (:func:`snr_table`) and their figure
(:func:`plot_snr`)."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from spslidar.snr.simulate import snr_simulated
from spslidar.snr.theory import config_error

if TYPE_CHECKING:  # pragma: no cover
    import numpy as np

__all__ = ["plot_snr", "snr_table"]


def _as_list(value: Any) -> list:
    if isinstance(value, (str, bytes)) or not isinstance(value, Iterable):
        return [value]
    return list(value)


def snr_table(
    codes: str | Sequence[str],
    lengths: int | Sequence[int],
    ones_ratios: float | Sequence[float],
    signal: float,
    noise: float,
    size: int,
    on_fraction: float,
    reflectivity: float = 1.0,
    trials: int = 200,
    rng: np.random.Generator | int | None = None,
    *,
    method: str = "sum",
    interval: str = "delta",
    code_index: int | None = None,
    skip_invalid: bool = False,
) -> list[dict[str, Any]]:
    """Theory and simulated SNR over a grid of code kinds, lengths and ones ratios.

    Parameters
    ----------
    codes : str or sequence of str
        Code kinds (``'mseq'``, ``'gold'``, ``'random'``).
    lengths : int or sequence of int
        Code lengths ``T``.
    ones_ratios : float or sequence of float
        Shares of '1' bits; swept for random codes only (mseq and Gold codes get one row per
        length, with their own share).
    signal, noise, size, on_fraction, reflectivity, trials
        As in :func:`snr_simulated`, the same for every row.
    rng : numpy.random.Generator or int or None, optional
        Generator or seed; the rows draw from it in order (codes, then lengths, then ratios).
    method, interval, code_index
        As in :func:`snr_simulated`.
    skip_invalid : bool, optional
        Leave out (code, length) pairs the code kind does not support (e.g. Gold codes of
        length ``2^12 - 1``) instead of raising ConfigError (default False).

    Returns
    -------
    list of dict
        One tidy row per grid point: the dicts of :func:`snr_simulated` (every parameter a
        column, plus ``theory``, ``simulated``, ``stderr``, ``ci_low``, ``ci_high``).

    Raises
    ------
    ConfigError
        On invalid parameters (see :func:`snr_simulated`).

    Notes
    -----
    Each row compares eq. (10) with its simulation; with the photon numbers fixed the theory is
    proportional to ``T R_a``, a straight line of slope 1 on log-log axes.
    """

    from ..errors import ConfigError
    from ..randomness import as_generator
    from .theory import code_family

    gen = as_generator(rng)
    rows: list[dict[str, Any]] = []
    ratios = _as_list(ones_ratios)
    if not ratios:
        raise config_error("ones_ratios is empty: give at least one share of '1' bits")
    for kind in (code_family(c) for c in _as_list(codes)):
        for length in _as_list(lengths):
            # a family with a fixed share of ones (m-sequence, Gold) gets one row, at 0.5
            for ratio in ratios if kind == "random" else [0.5]:
                try:
                    row = snr_simulated(
                        kind,
                        length,
                        ratio,
                        signal,
                        noise,
                        size,
                        on_fraction,
                        reflectivity,
                        trials,
                        gen,
                        method=method,
                        interval=interval,
                        code_index=code_index,
                    )
                except ConfigError as exc:
                    if skip_invalid and str(exc).startswith("code length"):
                        continue
                    raise
                rows.append(row)
    return rows


def _series_label(row: dict[str, Any]) -> str:
    # (the figure said "random" where reproduce's table says Bernoulli: an audit)
    names = {"mseq": "m-sequence", "gold": "Gold", "random": "Bernoulli"}
    label = names.get(row["code"], row["code"])
    if row["code"] == "random":
        label += f", R_a = {row['ones_ratio']:g}"
    return label


def _fmt_values(rows: Sequence[dict[str, Any]], key: str) -> str:
    values = sorted({row[key] for row in rows})
    return "/".join(f"{v:g}" for v in values)


def plot_snr(rows: Sequence[dict[str, Any]], path: str | Path) -> Path:
    """Draw an SNR sweep: log-log SNR against code length, theory lines, simulated markers.

    Parameters
    ----------
    rows : sequence of dict
        Rows of :func:`snr_table` (or :func:`snr_simulated` dicts).
    path : str or pathlib.Path
        Output image file (format from its suffix, e.g. ``.png``, ``.pdf``).

    Returns
    -------
    pathlib.Path
        ``path``.

    Raises
    ------
    ConfigError
        If ``rows`` is empty.

    Notes
    -----
    One series per code kind and ones ratio: eq. (10) as a line, the simulation as markers with
    95 % error bars. Theory lines have slope 1 (SNR proportional to ``T R_a``, eq. 10). The
    title lists ``m_s``, ``m_n``, ``N`` and ``F`` (several values are joined by '/').
    Matplotlib is imported here, through its object-oriented API (no pyplot state).
    """
    from matplotlib.figure import Figure

    rows = list(rows)
    if not rows:
        raise config_error("no SNR rows to plot")
    series: dict[str, list[dict[str, Any]]] = {}
    for row in rows:
        series.setdefault(_series_label(row), []).append(row)
    fig = Figure(figsize=(6.4, 6.0), layout="constrained")
    ax = fig.add_subplot()
    for i, (label, group) in enumerate(series.items()):
        group = sorted(group, key=lambda r: r["code_length"])
        x = [r["code_length"] for r in group]
        color = f"C{i % 10}"
        ax.plot(x, [r["theory"] for r in group], "-", color=color, label=f"{label}: eq. (10)")
        y = [r["simulated"] for r in group]
        lo = [max(r["simulated"] - r["ci_low"], 0.0) for r in group]
        hi = [max(r["ci_high"] - r["simulated"], 0.0) for r in group]
        ax.errorbar(
            x,
            y,
            yerr=[lo, hi],
            fmt="o",
            color=color,
            mfc="none",
            capsize=3,
            label=f"{label}: simulated (95 %)",
        )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("code length T [bits]")
    ax.set_ylabel("output SNR of one pattern [1]")
    ax.grid(True, which="both", alpha=0.3)
    # below the axes, where it covers no point (the default "best" place inside covered the
    # longest Bernoulli point, the one furthest from theory: an audit)
    fig.legend(fontsize="small", loc="outside lower center", ncol=2)
    ax.set_title(
        f"m_s = {_fmt_values(rows, 'signal')} photons/pulse/pixel, "
        f"m_n = {_fmt_values(rows, 'noise')} counts/bin/pixel,\n"
        f"N = {_fmt_values(rows, 'size')}, F = {_fmt_values(rows, 'on_fraction')}, "
        f"{rows[0]['trials']} periods per point, unipolar replica",
        fontsize="medium",
    )
    from ..outwrite import atomic_path

    path = Path(path)
    with atomic_path(path) as tmp:  # (an interrupt leaves no partial PNG over a user's)
        fig.savefig(tmp, dpi=120, format=path.suffix.lstrip(".") or "png")
    return path
