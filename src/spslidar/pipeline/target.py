"""The calibration target's own geometry: a flat wall is not at one range.

``spslidar calibrate`` reads the instrument's delay and IRF from a target at a known distance
``D``. A flat wall facing the lidar is at ``D`` only on the optical axis: pixel ``p``, looking
along ``(u_p, v_p, 1)`` (:func:`spslidar.products.pixel_rays`, the pinhole of ``points.ply``),
sees it at the range ``r_p = D sqrt(1 + u_p^2 + v_p^2)``, and a wall tilted to
``z = D + a x + b y`` at ``D sqrt(1 + u^2 + v^2) / (1 - a u - b v)``. Through a 10 degree
field of view at 25 m the corners are 0.179 m (11.9 bins at 10 GHz, 32x32) farther than the centre;
summed over the patterns, the response is the IRF smeared over that spread: an audit measured
a delay of 14.236 ns for a simulated 13.74 ns (8 cm) and an IRF 8.29 bins wide for 1.9, every
calibrated depth then 4-5 cm short and its median error 6 cm (2026-11-28).

Each pattern lights its own pixels, so each pattern's histogram with the code removed,
``g_m(t) = sum_p phi_mp IRF(t - s_p)`` with ``s_p = 2 (r_p - D) / (c dt)`` bins, is the IRF
convolved with a kernel ``k_m`` that the patterns and the geometry give. Two steps:

1. **The geometry** (:func:`measure_geometry`). For a wall facing the lidar the one unknown
   is how far the corners lie behind the axis: the spread ``S`` (bins), which the field of
   view sets. Each candidate ``S`` (half-bin steps from 0 to :data:`MAX_SPREAD_BINS`) gives
   every pattern's kernel, and the least-squares fit of one IRF to all patterns at once
   (:data:`SCAN_PATTERNS` of them, on the window of the period that can hold the return)
   leaves a residual; the spread whose kernels leave the least is the target's. On the
   independent instrument it came within half a bin of the truth at 5, 10 and 20 degrees
   (3.0, 11.9 and 48.0 bins; two seeds each) and at 0.5 bin for a target at one range.
   ``auto`` keeps the plane where its residual stands :data:`Z_PLANE` deviations (of the
   residual's chi-square noise) below one range's and it spreads the pixels over
   :data:`MIN_SPREAD_BINS` or more: measured 1.5-1.7 at 5 degrees, 5.9-8.3 at 10, 9.3-11.1 at
   20 (32 x 32, 256 patterns), 26 at 10 degrees on ``run``'s 16 x 16 wall, 0.99 on its 64 x 64
   one (1 024 patterns: each pattern's share of the pixels tells less as they grow), and
   0-0.02 on eleven walls at one range (the independent one, ``run``'s at 16 x 16, signal 1
   and 0.1, seeds 0-3, and at 64 x 64, seeds 0-1) but 0.55 on an 8 x 8 one through a 10-bin
   IRF at 0.57 M photons (a 6-bin spread, which would have moved the delay by 1.3 bins): from
   :data:`Z_HINT` to :data:`Z_PLANE` the target is read as one range and said to be perhaps
   a flat wall (``--target plane --fov`` removes it). Tried first and dropped: the responses of
   4 x 4 blocks of the field, each solved by least squares from the blocks' sums, whose
   delays a plane would be fitted to: on a 32 x 32 calibration of 14.5 M photons they stood
   2-4 noise deviations high (each block's response estimated on its own, where this fit's
   one IRF is measured through every pixel).
2. **The response of one range** (:func:`range_free_response`): the IRF from all patterns at
   once, the Wiener estimate ``I(f) = sum_m conj(K_m(f)) G_m(f) / (sum_m |K_m(f)|^2 + eps)``.
   The patterns' sum alone cannot give it: its kernel is the whole field's spread, whose
   spectrum falls towards zero at about one cycle per spread, where the IRF still has its
   shape; each pattern's own choice of pixels keeps ``sum_m |K_m(f)|^2`` near ``M Q var(phi)``
   or above at every frequency. ``eps`` is :data:`PLANE_REG` times the median of
   ``sum_m |K_m|^2`` (that floor): chosen on the independent instrument of
   ``tests/test_independent_ptu.py`` (walls at 5, 10 and 20 degrees, two seeds each) by the
   IRF's distance from the one a wall at one range gives (L1 0.20-0.31; delays within 9 ps).

Written by hand: the deconvolutions of scikit-image, SciPy or PyLops take one kernel, not a
different known kernel per observation with one shared unknown. Not modelled: a tilted wall
(its spread is read as a facing wall's of the same span), a wall of uneven reflectivity.
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from ..constants import SPEED_OF_LIGHT
from ..errors import ConfigError

__all__ = ["MAX_SPREAD_BINS", "MIN_SPREAD_BINS", "PLANE_REG", "SCAN_PATTERNS", "TARGETS",
           "Z_HINT", "Z_PLANE", "measure_geometry", "plane_offsets", "plane_ranges",
           "range_free_response", "wall_offsets"]

#: what ``--target`` takes: ``auto`` keeps the plane where the data ask for one
TARGETS = ("auto", "plane", "range")
#: a plane whose pixels spread over less than this many bins is one range (``auto``)
MIN_SPREAD_BINS = 1.0
#: ``auto`` keeps the plane where its residual stands this many deviations below one range's
Z_PLANE = 1.0
#: ... and says (a warning) that the target may be a flat wall from this many
Z_HINT = 0.3
#: the candidate spreads' step, bins
SPREAD_STEP = 0.5
#: the largest spread scanned, bins (or a quarter of the code's period): 38 cm at 10 GHz, a
#: wall at 25 m through a 31 degree field of view (give a wider one with ``--fov``)
MAX_SPREAD_BINS = 256.0
#: bins of background on either side of the scan's window of the period
WINDOW_MARGIN = 16
#: patterns the scan fits (evenly spaced; bounds its memory: SCAN_PATTERNS x L / 2 complex)
SCAN_PATTERNS = 512
#: Wiener regularisation of :func:`range_free_response`, over the median of ``sum_m |K_m|^2``
PLANE_REG = 0.3
#: patterns per pass of the per-pattern steps (bounds their memory: ROW_BLOCK x L floats)
ROW_BLOCK = 256


def plane_ranges(shape: tuple[int, int], distance: float, fov_deg: float,
                 slopes: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """Range (metres) of a plane ``z = distance + a x + b y`` at each pixel of the pinhole of
    field of view ``fov_deg`` (:func:`spslidar.products.pixel_rays`).

    ``slopes = (0, 0)`` is a wall facing the lidar: ``distance`` on the axis, farther towards
    the corners. Refused (:class:`ConfigError`) where the plane lies behind a pixel.
    """
    from ..products import pixel_rays

    u, v = pixel_rays(shape, fov_deg)
    a, b = (float(s) for s in slopes)
    den = 1.0 - a * u - b * v
    if not np.all(den > 0):
        raise ConfigError(f"a plane of slopes ({a:g}, {b:g}) does not cross every pixel's ray "
                          f"in front of the lidar")
    return float(distance) * np.sqrt(1.0 + u * u + v * v) / den


def plane_offsets(shape: tuple[int, int], distance: float, fov_deg: float, bin_width: float,
                  slopes: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """Each pixel's round trip beyond the axis's, in bins (``s_p``), flattened row-major."""
    r = plane_ranges(shape, distance, fov_deg, slopes)
    return (2.0 * (r - float(distance)) / (SPEED_OF_LIGHT * bin_width)).ravel()


def wall_offsets(shape: tuple[int, int], distance: float, fov_deg: float, bin_width: float,
                 period: int) -> tuple[np.ndarray, float]:
    """A facing wall's :func:`plane_offsets` through the field of view ``fov_deg`` and their
    spread (bins), refused in one line (:class:`ConfigError`) where the spread is more than
    the code's ``period`` bins: its pixels' returns would wrap around the period onto each
    other (``--fov 179.9`` put a wall's corners 2e6 bins behind its centre in a 255-bin
    period, and the calibration was written without a word: an audit's)."""
    offsets = plane_offsets(shape, distance, fov_deg, bin_width)
    spread = float(offsets.max() - offsets.min())
    if spread > period:
        raise ConfigError(
            f"--fov {fov_deg:g} puts a flat wall at {float(distance):g} m over "
            f"{spread:.4g} bins of round trip across its {shape[0]}x{shape[1]} pixels, "
            f"more than the code's period of {period} bins (its returns would wrap onto "
            f"each other); check --fov (your optics' full field of view across the image, "
            f"degrees), or calibrate on a target at one range (--target range)")
    return offsets, spread


def _code_removed(hists: np.ndarray, code: np.ndarray) -> np.ndarray:
    """Each row's response with the code deconvolved and its constant background removed
    (:func:`~spslidar.pipeline.calibration.code_response`)."""
    from .calibration import code_response

    g = code_response(np.asarray(hists, dtype=np.float64), code)
    g -= np.median(g, axis=-1, keepdims=True)
    return g


def _rows(m: int):
    for start in range(0, m, ROW_BLOCK):
        yield slice(start, min(m, start + ROW_BLOCK))


def _grouped(patterns: np.ndarray, offsets: np.ndarray, rows: slice | np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The patterns' light summed over the pixels that share an offset (a facing wall's
    pixels at one distance from the axis: an eighth of them or fewer), those offsets, and one
    pixel of each group: the kernels need no more, at a fraction of the pixels' cost (a
    256 x 256 image: 8 256 groups for 65 536 pixels)."""
    values, first, group = np.unique(np.asarray(offsets, dtype=np.float64),
                                     return_index=True, return_inverse=True)
    order = np.argsort(group, kind="stable")
    starts = np.searchsorted(group[order], np.arange(values.size))
    light = np.add.reduceat(np.asarray(patterns[rows], dtype=np.float64)[:, order], starts,
                            axis=1)
    return light, values, first


def _kernels(light: np.ndarray, offsets: np.ndarray, period: int) -> np.ndarray:
    """Each pattern's kernel ``k_m`` over one period: the light on each group of pixels
    (:func:`_grouped`), on the two bins about its offset (linear in the offset's part of a
    bin)."""
    s = np.asarray(offsets, dtype=np.float64)
    base = np.floor(s).astype(np.int64)
    frac = s - base
    kern = np.zeros((light.shape[0], period))
    for b in np.unique(base):
        sel = base == b
        kern[:, b % period] += light[:, sel] @ (1.0 - frac[sel])
        kern[:, (b + 1) % period] += light[:, sel] @ frac[sel]
    return kern


#: the widest field of view (degrees) the wall fit tries
MAX_FIT_FOV = 170.0


def _fov_of_spread(spread: float, tau_d: float, n: int) -> float:
    """The field of view (degrees) whose corner pixels of an ``n`` x ``n`` image see a facing
    wall ``spread`` bins of round trip behind the axis's ``tau_d``."""
    if spread <= 0:
        return 0.0
    if not tau_d > 0:  # a wall at the lidar: no field of view spreads it
        return 180.0
    t = np.sqrt(((1.0 + spread / tau_d) ** 2 - 1.0) / 2.0) / (1.0 - 1.0 / n)
    return float(np.degrees(2.0 * np.arctan(t)))


