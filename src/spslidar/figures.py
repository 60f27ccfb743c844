"""Figures: ``depth.png`` of a run, drawn with Pillow (fast), or with matplotlib on request.

``spslidar run`` writes ``depth.png`` after every run, so it must be cheap: importing
``matplotlib.pyplot`` alone takes 0.4-2 s on a 2-core machine (2.2 s measured under load)
against ~30 ms for Pillow, and rendering a 13 x 4 inch figure another ~0.2 s. The default
:func:`depth_figure` therefore composes the three panels (truth | estimate | error) as
colour-mapped images with Pillow (colour bars with their ranges, the title with the RMSE);
``engine='matplotlib'`` gives the publication version with axes and tick labels.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from .metrics import mostly_noise, outside_gate
from .metrics import percent as _percent
from .patterns import pattern_share as _share
from .patterns import realisation_note

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


def _side(shape: tuple[int, ...]) -> int:
    """A panel's side in the figure: :data:`_PANEL`, or the image's own where it is larger,
    so that no row or column is left out (a 512 x 512 map resized to 320 lost 192 of its
    rows and columns, one-pixel poles with them: an audit)."""
    return max(_PANEL, *(int(n) for n in shape))


def _panel(draw_img, x0: int, y0: int, rgb: np.ndarray, title: str, lo: float, hi: float,
           table, unit: str, side: int = _PANEL) -> None:
    """Paste one colour-mapped panel, ``side`` pixels square, with its title and a colour
    bar labelled lo .. hi."""
    from PIL import Image, ImageDraw

    img = Image.fromarray(rgb)
    if img.size != (side, side):
        img = img.resize((side, side), Image.NEAREST)
    draw_img.paste(img, (x0, y0 + 22))
    d = ImageDraw.Draw(draw_img)
    d.text((x0, y0 + 4), title, fill=(0, 0, 0))
    bar = _colormap(np.linspace(hi, lo, side)[:, None] * np.ones((1, 12)), lo, hi, table, 0)
    draw_img.paste(Image.fromarray(bar), (x0 + side + 6, y0 + 22))
    d.text((x0 + side + 22, y0 + 22), _tick(hi, lo, hi), fill=(0, 0, 0))
    d.text((x0 + side + 22, y0 + 22 + side // 2 - 6), unit, fill=(0, 0, 0))
    d.text((x0 + side + 22, y0 + 10 + side), _tick(lo, lo, hi), fill=(0, 0, 0))


def _wrap(draw, text: str, width: float, sep: str = " ") -> list[str]:
    """``text`` in lines no wider than ``width`` pixels as ``draw`` writes them, broken at
    ``sep`` (a word longer than a line keeps its own line)."""
    lines: list[str] = []
    # (one line of text to measure: a file name's newline made textlength refuse it and
    # the figure, so reconstruct, fail; a review)
    text = " ".join(text.splitlines())
    for word in text.split(sep):
        if lines and draw.textlength(lines[-1] + sep + word) <= width:
            lines[-1] += sep + word
        else:
            lines.append(word)
    return lines


def _tick(v: float, lo: float, hi: float) -> str:
    """A colour bar's end label: three significant digits, or more decimals where those do
    not resolve the span to a tenth of itself (a flat wall at 25 m read '25 .. 25', a bar
    over 9.985-10.015 m '9.99 .. 10', a third of its span: an audit)."""
    short = f"{v:.3g}"
    if not hi > lo or "e" in short or v == 0:
        return short
    decimals = min(int(np.ceil(-np.log10(hi - lo))) + 1, 9)
    have = len(short.partition(".")[2])
    return short if have >= decimals else f"{v:.{decimals}f}"


#: colours (RGB) of the pixels a depth map cannot show, one per reason, named in the legend
NO_TRUTH = (150, 150, 150)  # grey: the scene has no ground truth there (e.g. a stereo hole)
NO_RETURN = (0, 0, 0)  # black: the estimator found no return (white is the error's zero)
LOW_CONFIDENCE = (230, 0, 200)  # magenta dot: a depth the estimator itself does not trust
OUT_OF_RANGE = (255, 120, 0)  # orange cross: a depth outside the colour bar's range
#: colour of the second surface panel's one-surface pixels
ONE_SURFACE = (235, 235, 235)


def _classes(result) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Masks of the pixels without ground truth, without a return, and with a low-confidence
    depth (a return the depth estimator flags)."""
    valid = np.asarray(result.scene.valid, dtype=bool)
    if not getattr(result, "has_truth", True):
        valid = np.zeros(np.shape(result.depth), dtype=bool)
    no_return = ~np.isfinite(result.depth)
    low = result.low_confidence
    low = (np.zeros_like(valid) if low is None
           else np.asarray(low, dtype=bool).reshape(valid.shape) & ~no_return)
    return ~valid, no_return, low


