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
   a flat wall (``--target plane --fov`` removes it). Each pixel's return is split between
   the two bins about its offset linearly, which holds for a response smooth over a bin; a
   response narrower than a bin (an instrument without jitter) puts each pixel's pulse in
   one bin or two by where it starts in its bin, so the spreads are scanned again with the
   axis's pulse at each of :data:`PHASES` in its bin (every other phase and spread, then
   all about the best: :func:`_phase_scan`), kept where that fits :data:`Z_PLANE`
   deviations better than the linear split (a given field of view takes the place that fits
   best on the same terms): an ideal instrument's 10 degree wall at 32 x 32 was read as one
   range with its delay 4.7 bins off at 13.70 ns and right at 13.74 ns, and at 16 x 16 and
   10 m fitted a 1-bin spread for 4.5 with delays 0.6-0.8 bin late at five of eight sub-bin
   delays (audits of 2026-11-29); now 13.695 and 13.738 ns, and all eight within 0.01 bin.
   The scan takes about three times as long (3 s at 32 x 32). The spreads the data cannot
   tell from the best (residuals within one deviation of it, ``spread_band`` in the
   geometry) are read for the delay too, and a delay that moves over them by more than a
   quarter of a bin is said (a 10-bin IRF's 25 m wall fitted at 1.2-2.2 deviations had its
   delay 0.7-1.1 bins off, unsaid). A tilted wall seen so (step 3) is scanned on the
   responses smoothed over :data:`SHARP_BLUR_BINS` (:func:`_sharp_tilt`; a 5 degree tilt
   without jitter was read as one range, 1.9-2.0 bins early; now within 0.06 bin on three
   of four seeds and delays, 0.39 bin on the fourth). Tried first and dropped: the
   responses of
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