def measure_geometry(hists: np.ndarray, patterns: np.ndarray, code: np.ndarray,
                     bin_width: float, distance: float, shape: tuple[int, int],
                     fov_deg: float | None = None, target: str = "auto") -> dict[str, Any]:
    """The calibration target's geometry from its acquisition (module docstring, step 1).

    Parameters
    ----------
    hists : ndarray, shape (M, L)
        Each pattern's histogram over one code period.
    patterns : ndarray, shape (M, Q)
        The mirror states shown, ``Q = N * N`` pixels row-major.
    code : ndarray, shape (L,)
    bin_width, distance : float
        Seconds; metres (the target on the optical axis).
    shape : (int, int)
        The image's shape (square).
    fov_deg : float, optional
        The field of view, where known (then nothing is scanned): the target is that plane.
    target : {'auto', 'plane'}
        ``plane`` keeps the best plane whatever the test says.

    Returns
    -------
    dict
        ``model`` ('plane' or 'range'), ``fov_deg`` (given or fitted), ``spread_bins`` (the
        pixels' span of round trips), ``z`` (the plane's residual below one range's, in
        deviations; None where not scanned), ``reason`` (one line), and ``offsets``
        (per-pixel ``s_p``, bins, or None; not for the JSON).

    Raises
    ------
    ConfigError
        A ``fov_deg`` whose wall spreads the pixels over more than the code's period
        (:func:`wall_offsets`).
    """
    tau_d = 2.0 * float(distance) / (SPEED_OF_LIGHT * bin_width)
    n = int(shape[0])
    if tau_d <= 0:  # a target at the lidar: every pixel at one range
        return {"model": "range", "fov_deg": None, "spread_bins": 0.0, "z": None,
                "offsets": None, "reason": "one range: a target at distance 0"}
    if fov_deg is not None:
        offsets, spread = wall_offsets(shape, distance, fov_deg, bin_width, np.asarray(code).size)
        return {"model": "plane", "fov_deg": float(fov_deg), "spread_bins": round(spread, 4),
                "z": None, "offsets": offsets,
                "reason": f"a wall facing the lidar through the {fov_deg:g} degree field of "
                          f"view given: its pixels over {spread:.3g} bins of round trip"}
    m = patterns.shape[0]
    pick = np.unique(np.linspace(0, m - 1, min(m, SCAN_PATTERNS)).round().astype(int))
    # the pixels at one distance from the axis share every candidate's offset
    col = 2 * np.arange(shape[1]) + 1 - shape[1]
    row = 2 * np.arange(shape[0]) + 1 - shape[0]
    ring = (row[:, None] ** 2 + col[None, :] ** 2).ravel().astype(np.float64)
    light, keys, first = _grouped(patterns, ring, pick)
    from .calibration import IRF_AFTER, IRF_BEFORE

    period = int(np.asarray(code).size)
    g = _code_removed(np.asarray(hists)[pick], code)
    limit = min(MAX_SPREAD_BINS, period / 4.0)
    # the scan's window of the period: the axis's response lies up to `limit` before the
    # sum's peak and the corners' up to `limit` after it (circular on the window, whose
    # margins hold background only); the rest of the period is noise to every candidate
    span = int(2 * limit) + IRF_BEFORE + IRF_AFTER + 2 * WINDOW_MARGIN
    if span < period:
        from scipy.fft import next_fast_len

        span = next_fast_len(span, real=True)
        start = int(np.argmax(g.sum(axis=0))) - int(limit) - IRF_BEFORE - WINDOW_MARGIN
        g = g[:, (start + np.arange(span)) % period]
    size = g.shape[1]
    gf = np.fft.rfft(g, axis=1)
    total = float(np.sum(np.abs(gf) ** 2))
    spreads, residuals = [], []
    for spread in np.arange(0.0, limit + SPREAD_STEP / 2, SPREAD_STEP):
        fov = _fov_of_spread(spread, tau_d, n)
        if not fov < MAX_FIT_FOV:
            # a wall this near spreads no further within any lens (--distance 1e-300 ended
            # in "the field of view must lie in (0, 180) degrees, got 180.0", an audit)
            break
        off = (plane_offsets(shape, distance, fov, bin_width)[first] if fov > 0
               else np.zeros(keys.size))
        kf = np.fft.rfft(_kernels(light, off, size), axis=1)
        num = np.sum(np.conj(kf) * gf, axis=0)
        den = np.sum(np.abs(kf) ** 2, axis=0)
        fit = np.divide(np.abs(num) ** 2, den, out=np.zeros_like(den), where=den > 0)
        spreads.append(float(spread))
        residuals.append(total - float(fit.sum()))
    res = np.asarray(residuals)
    j = int(np.argmin(res))
    n_f = gf.shape[1]
    # the residual's noise: a chi-square of about (M - 1) F complex terms of variance sigma^2,
    # which a change of model moves by about sigma^2 sqrt(2 F)
    sigma2 = res[j] / max((light.shape[0] - 1) * n_f, 1)
    z = float((res[0] - res[j]) / (sigma2 * np.sqrt(2.0 * n_f))) if sigma2 > 0 else 0.0
    fov = _fov_of_spread(spreads[j], tau_d, n)
    out = {"model": "range", "fov_deg": round(fov, 4), "spread_bins": float(spreads[j]),
           "z": round(z, 3), "offsets": None}
    if target != "plane" and not (z >= Z_PLANE and spreads[j] >= MIN_SPREAD_BINS):
        out["reason"] = (f"one range: a plane fits no better (best spread {spreads[j]:g} bins, "
                         f"{z:.2g} deviations)")
        out["spread_bins"] = 0.0
        if z >= Z_HINT and spreads[j] >= MIN_SPREAD_BINS:
            warnings.warn(f"the calibration target may be a flat wall whose pixels spread over "
                          f"{spreads[j]:g} bins of round trip (a {fov:.3g} degree field of "
                          f"view; {z:.2g} deviations, too few to remove it unasked): it was "
                          f"read as one range; if it is a flat wall facing the lidar, calibrate "
                          f"with --target plane --fov (your optics' field of view)",
                          RuntimeWarning, stacklevel=3)
        return out
    out.update(model="plane", offsets=plane_offsets(shape, distance, fov, bin_width)
               if fov > 0 else np.zeros(n * n),
               reason=f"a wall facing the lidar, fitted: its pixels over {spreads[j]:g} bins "
                      f"of round trip (a {fov:.3g} degree field of view), {z:.2g} deviations "
                      f"below one range's residual")
    if z < Z_PLANE:
        warnings.warn(f"the calibration's data barely tell the wall's spread ({z:.2g} "
                      f"deviations): the field of view fitted, {fov:.3g} degrees, is uncertain; "
                      f"give your optics' with --fov", RuntimeWarning, stacklevel=3)
    return out


