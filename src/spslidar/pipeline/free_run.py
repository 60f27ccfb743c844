"""A free-running DMD (``--first-pattern I``): a DMD that loops its pattern sequence on its
own while the time tagger records from some moment on. The file's first marker block then
shows pattern ``I``, not 0, and the recording stops wherever it stops, so its number of
blocks ``B`` is no multiple of the ``M`` patterns: block ``b`` shows pattern ``(I + b) mod M``,
and each pattern's blocks are summed (histograms and dwells, as ``--repeats`` sums them:
:func:`~spslidar.pipeline.blocks.fold_repeats`), whatever their number.

The flag says the sequence loops, so it goes with neither ``--repeats`` (the passes are
whatever the file holds) nor ``--frame`` (no pass is whole but by chance), nor several
``--ptu`` files (each would start at its own pattern); each is refused in one line.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from ..errors import ConfigError

__all__ = ["AUTO_MARGIN", "AUTO_MAX", "AUTO_SMOOTH", "CHECK_MAX", "auto_note", "block_numbers",
           "check_first_pattern", "check_given", "find_first_pattern", "free_block_patterns",
           "resolve_first"]


def check_first_pattern(first: Any, m: int, *, repeats: int = 1, n_files: int = 1,
                        frame: Any = None) -> int | str | None:
    """``--first-pattern`` (the ``--patterns`` row, from 0, that the file's first marker
    block shows) as an int in ``[0, m)``, ``"auto"`` (found from the data:
    :func:`find_first_pattern`), or None where not given; one line (:class:`ConfigError`)
    for anything else, and for ``--repeats`` of 2 or more, several files or ``--frame``
    with it."""
    if first is None:
        return None
    from ..arrays import real_number

    value = real_number(first)
    auto = isinstance(first, str) and first == "auto"  # (an array compared is no bool)
    if auto:
        pass
    elif value is None or not (math.isfinite(value) and value == int(value)):
        raise ConfigError(f"--first-pattern must be a whole number, the --patterns row (from 0) "
                          f"the file's first marker block shows, or auto, got {first!r}")
    elif not 0 <= value < m:
        raise ConfigError(f"--first-pattern must be a row of --patterns, 0 to {m - 1} ({m} "
                          f"patterns), got {int(value)}")
    if repeats != 1:
        raise ConfigError("--first-pattern reads a free-running sequence, looped any number "
                          "of times, each pattern's blocks summed: leave --repeats out")
    if n_files > 1:
        raise ConfigError(f"--first-pattern reads one PTU file (each file of a free-running "
                          f"sequence starts at its own pattern), got {n_files}: reconstruct "
                          f"them one at a time")
    if frame is not None:
        raise ConfigError("--frame picks one repeat of a sequence shown --repeats times; a "
                          "free-running sequence (--first-pattern) is summed over every pass")
    return "auto" if auto else int(value)


def block_numbers(first: int | None, n_blocks: int, m: int) -> np.ndarray:
    """The pattern each of ``n_blocks`` marker blocks shows: ``(first + b) mod m``
    (``first`` None: 0, block ``b`` showing pattern ``b mod m`` as under ``--repeats``)."""
    return (int(first or 0) + np.arange(n_blocks)) % m


def free_block_patterns(shown: np.ndarray, numbers: np.ndarray) -> np.ndarray:
    """What the screening reads of each block's pattern (its light alone, a column, as
    :func:`~spslidar.pipeline.blocks.block_patterns` gives under ``--repeats``): no
    ``(B, Q)`` copy of the patterns for a long free-running file."""
    return shown.sum(axis=1, dtype=np.float64)[numbers][:, None]


#: ``--first-pattern auto`` picks an offset only where its fit beats the runner-up's by this
#: much (chi-square units: the difference of the two residuals over the noise variance).
#: Chosen on seeds 0-2 (216 simulated single passes: the best fit of a wrong offset stood at
#: most 7.3 above the runner-up); on seeds 3-5 (432 files of 1 and 2.3 passes) no wrong
#: offset stood above 10.0, and every one of the 130 picks was right (README, known limits)
AUTO_MARGIN = 20.0
#: the smoothness weight of the fit, relative to the patterns' (chosen on seed 0 among 0.1,
#: 1 and 10)
AUTO_SMOOTH = 10.0
#: the most pixels (and patterns) ``auto`` reads: its fit is a dense (Q, Q) solve and an
#: (M, Q) x (Q, M) product: at 64 x 64 it took 8.5 s with 1 024 patterns and 30 s with
#: 4 096 (two cores)
AUTO_MAX = 4096


def _laplacian(n: int) -> np.ndarray:
    """The ``(n^2, n^2)`` graph Laplacian of an ``n x n`` grid (4 neighbours)."""
    d = np.zeros((n, n))
    i = np.arange(n - 1)
    d[i, i] += 1
    d[i + 1, i + 1] += 1
    d[i, i + 1] = d[i + 1, i] = -1
    eye = np.eye(n)
    return np.kron(eye, d) + np.kron(d, eye)


def find_first_pattern(hist: np.ndarray, periods: np.ndarray, shown: np.ndarray,
                       code: np.ndarray, given: int | None = None) -> tuple[int, float, int]:
    """The pattern a free-running file's first block shows, from its data alone
    (``--first-pattern auto``).

    Each block's photons are correlated with the code at the strongest delay (the blocks'
    mean correlation's peak, which no ordering changes), summed per slot ``b mod M`` over
    the passes and divided by the slot's dwell. Under offset ``I`` pattern ``p`` holds slot
    ``(p - I) mod M``; each offset's vector is fitted by the patterns times a smooth image
    (a least-squares fit with a Laplacian penalty, :data:`AUTO_SMOOTH`) and the offset
    whose residual is least is picked. All ``M`` offsets are read at once, one ``(M, M)``
    product.

    Returns
    -------
    first, margin, runner_up
        The offset picked, how much larger the runner-up's residual is in units of the
        noise variance, and the runner-up (with ``given``: how much larger the residual of
        the offset given is, and that offset). Patterns over :data:`AUTO_MAX` pixels or rows
        are refused (:class:`ConfigError`).
    """
    m, q = shown.shape
    n = int(round(math.sqrt(q)))
    if max(m, q) > AUTO_MAX or n * n != q:
        raise ConfigError(f"--first-pattern auto reads at most {AUTO_MAX} patterns of at most "
                          f"{AUTO_MAX} square pixels ({m} of {q} here): give the number")
    rep = np.asarray(code, np.float64) - float(np.mean(code))
    spectrum = np.fft.fft(np.asarray(hist, np.float64), axis=1)
    corr = np.fft.ifft(spectrum * np.conj(np.fft.fft(rep))[None, :], axis=1).real
    tau = int(np.argmax(corr.sum(axis=0)))
    var = np.fft.ifft(spectrum * np.conj(np.fft.fft(rep ** 2))[None, :], axis=1).real[:, tau]
    slot = np.arange(hist.shape[0]) % m
    dwell = np.bincount(slot, np.asarray(periods, np.float64), minlength=m)
    dwell = np.maximum(dwell, 1.0)
    z = np.bincount(slot, corr[:, tau], minlength=m) / dwell
    noise = float(np.mean(np.bincount(slot, np.maximum(var, 0.0), minlength=m) / dwell ** 2))
    p = np.asarray(shown, np.float64)
    ptp = p.T @ p
    lap = _laplacian(n)
    weight = AUTO_SMOOTH * np.trace(ptp) / np.trace(lap)
    fit = np.linalg.solve(ptp + weight * lap + 1e-9 * np.trace(ptp) / q * np.eye(q), p.T)
    offsets = z[(np.arange(m)[:, None] - np.arange(m)[None, :]) % m]  # column I: offset I's
    residual = np.einsum("pi,pi->i", offsets, offsets - p @ (fit @ offsets))
    residual /= max(noise, 1e-300)
    order = np.argsort(residual)
    if given is not None:  # (how much worse the offset given fits than the best)
        return int(order[0]), float(residual[int(given)] - residual[order[0]]), int(given)
    return int(order[0]), float(residual[order[1]] - residual[order[0]]), int(order[1])


def auto_note(first: int, margin: float, runner_up: int, m: int) -> str:
    """The warning of an ``auto`` pick, or its refusal (:class:`ConfigError`) where the
    margin is under :data:`AUTO_MARGIN`."""
    if not margin >= AUTO_MARGIN:
        raise ConfigError(f"--first-pattern auto cannot tell which of the {m} patterns the "
                          f"first block shows: offset {first} fits the data best by "
                          f"{margin:.3g} (chi-square) over {runner_up}, under the {AUTO_MARGIN:g} "
                          f"it needs (too few photons, patterns that repeat, or returns at "
                          f"many depths?): give the number, --first-pattern I")
    return (f"--first-pattern auto: the file's first block shows pattern {first} (read from "
            f"the data: its fit beats the runner-up, {runner_up}, by {margin:.3g} chi-square, "
            f"{AUTO_MARGIN:g} needed); if the DMD's sequence log says otherwise, give it")


#: the most pixels (and patterns) at which a --first-pattern given is checked against the
#: data (the fit of :func:`find_first_pattern`, well under a second there)
CHECK_MAX = 1024


def check_given(data: Any, shown: np.ndarray, code: np.ndarray, given: int,
                notes: list[str]) -> None:
    """A ``--first-pattern I`` given, checked against the data where that is cheap (at most
    :data:`CHECK_MAX` pixels and patterns): where another offset fits them better by
    :data:`AUTO_MARGIN` or more, a warning says so (a wrong I read with exit 0 and no word,
    0.15-0.94 m median error where auto picked the right one by 150: an audit of stop 67)."""
    m, q = shown.shape
    if max(m, q) > CHECK_MAX:
        return
    best, worse, _ = find_first_pattern(data.histograms, np.maximum(data.exposure_periods, 1),
                                        shown, code, given=given)
    if best != given and worse >= AUTO_MARGIN:
        notes.append(f"--first-pattern {given}: the data fit pattern {best} as the first "
                     f"block's better, by {worse:.3g} chi-square ({AUTO_MARGIN:g} would pick "
                     f"it): is the DMD's sequence log right? (--first-pattern auto reads it "
                     f"from the data)")


def resolve_first(data: Any, shown: np.ndarray, code: np.ndarray, notes: list[str]) -> int:
    """``--first-pattern auto`` on a free-running file read (every block): the offset found
    (:func:`find_first_pattern`), its warning added to ``notes``, or refused in one line."""
    first, margin, runner_up = find_first_pattern(
        data.histograms, np.maximum(data.exposure_periods, 1), shown, code)
    notes.append(auto_note(first, margin, runner_up, int(shown.shape[0])))
    return first