def _outside(result, lo: float, hi: float, values=None) -> np.ndarray:
    """Depths the colour bar cannot show (drawn at its end colour, marked by a cross): of the
    estimate, or of ``values`` (the second surfaces, drawn on the same bar)."""
    d = np.asarray(result.depth if values is None else values, dtype=np.float64)
    tol = float(result.metrics.get("bin_depth_m", 0.0))  # a bin's error is not "outside"
    with np.errstate(invalid="ignore"):
        return np.isfinite(d) & ((d < lo - tol) | (d > hi + tol))


def _pixels(n: int) -> str:
    return f"{n} pixel{'' if n == 1 else 's'}"


def _legend_items(result, outside: np.ndarray, beyond: np.ndarray | None = None,
                  outside2: np.ndarray | None = None
                  ) -> list[tuple[tuple[int, int, int], str]]:
    """The legend's swatches and texts; ``outside2``: :func:`_outside2`, where the caller has
    it (else computed here)."""
    no_truth, no_return, low = _classes(result)
    items = []
    if getattr(result, "has_truth", True):
        items.append((NO_TRUTH, f"no ground truth ({_percent(no_truth.mean())})"))
    m = result.metrics  # the share the estimate's title and metrics.json give
    share = m.get("missing_fraction")
    share = no_return.mean() if share is None or not np.isfinite(share) else share
    of = " of the pixels with a ground truth" if getattr(result, "has_truth", True) else ""
    # (one pixel of 4 096 read "0.0%" beside its black square)
    items += [(NO_RETURN, f"no return ({_percent(share)}{of})"),
              (LOW_CONFIDENCE, f"low-confidence depth ({_percent(low.mean())}, dot)")]
    depth2 = getattr(result, "depth2", None)
    if depth2 is not None and np.isfinite(depth2).any():  # the second-surface panel's grey
        # (pixels without a return are black there too, not "one surface"; the share was
        # rounded to "100%" with one pixel of 1 024 holding two: an audit of 2026-11-29)
        one = ~np.isfinite(depth2) & ~no_return
        items.append((ONE_SURFACE, f"one surface (second-surface panel, {_percent(one.mean())})"))
        if outside2 is None:
            outside2 = _outside2(result, *_limits(result)[:2])
    if outside.any():
        items.append((OUT_OF_RANGE, f"depth outside the colour range "
                                    f"({_pixels(int(outside.sum()))}, cross)"))
    if outside2 is not None and outside2.any():
        items.append((OUT_OF_RANGE, f"second surface outside the colour range "
                                    f"({_pixels(int(outside2.sum()))}, cross)"))
    if beyond is not None and beyond.any():  # (the error panel's: _beyond)
        items.append((OUT_OF_RANGE, f"error beyond its colour bar "
                                    f"({_pixels(int(beyond.sum()))}, cross)"))
    return items