def range_free_response(hists: np.ndarray, patterns: np.ndarray, code: np.ndarray,
                        offsets: np.ndarray, reg: float = PLANE_REG) -> np.ndarray:
    """The response a target at one range would have given (module docstring, step 2).

    Parameters
    ----------
    hists : ndarray, shape (M, L)
    patterns : ndarray, shape (M, Q)
    code : ndarray, shape (L,)
    offsets : ndarray, shape (Q,)
        Each pixel's round trip beyond the axis's, bins (:func:`plane_offsets`).
    reg : float
        Wiener regularisation over the median of ``sum_m |K_m(f)|^2``.

    Returns
    -------
    ndarray, shape (L,)
        The code-free response (as :func:`~spslidar.pipeline.calibration.code_response`
        gives for one range), background removed.
    """
    period = int(np.asarray(code).size)
    num = np.zeros(period // 2 + 1, dtype=np.complex128)
    den = np.zeros(period // 2 + 1)
    for rows in _rows(patterns.shape[0]):
        light, values, _ = _grouped(patterns, offsets, rows)
        kf = np.fft.rfft(_kernels(light, values, period), axis=1)
        gf = np.fft.rfft(_code_removed(hists[rows], code), axis=1)
        num += np.sum(np.conj(kf) * gf, axis=0)
        den += np.sum(np.abs(kf) ** 2, axis=0)
    eps = float(reg) * float(np.median(den))
    if not eps > 0:
        eps = 1e-12 * float(den.max()) if den.max() > 0 else 1.0
    return np.fft.irfft(num / (den + eps), period)