3. **A tilted wall** (:func:`~spslidar.pipeline.target_tilt.tilt_of_target`,
   :func:`_tilt_scan`). A wall turned about a vertical or horizontal axis puts one side of the
   field farther than the other, which the rings of step 1 cannot fit: an audit's wall tilted
   by 5 degrees at 25 m (16 x 16) was read as one range, its IRF 16 bins wide for 1.7 and its
   delay 1.8 cm short, and a scan reconstructed through it came out 30 cm too far (RMSE 0.48
   m), with no word (2026-11-29). Each pattern's response centroid is the light-weighted mean
   of its pixels' round trips, so regressed on each pattern's light-weighted mean of ``x``,
   ``y`` and ``x^2 + y^2`` (image coordinates in ``[-1, 1]``) it gives the tilt's direction
   and a facing wall's curvature (a tilt's own square, under 0.1 bin at 5 degrees through 10,
   is left out). Where a linear term stands :data:`Z_TILT_LOOK` standard errors out, the
   residual of step 1's fit is scanned (:func:`_tilt_scan`): the tilt's size with a facing
   wall's curvature on a coarse grid, then each of size, curvature and direction in turn,
   twice (on the facing wall of a ``--fov`` given, the curvature is that wall's); the tilt is
   kept where it stands :data:`Z_TILT` deviations below the best facing wall's and spans
   :data:`MIN_SPREAD_BINS`; where it does not, the tilt is said (:func:`_maybe_tilted`).
   Measured on ``run``'s 16 x 16 walls (the README's instrument; 5 degrees about the vertical
   axis on seeds 0, 1, 2, 6, 3 degrees about the horizontal one on seeds 0-1, 5 degrees about
   both on seeds 1 and 4): delays 13.695-13.748 ns for 13.74 and IRFs 1.82-2.47 bins wide (a
   facing wall's: 13.746 ns, 2.00 bins); before the review's mends (one scan along the
   centroids' direction) seeds 4 and 6 gave IRFs of 3-5 bins. The scan finds a tilt where the
   centroids' direction is within about 10-20 degrees of it (a review forced it 20 degrees or
   more off and found none; natural runs were 0-9 off). On the independent instrument's 32 x
   32 walls a 3 degree tilt is fitted (13.681 ns, 2.2 bins) and a 5 degree one is only said
   (its centroids stand 3.9 errors out; a tilt fitting better than a facing wall exists but
   the scans do not reach it). On facing walls and walls at one range the centroids' linear
   terms stood up to 2.7 errors out (Hadamard patterns), under :data:`Z_TILT_LOOK`, and no
   tilt was accepted even with the scan forced (a review's 163 walls); a facing wall of uneven
   reflectivity can raise the centroids past it (2 of 18 seeds), which is then said, not
   fitted.

Written by hand: the deconvolutions of scikit-image, SciPy or PyLops take one kernel, not a
different known kernel per observation with one shared unknown. Not modelled: a wall of
uneven reflectivity (the centroids then follow the bright pixels' round trips).
"""

from __future__ import annotations

import warnings
from typing import Any

import numpy as np

from ..constants import SPEED_OF_LIGHT
from ..errors import ConfigError
from .calibrated import IRF_AFTER, IRF_BEFORE, code_response
from .target_tilt import _coordinates, tilt_of_target

__all__ = ["MAX_SPREAD_BINS", "MIN_SPREAD_BINS", "PHASES", "PLANE_REG", "SCAN_PATTERNS",
           "SHARP_BLUR_BINS", "TARGETS", "Z_HINT", "Z_PLANE", "Z_TILT", "Z_TILT_LOOK",
           "measure_geometry", "plane_offsets", "plane_ranges", "range_free_response",
           "wall_offsets"]

#: what ``--target`` takes: ``auto`` keeps the plane where the data ask for one
TARGETS = ("auto", "plane", "range")
#: a plane whose pixels spread over less than this many bins is one range (``auto``)
MIN_SPREAD_BINS = 1.0
#: where the axis's pulse may start in its bin (bins): a response narrower than a bin is fitted
#: with each pixel's pulse split between the two bins it falls in from there
#: (:func:`_kernels`), kept where it fits better than the linear split
PHASES = np.arange(8) / 8.0
#: ``auto`` keeps the plane where its residual stands this many deviations below one range's
Z_PLANE = 1.0
#: ... and says (a warning) that the target may be a flat wall from this many
Z_HINT = 0.3
#: the centroids' tilt (:func:`~.target_tilt.tilt_of_target`) is scanned where a linear term
#: stands this many standard errors from 0
Z_TILT_LOOK = 3.0
#: ... and a tilt kept where its residual stands this many deviations below a facing wall's
Z_TILT = 3.0
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
    (:func:`~spslidar.pipeline.calibrated.code_response`)."""
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


def _kernels(light: np.ndarray, offsets: np.ndarray, period: int,
             phase: float | None = None, width: float = 0.5) -> np.ndarray:
    """Each pattern's kernel ``k_m`` over one period: the light on each group of pixels
    (:func:`_grouped`), on the two bins about its offset: linear in the offset's part of a
    bin (``phase`` None: a response smooth over a bin), or, with ``phase``, the share of a
    pulse ``width`` bins long starting ``phase`` into the axis's bin that each bin holds (a
    response narrower than a bin, :data:`PHASES`)."""
    s = np.asarray(offsets, dtype=np.float64)
    if phase is not None:
        s = s + float(phase)
    base = np.floor(s).astype(np.int64)
    frac = s - base
    if phase is not None:
        frac = np.clip((frac + width - 1.0) / width, 0.0, 1.0)
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


def _explained(gf: np.ndarray, light: np.ndarray, offsets: np.ndarray, size: int,
               phase: float | None = None, width: float = 0.5) -> float:
    """How much of the responses' power (their FFT ``gf`` on a window of ``size`` bins) one
    shared IRF explains through the kernels of the light on groups of pixels (``light``,
    :func:`_grouped`) at round trips ``offsets``: the scans' least-squares fit,
    ``sum_f |sum_m conj(K_m) G_m|^2 / sum_m |K_m|^2``."""
    kf = np.fft.rfft(_kernels(light, offsets, size, phase, width), axis=1)
    num = np.sum(np.conj(kf) * gf, axis=0)
    den = np.sum(np.abs(kf) ** 2, axis=0)
    return float(np.sum(np.divide(np.abs(num) ** 2, den, out=np.zeros_like(den),
                                  where=den > 0)))


def _deviation(best: float, patterns: int, n_f: int) -> float:
    """One deviation of the scans' residual ``best``: a chi-square of about ``(patterns - 1)
    n_f`` complex terms of variance ``sigma^2``, which a change of model moves by about
    ``sigma^2 sqrt(2 n_f)`` (0 for a residual of 0). A model stands ``(reference - best) /
    deviation`` deviations below another's residual ``reference``."""
    return best / max((patterns - 1) * n_f, 1) * np.sqrt(2.0 * n_f)


def _deviations(reference: float, best: float, patterns: int, n_f: int) -> float:
    """How many :func:`_deviation` of ``best`` it stands below ``reference`` (0 where the
    deviation is 0)."""
    unit = _deviation(best, patterns, n_f)
    return float((reference - best) / unit) if unit > 0 else 0.0


#: the phase scan's coarse pass takes every PHASE_STEP-th spread and every other phase, then
#: refines every phase within PHASE_STEP spreads of the best (a third of a full scan's time)
PHASE_STEP = 2


def _phase_scan(gf: np.ndarray, light: np.ndarray, offs: list, size: int, width: float
                ) -> tuple[float, int, float] | None:
    """The best fit of a response narrower than a bin over the spreads ``offs[1:]`` (offsets
    of each candidate spread's pixel groups) and :data:`PHASES`: ``(residual, index,
    phase)``, coarse to fine; None without a spread to scan."""
    if len(offs) < 2:
        return None
    total = float(np.sum(np.abs(gf) ** 2))

    def fit(i: int, ph: float) -> float:
        return total - _explained(gf, light, offs[i], size, ph, width)

    best = min((fit(i, float(ph)), i, float(ph)) for ph in PHASES[::2]
               for i in range(1, len(offs), PHASE_STEP))
    near = range(max(1, best[1] - PHASE_STEP), min(len(offs), best[1] + PHASE_STEP + 1))
    return min([best] + [(fit(i, float(ph)), i, float(ph)) for ph in PHASES for i in near])


def _phase_of(gf: np.ndarray, light: np.ndarray, offsets: np.ndarray, size: int,
              width: float, linear: float) -> tuple[float | None, float]:
    """The pulse's start in its bin (:data:`PHASES`) whose kernels leave the least residual
    for these round trips, where it stands :data:`Z_PLANE` deviations below the linear
    split's residual ``linear`` (a response narrower than a bin); else None."""
    best, phase = linear, None
    total = float(np.sum(np.abs(gf) ** 2))
    for ph in PHASES:
        r = total - _explained(gf, light, offsets, size, float(ph), width)
        if r < best:
            best, phase = r, float(ph)
    if phase is None or _deviations(linear, best, light.shape[0], gf.shape[1]) < Z_PLANE:
        return None, linear
    return phase, best


def _fit(gf: np.ndarray, light: np.ndarray, offsets: np.ndarray, size: int,
         phase: float | None = None, width: float = 0.5) -> float:
    """:func:`_explained` of per-pixel round trips ``offsets`` and the patterns ``light``
    (M, Q), the pixels grouped by their round trip (``phase``, ``width``: as
    :func:`_kernels`)."""
    group, values, _ = _grouped(light, offsets, slice(None))
    return _explained(gf, group, values, size, phase, width)


def _tilt_scan(gf: np.ndarray, size: int, light: np.ndarray, shape: tuple[int, int],
               tilt: dict[str, Any], base: np.ndarray, reference: float, limit: float,
               free_curvature: bool = False, phase: float | None = None,
               width: float = 0.5) -> dict[str, Any] | None:
    """Step 3's scan: round trips ``base + c (x^2 + y^2) + k (cos t x + sin t y)``, the tilt's
    size ``k`` (bins at the image's edge along its direction ``t``), its direction and, where
    ``free_curvature`` (no field of view given), a facing wall's curvature ``c``, each fitted
    in turn by the residual of step 1's fit: ``k`` and ``c`` on a coarse grid (at most 17 x
    9) then in half-bin steps, ``t`` within 30 degrees of the centroids' direction in 3-degree
    steps (the tilt is found where that direction is within 10-20 degrees of it), then ``k``
    from the coarse grid again, ``c``, ``t`` within 9 degrees and ``k`` about their values.
    The centroids alone gave a noisy curvature (9-10 bins for 6.4) and direction (56 degrees
    for 45), and with them the tilts of a review's seeds calibrated to IRFs 3-5 bins wide;
    fitted so, 1.8-2.5 (2026-11-29).
    The best is kept where its residual stands :data:`Z_TILT` deviations below
    ``reference`` (the best facing wall's, or the given one's) and its tilt spans
    :data:`MIN_SPREAD_BINS`. None otherwise. ``phase``, ``width``: the kernels of a response
    narrower than a bin (:func:`_kernels`), the pulse starting ``phase`` into the axis's
    bin; ``found['phase']`` says which."""
    a, b = tilt["tilt_bins"]
    h = float(np.hypot(a, b))
    if not h > 0 or max(abs(z) for z in tilt["tilt_z"]) < Z_TILT_LOOK:
        return None
    x, y = _coordinates(shape)
    r2 = x * x + y * y
    total = float(np.sum(np.abs(gf) ** 2))
    state = {"k": 0.0, "t": float(np.arctan2(b, a)),
             "c": max(float(tilt["curvature_bins"]), 0.0) if free_curvature else 0.0}

    def offsets(k: float, t: float, c: float) -> np.ndarray:
        return base + c * r2 + k * (np.cos(t) * x + np.sin(t) * y)

    def best(name: str, values) -> float:
        trial = dict(state)
        res = []
        for v in values:
            trial[name] = float(v)
            res.append(total - _fit(gf, light, offsets(trial["k"], trial["t"], trial["c"]),
                                    size, phase, width))
        i = int(np.argmin(res))
        state[name] = float(values[i])
        return float(res[i])

    k_max = min(limit, 2.0 * h + 8.0)
    # (at most 17 sizes and 9 curvatures on the coarse grid: a steep 64x64 tilt whose
    # centroids read 235 bins scanned 513 sizes, 18 s, and 33 x 9 took a 64x64 calibration
    # from 3.7 to 10.7 s, two reviews)
    ks = np.linspace(0.0, k_max, int(min(17, np.ceil(k_max / 2.0) + 1)))
    if free_curvature:  # k and c together on a coarse grid (one after the other, a review's
        # wall tilted about both axes stopped at k = 7 for 18 on the centroids' curvature)
        c_max = min(limit, max(2.0 * state["c"], 16.0))
        cs = np.linspace(0.0, c_max, int(min(9, np.ceil(c_max / 2.0) + 1)))
        grid = []
        for c in cs:
            state["c"] = float(c)
            grid.append((best("k", ks), state["k"], float(c)))
        _, state["k"], state["c"] = min(grid)
    else:
        best("k", ks)
    dk = float(ks[1] - ks[0]) if ks.size > 1 else 2.0
    best("k", np.arange(max(0.0, state["k"] - dk), state["k"] + dk + 0.25, SPREAD_STEP))
    if free_curvature:
        dc = float(cs[1] - cs[0]) if cs.size > 1 else 2.0
        best("c", np.arange(max(0.0, state["c"] - dc), state["c"] + dc + 0.25, SPREAD_STEP))
    best("t", state["t"] + np.radians(np.arange(-30.0, 31.0, 3.0)))
    # a second round from the direction found (the first can stop short along a direction
    # the centroids had 15 degrees off: the independent instrument's 32x32 wall at 5 degrees)
    best("k", ks)
    best("k", np.arange(max(0.0, state["k"] - dk), state["k"] + dk + 0.25, SPREAD_STEP))
    if free_curvature:
        best("c", np.arange(max(0.0, state["c"] - 3.0), state["c"] + 3.25, SPREAD_STEP))
    best("t", state["t"] + np.radians(np.arange(-9.0, 9.5, 1.5)))
    res = best("k", np.arange(max(0.0, state["k"] - 2.0), state["k"] + 2.25, SPREAD_STEP))
    z = _deviations(reference, res, light.shape[0], gf.shape[1])
    if not (z >= Z_TILT and 2.0 * state["k"] >= MIN_SPREAD_BINS):
        return None
    return {"k": state["k"], "z": z, "offsets": offsets(state["k"], state["t"], state["c"]),
            "direction": (float(np.cos(state["t"])), float(np.sin(state["t"]))),
            "phase": phase}


#: the geometry of a response narrower than a bin is scanned on the responses smoothed by a
#: Gaussian of this many bins (:func:`_sharp_tilt`)
SHARP_BLUR_BINS = 1.5


def _sharp_tilt(gf: np.ndarray, size: int, light: np.ndarray, facing: np.ndarray,
                light_all: np.ndarray, shape: tuple[int, int], tilt: dict[str, Any],
                limit: float, width: float) -> dict[str, Any] | None:
    """Step 3 for a response narrower than a bin: its residual is flat away from the exact
    round trips, so the coarse grid of :func:`_tilt_scan` finds no tilt (a 5 degree tilt seen
    without jitter was read as one range, its delay 1.9-2.0 bins early: an audit of
    2026-11-29). The tilt is scanned on the responses smoothed over :data:`SHARP_BLUR_BINS`
    (the IRF a little wider, the geometry the same) against the best facing wall's rings
    ``facing`` (offsets of ``light``'s groups) smoothed alike; the pulse's place in its bin
    is then fitted on the responses as they are (:func:`_phase_of`)."""
    f = np.fft.rfftfreq(size)
    gb = gf * np.exp(-2.0 * (np.pi * SHARP_BLUR_BINS * f) ** 2)[None, :]
    total = float(np.sum(np.abs(gb) ** 2))
    found = _tilt_scan(gb, size, light_all, shape, tilt, np.zeros(shape[0] * shape[1]),
                       total - _explained(gb, light, facing, size), limit,
                       free_curvature=True)
    if found is None:
        return None
    found["phase"] = _phase_at(gf, size, light_all, found["offsets"], width)[0]
    return found


def _phase_at(gf: np.ndarray, size: int, light_all: np.ndarray, offsets: np.ndarray,
              width: float) -> tuple[float | None, float]:
    """:func:`_phase_of` the per-pixel round trips ``offsets`` (None: the linear split), and
    the linear split's residual."""
    group, values, _ = _grouped(light_all, offsets, slice(None))
    linear = float(np.sum(np.abs(gf) ** 2)) - _explained(gf, group, values, size)
    return _phase_of(gf, group, values, size, width, linear)[0], linear


def _maybe_tilted(tilt: dict[str, Any]) -> None:
    """Said where the centroids move across the field (:data:`Z_TILT_LOOK` errors) but no
    tilt fits better than a facing wall: the independent instrument's 32 x 32 wall tilted
    by 5 degrees (256 patterns, 56 000 photons each) stood 3.9 errors out and was read as
    one range, its IRF 15 bins wide for 2 and its delay 0.14 ns short (with ``--fov 10``
    0.65 ns), where a 3 degree one was fitted (2026-11-29)."""
    a, b = tilt["tilt_bins"]
    za, zb = tilt["tilt_z"]
    if max(abs(za), abs(zb)) < Z_TILT_LOOK:
        return
    warnings.warn(f"the calibration target may be tilted: its patterns' responses move by "
                  f"{a:+.3g} bins of round trip from the axis to the right edge and {b:+.3g} "
                  f"to the bottom ({za:.2g} and {zb:.2g} standard errors), but no tilt "
                  f"fitted better than a facing wall; a tilted wall's spread is read as the "
                  f"instrument's response and moves its delay: face the wall to the lidar, "
                  f"acquire it longer, or calibrate on a target at one range", RuntimeWarning,
                  stacklevel=4)


def one_range(reason: str, z: float | None = None) -> dict[str, Any]:
    """The geometry of a target read as one range (the keys of :func:`measure_geometry`'s
    answer): no field of view, no spread, no per-pixel offsets. One builder for every path
    that reads one (it was written out at each, and ``--target range`` wrote a record
    without ``fov_deg`` and ``spread_bins``, which every other target's record holds: a
    review of 2026-12-03)."""
    return {"model": "range", "fov_deg": None, "spread_bins": 0.0,
            "z": None if z is None else round(float(z), 3), "phase_bins": None,
            "offsets": None, "reason": reason}


def _tilt_geometry(found: dict[str, Any], fov_deg: float | None) -> dict[str, Any]:
    """The geometry of a tilted target (:func:`_tilt_scan`'s best round trips, with
    ``fov_deg`` given on the facing wall's through it)."""
    ca, cb = found["direction"]
    a, b = round(found["k"] * ca, 4), round(found["k"] * cb, 4)
    offsets = found["offsets"]
    spread = float(offsets.max() - offsets.min())
    how = (f"the facing wall of the {fov_deg:g} degree field of view given, tilted"
           if fov_deg is not None else "a tilted wall, its round trips fitted")
    return {"model": "plane", "fov_deg": fov_deg, "spread_bins": round(spread, 4),
            "z": round(found["z"], 3), "tilt_bins": [a, b], "offsets": offsets,
            "phase_bins": found.get("phase"),
            "reason": f"{how}: its round trip changes by {a:+.3g} bins from the axis to the "
                      f"right edge and {b:+.3g} to the bottom ({found['z']:.3g} deviations "
                      f"below a facing wall's residual), its pixels over {spread:.3g} bins"}


def measure_geometry(hists: np.ndarray, patterns: np.ndarray, code: np.ndarray,
                     bin_width: float, distance: float, shape: tuple[int, int],
                     fov_deg: float | None = None, target: str = "auto",
                     pulse_width: float = 0.5) -> dict[str, Any]:
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
    pulse_width : float
        The laser pulse's width in bins, for a response narrower than a bin (:data:`PHASES`).

    Returns
    -------
    dict
        ``model`` ('plane' or 'range'), ``fov_deg`` (given or fitted; None for one range),
        ``spread_bins`` (the pixels' span of round trips), ``z`` (the plane's residual below
        one range's, in deviations; None where not scanned), ``phase_bins`` (None, or where
        the axis's pulse starts in its bin for a response narrower than a bin), ``reason``
        (one line), and ``offsets`` (per-pixel ``s_p``, bins, or None; not for the JSON).

    Raises
    ------
    ConfigError
        A ``fov_deg`` whose wall spreads the pixels over more than the code's period
        (:func:`wall_offsets`).
    """
    tau_d = 2.0 * float(distance) / (SPEED_OF_LIGHT * bin_width)
    n = int(shape[0])
    if tau_d <= 0:  # a target at the lidar: every pixel at one range
        return one_range("one range: a target at distance 0")
    m = patterns.shape[0]
    pick = np.unique(np.linspace(0, m - 1, min(m, SCAN_PATTERNS)).round().astype(int))
    period = int(np.asarray(code).size)
    if fov_deg is not None:  # (refused before the file is read where it spreads too far)
        offsets, spread = wall_offsets(shape, distance, fov_deg, bin_width, period)
    g = _code_removed(np.asarray(hists)[pick], code)
    light_all = np.asarray(patterns, dtype=np.float64)[pick]
    tilt = tilt_of_target(g, light_all, shape)
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
    if fov_deg is not None:
        phase, given = _phase_at(gf, size, light_all, offsets, pulse_width)
        if tilt is not None:
            found = _tilt_scan(gf, size, light_all, shape, tilt, offsets, given, limit)
            if found is not None:  # its pulse's place in its bin (as without --fov, below)
                found["phase"] = _phase_at(gf, size, light_all, found["offsets"],
                                           pulse_width)[0]
                return _tilt_geometry(found, fov_deg)
            _maybe_tilted(tilt)
        return {"model": "plane", "fov_deg": float(fov_deg), "spread_bins": round(spread, 4),
                "z": None, "phase_bins": phase, "offsets": offsets,
                "reason": f"a wall facing the lidar through the {fov_deg:g} degree field of "
                          f"view given: its pixels over {spread:.3g} bins of round trip"}
    # the pixels at one distance from the axis share every candidate's offset
    col = 2 * np.arange(shape[1]) + 1 - shape[1]
    row = 2 * np.arange(shape[0]) + 1 - shape[0]
    ring = (row[:, None] ** 2 + col[None, :] ** 2).ravel().astype(np.float64)
    light, keys, first = _grouped(light_all, ring, slice(None))
    spreads, residuals, offs = [], [], []
    for spread in np.arange(0.0, limit + SPREAD_STEP / 2, SPREAD_STEP):
        fov = _fov_of_spread(spread, tau_d, n)
        if not fov < MAX_FIT_FOV:
            # a wall this near spreads no further within any lens (--distance 1e-300 ended
            # in "the field of view must lie in (0, 180) degrees, got 180.0", an audit)
            break
        off = (plane_offsets(shape, distance, fov, bin_width)[first] if fov > 0
               else np.zeros(keys.size))
        spreads.append(float(spread))
        offs.append(off)
        residuals.append(total - _explained(gf, light, off, size))
    res = np.asarray(residuals)
    j = int(np.argmin(res))
    m_rows, n_f = light.shape[0], gf.shape[1]
    best, phase = float(res[j]), None
    # a response narrower than a bin: each pixel's pulse falls in one bin or two by where it
    # starts in its bin, which the linear split averages away (an ideal instrument's 10
    # degree wall at 32 x 32 was read as one range at 0.33 deviations with its delay at
    # 13.70 ns, 4.7 bins off, and fitted at 19 with it at 13.74 ns; at 16 x 16 and 10 m the
    # linear split fitted a 1-bin spread for 6, its delay 0.5-0.8 bin late: audits of
    # 2026-11-29): the spreads again with the pulse at each of PHASES in its bin, kept where
    # they fit Z_PLANE deviations better than the linear split's best
    phased = _phase_scan(gf, light, offs, size, pulse_width)
    if phased is not None:
        r, i, ph = phased
        if _deviations(best, r, m_rows, n_f) >= Z_PLANE:
            best, j, phase = r, i, ph
    z = _deviations(float(res[0]), best, m_rows, n_f)
    fov = _fov_of_spread(spreads[j], tau_d, n)
    if tilt is not None:  # step 3: a tilted wall, which no facing wall's rings fit
        found = _tilt_scan(gf, size, light_all, shape, tilt, np.zeros(n * n), best,
                           limit, free_curvature=True)
        if found is None and phased is not None:
            found = _sharp_tilt(gf, size, light, offs[j], light_all, shape, tilt, limit,
                                pulse_width)
        elif found is not None:  # its pulse's place in its bin, where that fits better
            found["phase"] = _phase_at(gf, size, light_all, found["offsets"], pulse_width)[0]
        if found is not None:
            return _tilt_geometry(found, None)
        _maybe_tilted(tilt)
    if target != "plane" and not (z >= Z_PLANE and spreads[j] >= MIN_SPREAD_BINS):
        # (and no field of view: the rejected plane's was kept beside a spread of 0, an
        # outside audit of 2026-12-03; one range has none, as --target range says)
        out = one_range(f"one range: a plane fits no better (best spread {spreads[j]:g} "
                        f"bins, {z:.2g} deviations)", z)
        if z >= Z_HINT and spreads[j] >= MIN_SPREAD_BINS:
            warnings.warn(f"the calibration target may be a flat wall whose pixels spread over "
                          f"{spreads[j]:g} bins of round trip (a {fov:.3g} degree field of "
                          f"view; {z:.2g} deviations, too few to remove it unasked): it was "
                          f"read as one range, which puts a flat wall's delay up to half its "
                          f"spread late; if it is a flat wall facing the lidar, calibrate "
                          f"with --target plane --fov (your optics' field of view)",
                          RuntimeWarning, stacklevel=3)
        return out
    out = {"model": "plane", "fov_deg": round(fov, 4), "spread_bins": float(spreads[j]),
           "z": round(z, 3)}

    def wall(spread: float) -> np.ndarray:
        f = _fov_of_spread(spread, tau_d, n)
        return plane_offsets(shape, distance, f, bin_width) if f > 0 else np.zeros(n * n)

    out.update(phase_bins=phase, offsets=wall(spreads[j]),
               reason=f"a wall facing the lidar, fitted: its pixels over {spreads[j]:g} bins "
                      f"of round trip (a {fov:.3g} degree field of view), {z:.2g} deviations "
                      f"below one range's residual")
    if phase is None:
        # the spreads whose residual lies within one deviation of the best: the data cannot
        # tell them apart, and the caller reads the delay at both ends (at 1-2.3 deviations
        # a 10-bin IRF's wall at 25 m was fitted 1.5-4 degrees off and its delay 0.7-1.1
        # bins off, without a word: an audit of 2026-11-29)
        near = np.flatnonzero(res <= best + _deviation(best, m_rows, n_f))
        lo, hi = spreads[int(near.min())], spreads[int(near.max())]
        if hi - lo >= MIN_SPREAD_BINS:
            out["spread_band"] = ((lo, _fov_of_spread(lo, tau_d, n), wall(lo)),
                                  (hi, _fov_of_spread(hi, tau_d, n), wall(hi)))
    if z < Z_PLANE:
        warnings.warn(f"the calibration's data barely tell the wall's spread ({z:.2g} "
                      f"deviations): the field of view fitted, {fov:.3g} degrees, is uncertain; "
                      f"give your optics' with --fov", RuntimeWarning, stacklevel=3)
    return out


def range_free_response(hists: np.ndarray, patterns: np.ndarray, code: np.ndarray,
                        offsets: np.ndarray, reg: float = PLANE_REG,
                        phase: float | None = None, width: float = 0.5) -> np.ndarray:
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
    phase, width : float
        Where a response narrower than a bin was fitted (:func:`measure_geometry`'s
        ``phase_bins``): the axis's pulse's start in its bin and its width, bins; None: the
        linear split of a smooth response.

    Returns
    -------
    ndarray, shape (L,)
        The code-free response (as :func:`~spslidar.pipeline.calibrated.code_response`
        gives for one range), background removed.
    """
    period = int(np.asarray(code).size)
    num = np.zeros(period // 2 + 1, dtype=np.complex128)
    den = np.zeros(period // 2 + 1)
    for rows in _rows(patterns.shape[0]):
        light, values, _ = _grouped(patterns, offsets, rows)
        kf = np.fft.rfft(_kernels(light, values, period, phase, width), axis=1)
        gf = np.fft.rfft(_code_removed(hists[rows], code), axis=1)
        num += np.sum(np.conj(kf) * gf, axis=0)
        den += np.sum(np.abs(kf) ** 2, axis=0)
    eps = float(reg) * float(np.median(den))
    if not eps > 0:
        eps = 1e-12 * float(den.max()) if den.max() > 0 else 1.0
    return np.fft.irfft(num / (den + eps), period)