def _limits(result):
    """Colour range of the depth panels, the masked error map and its symmetric range.

    With a ground truth the depth range is the truth's (an estimate outside it is marked),
    and takes in the estimate's 1st to 99th percentile where most of the estimate lies
    outside it (an uncalibrated instrument's map 2.06 m farther than its scene was all end
    colour and crosses: an outside audit of 2026-12-03); without one it is the estimate's
    1st to 99th percentile, widened to the depths within a quarter of that span beyond
    either end."""
    valid = _classes(result)[0] == 0
    truth = result.truth
    if valid.any():
        lo, hi = float(np.min(truth[valid])), float(np.max(truth[valid]))
        found = valid & np.isfinite(result.depth)
        if found.any() and _outside(result, lo, hi)[found].mean() > 0.5:
            p1, p99 = (float(v) for v in np.percentile(result.depth[found], [1, 99]))
            lo, hi = min(lo, p1), max(hi, p99)
    elif np.isfinite(result.depth).any():
        d = np.asarray(result.depth, dtype=np.float64)
        d = d[np.isfinite(d)]
        lo, hi = (float(v) for v in np.percentile(d, [1, 99]))
        # widened to the depths within a quarter of that span beyond it, so that only depths
        # apart from the rest are crossed (a ramp's correct end pixels, 2 % of any map, were
        # crossed as outside its range: an audit)
        reach = 0.25 * (hi - lo)
        lo, hi = float(d[d >= lo - reach].min()), float(d[d <= hi + reach].max())
    else:
        lo, hi = 0.0, 1.0
    bin_m = float(result.metrics.get("bin_depth_m", 0.0)) or 1e-3
    if hi - lo < 2 * bin_m:  # a flat scene: +- a bin, so that half a bin's error is not the
        mid = 0.5 * (lo + hi)  # whole colour range (a truth all purple, an estimate yellow)
        lo, hi = mid - bin_m, mid + bin_m
    err_masked = np.where(valid, result.depth - truth, np.nan)
    lim = float(np.nanpercentile(np.abs(err_masked), 99)) if np.isfinite(err_masked).any() else 0
    return lo, hi, err_masked, max(lim, result.metrics["bin_depth_m"])


def _title(result) -> str:
    c, m = result.config, result.metrics
    # the solver with the regulariser it ran (the resolved config: 'auto' named)
    reg = m.get("config", {}).get("regulariser", c.regulariser)
    solve = f"{c.solver} + {reg}"
    if "ptu" in m:  # a measured acquisition: no simulated photon numbers to show
        files = m["ptu"]["file"]  # (a list where several files were read as one)
        name = (Path(files).name if not isinstance(files, list) else
                f"{Path(files[0]).name} and {len(files) - 1} more file(s)")
        # the sequence's repeats (through the files), summed or one of them (--frame): a
        # frame's figure read as the whole acquisition's
        total = int(m["ptu"].get("repeats") or 1) * (len(files) if isinstance(files, list)
                                                     else 1)
        frame = m["ptu"].get("frame")
        reps = (f" (repeat {frame} of {total})" if frame is not None else
                f" (shown {total} times, summed)" if total > 1 else "")
        what = (f"measured {name}: {m['n_patterns']} patterns{reps}, "
                f"{int(sum(m['ptu']['counts_per_pattern']))} photons, "
                f"{'QCR' if c.qcr else 'no QCR'}, {solve}, "
                f"{_depth_words(c, bool(m.get('calibration')))}")
        cal = m.get("calibration")
        if cal:  # which instrument calibration the depths are corrected by
            name = f"{Path(cal['file']).name}: " if cal.get("file") else ""
            fwhm = float(cal["irf_fwhm_bins"])
            what += (f", calibrated ({name}delay {1e9 * cal['delay_s']:.3f} ns, IRF FWHM "
                     f"{fwhm:.2f} bin{'' if fwhm == 1 else 's'})")
        det = m.get("detector") or {}
        if det.get("corrected"):  # (which dead time the counts were corrected for)
            what += f", pile-up corrected (dead time {1e9 * float(det['dead_time_s']):g} ns)"
    else:
        # (a noiseless run was titled with the m_n of a noisy one: an audit)
        light = (f"m_s={c.signal:g}, noiseless" if getattr(c, "noiseless", False)
                 else f"m_s={c.signal:g}, m_n={c.noise:g}")
        what = (f"{c.lidar.upper()} {m['code_description']}, {m['n_patterns']} {c.patterns} "
                f"patterns ({_share(m['n_patterns'], c.size)}%{realisation_note(c)}), {light}, "
                f"{'QCR' if c.qcr else 'no QCR'}, {solve}, {_depth_words(c)}")
        if c.lidar == "conventional":  # (--fairness power moved an RMSE 0.325 -> 0.046 m
            # and no label said it, an outside audit)
            what += f", {c.fairness} fairness"
        # a simulated instrument, which run reads as an uncalibrated one
        inst = ([f"delay {1e9 * c.system_delay:g} ns (uncalibrated)"] if c.system_delay else []
                ) + ([f"IRF {c.irf}"] if c.irf else [])
        if inst:
            what += f", instrument: {', '.join(inst)}"
        if c.detector != "linear":  # (a GMAPD's run read as a linear counter's: an audit)
            what += f", {_detector_words(c, m)}"
    # the no-return rule is relative: "returns in 100 % of pixels" of an image of noise;
    # the returns outside the gate said too, where they are why (they were hidden behind
    # MOSTLY NOISE, a gate that missed the whole scene: an outside audit of 2026-12-03)
    notes = []
    share = outside_gate(m)
    beyond = 0 if share is not None or "ptu" in m else _truth_outside_gate(result)
    if share is not None:
        notes.append(f"{share:.0%} of the returns outside the range gate")
    elif beyond:
        notes.append(f"{_pixels(beyond)} of the scene outside the range gate")
    if mostly_noise(m):
        notes.append("MOSTLY NOISE: at most a tenth of the pixels hold a return")
    noise = f"; {'; '.join(notes)} (see the warnings)" if notes else ""
    if m.get("depth_rmse_m") is None:
        # (not "returns in 97% of pixels" beside MOSTLY NOISE, as the summary line says it)
        found = "a depth" if noise else "returns"
        return (f"{what}: no ground truth; {found} in {_percent(m['coverage'])} of "
                f"pixels{noise}")
    if not math.isfinite(m["depth_rmse_m"]):  # (it read "RMSE = nan m over 0% of pixels")
        return f"{what}: no depth to score, no pixel with a truth holds a return{noise}"
    return (f"{what}: RMSE = {m['depth_rmse_m']:.4f} m over {_percent(m['coverage'])} "
            f"of pixels{noise}")


def _depth_words(c, calibrated: bool = False) -> str:
    """``mrf depth``, with ``sub-bin`` where the depths were placed below a bin (it moves
    them; no label said it, an outside audit): ``subbin``, or a calibration, whose
    response's own sub-bin step applies whatever ``subbin`` says."""
    sub = getattr(c, "subbin", False) or calibrated
    return f"{c.depth} depth{' (sub-bin)' if sub else ''}"


def _truth_outside_gate(result) -> int:
    """A simulated run's scene pixels (with a truth) beyond its range gate, whose returns
    alias into it or are lost (the run warns of them; its figure did not)."""
    gate = result.metrics.get("range_gate_m")
    valid = ~_classes(result)[0]
    if not gate or not valid.any():
        return 0
    truth = np.asarray(result.truth, dtype=np.float64)[valid]
    return int(np.count_nonzero((truth < gate[0]) | (truth > gate[1])))


def _detector_words(c, m: dict) -> str:
    """A simulated detector other than the linear counter, with its dead time and dwell
    where it has them: ``GMAPD (dead time 50 ns, 5000 periods, pile-up corrected)``."""
    det = m.get("detector") or {}
    parts = []
    dead = det.get("dead_time_s", getattr(c, "dead_time", None))
    if dead:
        parts.append(f"dead time {1e9 * float(dead):g} ns")
    if int(getattr(c, "periods", 1) or 1) > 1:
        parts.append(f"{int(c.periods)} periods")
    if det.get("corrected") or (getattr(c, "pileup_correction", False) and dead):
        parts.append("pile-up corrected")
    name = c.detector.upper() if c.detector == "gmapd" else c.detector
    return f"{name} ({', '.join(parts)})" if parts else name


def _reflectivity_range(result) -> tuple[float, float]:
    r = result.reflectivity
    if r is None or not np.isfinite(r).any():
        return 0.0, 1.0
    hi = float(np.nanpercentile(r, 99))
    return 0.0, hi if hi > 0 else 1.0


def _beyond(err_masked: np.ndarray, lim: float) -> np.ndarray:
    """Errors the error panel's symmetric bar (the 99th percentile of ``|error|``) cannot
    show: drawn at its end colour, marked by a cross. A run whose RMSE of 0.039 m came from two
    pixels at +0.6 and -0.15 m showed a bar of +-0.015 m and nothing else."""
    with np.errstate(invalid="ignore"):
        return np.isfinite(err_masked) & (np.abs(err_masked) > lim * (1 + 1e-9))


def _marks(kind: str, low: np.ndarray, outside: np.ndarray, beyond: np.ndarray,
           outside2: np.ndarray | None = None
           ) -> tuple[tuple[np.ndarray, tuple[int, int, int], str], ...]:
    """What both engines draw over a panel, ``(mask, colour, marker)`` with marker ``'o'`` (a
    dot) or ``'x'`` (a cross): on the estimate the low-confidence depths and the depths
    outside the colour bar, on the error the errors beyond its bar (:func:`_beyond`), on the
    second surface its depths outside the bar (``outside2``; they were drawn at its end
    colour unmarked)."""
    return {"estimate": ((low, LOW_CONFIDENCE, "o"), (outside, OUT_OF_RANGE, "x")),
            "error": ((beyond, OUT_OF_RANGE, "x"),),
            "depth2": (() if outside2 is None else ((outside2, OUT_OF_RANGE, "x"),))
            }.get(kind, ())


def _outside2(result, lo: float, hi: float) -> np.ndarray | None:
    """The second surfaces outside the depth bar (None without a second-surface panel)."""
    depth2 = getattr(result, "depth2", None)
    if depth2 is None or not np.isfinite(depth2).any():
        return None
    return _outside(result, lo, hi, depth2)


def _panels(result):
    """The panels of ``depth.png``, left to right: ``(kind, title, values, lo, hi, table,
    unit)``. With a ground truth: truth, estimate, error, reflectivity (and a second surface
    where the estimator found one); without: estimate, reflectivity (second surface),
    confidence."""
    lo, hi, err_masked, lim = _limits(result)
    no_truth, no_return, low = _classes(result)
    m = result.metrics
    est_title = (f"estimate: {_percent(m['missing_fraction'])} no return, "
                 f"{_percent(low.mean())} low-confidence")
    panels = []
    if getattr(result, "has_truth", True):
        # (a PTU scene is the file: its truth is named by its own file, where one was read)
        name = (result.scene.name if "ptu" not in m else
                Path(m["ptu"].get("truth_file") or "").name or "given")
        panels.append(("truth", f"ground truth: {name}", result.truth, lo, hi, _VIRIDIS, "m"))
    panels.append(("estimate", est_title, result.depth, lo, hi, _VIRIDIS, "m"))
    if getattr(result, "has_truth", True):
        beyond = _beyond(err_masked, lim)
        title = "error: estimate - truth"
        if beyond.any():  # the 99th percentile hides the few pixels that carry the RMSE
            # (the sign convention kept: it was dropped for the count, an outside audit)
            title = (f"error (estimate - truth): {int(beyond.sum())} px beyond the bar (x), "
                     f"to {float(np.nanmax(np.abs(err_masked))):.3g} m")
        panels.append(("error", title, err_masked, -lim, lim, _RDBU_R, "m"))
    if result.reflectivity is not None:
        rlo, rhi = _reflectivity_range(result)
        unit = "ph/pulse" if "ptu" in m else "alpha"
        refl = np.asarray(result.reflectivity, dtype=np.float64)
        with np.errstate(invalid="ignore"):
            above = int(np.count_nonzero(refl > rhi * (1 + 1e-9)))
            # (not said where they lie within 2 % of the bar's end, which its colour shows
            # well enough: a 99th-percentile bar always leaves a percent above it, and a
            # uniform wall read "11 px above the bar, to 1.02" on a bar ending at 1.02, an
            # outside audit of 2026-12-03)
            if above and not np.nanmax(refl) > rhi + 0.02 * max(rhi - rlo, abs(rhi)):
                above = 0
        # (the bar ends at the 99th percentile: the brighter pixels showed its end colour
        # unmarked, an audit of 2026-11-29)
        title = ("reflectivity (intensity)" if not above else
                 f"reflectivity: {above} px above the bar, to "
                 f"{float(np.nanmax(result.reflectivity)):.3g}")
        panels.append(("reflectivity", title, result.reflectivity, rlo, rhi, _VIRIDIS, unit))
    depth2 = getattr(result, "depth2", None)
    if depth2 is not None and np.isfinite(depth2).any():
        panels.append(("depth2", f"second surface ({100 * np.isfinite(depth2).mean():.1f}% "
                                 "of pixels)", depth2, lo, hi, _VIRIDIS, "m"))
    if not getattr(result, "has_truth", True) and result.confidence is not None:
        # (each pixel's confidence reads its profile against its own noise: a map the
        # verdict calls noise showed 93 % of its pixels confident under MOSTLY NOISE, an
        # outside audit; the title says the pixels' confidence is not the map's)
        title = ("confidence (per pixel; the map is mostly noise)"
                 if mostly_noise(getattr(result, "metrics", None) or {}) else "confidence")
        panels.append(("confidence", title, result.confidence, 0.0, 1.0, _VIRIDIS, ""))
    return panels


def depth_figure(result, path: str | Path, engine: str = "pil") -> Path:
    """``depth.png``: ground truth | estimate | error | reflectivity (| second surface, where
    the estimator reports one), colour bars in metres (without a ground truth: estimate |
    reflectivity (| second surface) | confidence).

    Every pixel without a number has the colour of its reason, named in a legend: grey where
    the scene has no ground truth (truth and error panels), black where the estimator found no
    return (estimate, error and second-surface panels), a magenta dot on the depths the
    estimator flags as low-confidence, and an orange cross on estimated depths outside the
    colour bar's range (the truth's range; e.g. an aliased return metres away), which are
    drawn at the bar's end colour. The title gives the RMSE with the share of pixels it
    covers (ground truth and a return), never rounded up to 100 % while a pixel is missing.

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
    outside, beyond = _outside(result, lo, hi), _beyond(err_masked, lim)
    outside2 = _outside2(result, lo, hi)
    panels = _panels(result)
    side = _side(no_return.shape)
    width = len(panels) * (side + 70) + 20
    # the title and the legend wrap to the figure's width (a long file name cut the noise
    # verdict off the title, and a fifth panel's legend its last item: an audit)
    measure = ImageDraw.Draw(Image.new("RGB", (1, 1)))
    title_lines = _wrap(measure, _title(result), width - 20)
    # each legend item's place (x, row), laid out once: it sets the figure's height
    legend = _legend_items(result, outside, beyond, outside2)
    places, x, row = [], 10, 0
    for _, text in legend:
        w = 28 + measure.textlength(text) + 8
        if x > 10 and x + w > width:
            x, row = 10, row + 1
        places.append((x, row))
        x += w
    y0 = 8 + 12 * len(title_lines)
    height = y0 + side + 50 + 18 * (row + 1) + 12
    fig = Image.new("RGB", (width, height), (255, 255, 255))
    draw = ImageDraw.Draw(fig)
    for k, line in enumerate(title_lines):
        draw.text((10, 4 + 12 * k), line, fill=(0, 0, 0))
    cell = side / no_return.shape[0]
    for i, (kind, title, values, vlo, vhi, table, unit) in enumerate(panels):
        x0 = 10 + i * (side + 70)
        bad = ONE_SURFACE if kind == "depth2" else NO_RETURN
        rgb = _colormap(values, vlo, vhi, table, bad)
        if kind in ("truth", "error"):
            rgb[no_truth] = NO_TRUTH
        if kind in ("depth2", "confidence"):
            # no return at all is not "one surface", nor a confidence of 0 (it was drawn in
            # the colour map's 0, where the legend says black: an audit)
            rgb[no_return] = NO_RETURN
        _panel(fig, x0, y0, rgb, title, vlo, vhi, table, unit, side)
        r, h = max(1.0, cell / 5), max(1.5, cell / 3)
        for mask, colour, marker in _marks(kind, low, outside, beyond, outside2):
            for yy, xx in zip(*np.nonzero(mask), strict=True):
                cx, cy = x0 + (xx + 0.5) * cell, y0 + 22 + (yy + 0.5) * cell
                if marker == "o":
                    draw.ellipse((cx - r, cy - r, cx + r, cy + r), fill=colour)
                else:
                    draw.line((cx - h, cy - h, cx + h, cy + h), fill=colour, width=2)
                    draw.line((cx - h, cy + h, cx + h, cy - h), fill=colour, width=2)
    for (colour, text), (x, row) in zip(legend, places, strict=True):
        y = y0 + side + 50 + 18 * row
        draw.rectangle((x, y, x + 14, y + 12), fill=colour, outline=(80, 80, 80))
        draw.text((x + 20, y + 1), text, fill=(0, 0, 0))
    path = Path(path)
    fig.save(path, format="PNG", compress_level=1)
    return path


def _depth_figure_mpl(result, path: str | Path) -> Path:
    """The matplotlib version of :func:`depth_figure` (same panels, colours and legend)."""
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    plt = _plt()
    lo, hi, err_masked, lim = _limits(result)
    no_truth, no_return, low = _classes(result)
    outside, beyond = _outside(result, lo, hi), _beyond(err_masked, lim)
    outside2 = _outside2(result, lo, hi)
    panels = _panels(result)

    def paint(ax, mask, colour):
        if mask.any():
            ax.imshow(np.ma.masked_where(~mask, np.ones(mask.shape)),
                      cmap=ListedColormap([np.asarray(colour) / 255]), vmin=0, vmax=1,
                      interpolation="nearest")

    fig, axes = plt.subplots(1, len(panels), figsize=(4.4 * len(panels), 4.6),
                             constrained_layout=True, squeeze=False)
    try:  # (a savefig that raised, or a Ctrl-C, left the figure in pyplot: 6.7 MB a call)
        for ax, (kind, title, values, vlo, vhi, _table, unit) in zip(axes[0], panels,
                                                                      strict=True):
            cmap = plt.get_cmap("RdBu_r" if kind == "error" else "viridis")
            shown = np.ma.masked_invalid(np.asarray(values, dtype=np.float64))
            if kind in ("truth", "error"):
                shown = np.ma.masked_where(no_truth | shown.mask, shown)
            im = ax.imshow(shown, cmap=cmap, vmin=vlo, vmax=vhi)
            if kind in ("truth", "error"):
                paint(ax, no_truth, NO_TRUTH)
            if kind == "depth2":
                paint(ax, ~np.isfinite(np.asarray(values, dtype=np.float64)) & ~no_return,
                      ONE_SURFACE)
            if kind in ("estimate", "error", "depth2", "confidence"):
                paint(ax, ~no_truth & no_return if kind == "error" else no_return, NO_RETURN)
            for mask, colour, marker in _marks(kind, low, outside, beyond, outside2):
                if mask.any():
                    yy, xx = np.nonzero(mask)
                    ax.scatter(xx, yy, s=max(1.0, 400.0 / mask.shape[0]), marker=marker,
                               color=np.asarray(colour) / 255, linewidths=1)
            ax.set_title(title)
            label = {"m": "depth [m]", "": "confidence"}.get(unit, unit)
            _colorbar(fig, ax, im, "depth error [m]" if kind == "error" else label)
            ax.set_xticks([])
            ax.set_yticks([])
        fig.legend(handles=[Patch(facecolor=np.asarray(c) / 255, edgecolor="0.3", label=t)
                            for c, t in _legend_items(result, outside, beyond, outside2)],
                   loc="outside lower center", ncol=4, frameon=False)
        fig.suptitle(_title(result))
        path = Path(path)
        fig.savefig(path, dpi=110)
    finally:
        plt.close(fig)
    return path
