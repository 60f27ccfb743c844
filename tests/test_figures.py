"""depth.png: each kind of pixel without a number has its own colour (issue 15, item 6)."""

import numpy as np
import pytest

from spslidar import pipeline
from spslidar.figures import _PANEL, LOW_CONFIDENCE, NO_RETURN, NO_TRUTH, depth_figure


@pytest.fixture(scope="module")
def result():
    r = pipeline.run(scene="motorcycle", size=16, code_length=1023, noise=10, seed=0)
    # make every kind present: a pixel without return, and low-confidence ones
    # (a result's arrays are read-only views: edited copies put in)
    r.depth = _edited(r.depth, (0, 0), np.nan)
    r.low_confidence = _edited(np.zeros(r.depth.shape, dtype=bool), (5, 5), True)
    return r


def _edited(a, at, value):
    """A writable copy of ``a`` with ``a[at] = value``."""
    a = np.array(a)
    a[at] = value
    return a


def _pixel(img, panel, row, col, n):
    cell = _PANEL / n
    x = 10 + panel * (_PANEL + 70) + int((col + 0.5) * cell)
    y = 20 + 22 + int((row + 0.5) * cell)
    return tuple(img.getpixel((x, y)))


def test_pil_figure_colours_each_missing_kind(result, tmp_path):
    from PIL import Image

    img = Image.open(depth_figure(result, tmp_path / "d.png")).convert("RGB")
    n = result.depth.shape[0]
    invalid = np.argwhere(~result.scene.valid)
    assert invalid.size, "the motorcycle has pixels without ground truth"
    r, c = invalid[0]
    assert _pixel(img, 0, r, c, n) == NO_TRUTH  # truth panel
    assert _pixel(img, 2, r, c, n) == NO_TRUTH  # error panel
    if result.scene.valid[0, 0]:
        assert _pixel(img, 2, 0, 0, n) == NO_RETURN
    assert _pixel(img, 1, 0, 0, n) == NO_RETURN  # estimate panel
    assert _pixel(img, 1, 5, 5, n) == LOW_CONFIDENCE  # the dot in the pixel's centre
    assert NO_TRUTH != NO_RETURN != LOW_CONFIDENCE


def test_matplotlib_figure_writes(result, tmp_path):
    path = depth_figure(result, tmp_path / "m.png", engine="matplotlib")
    assert path.stat().st_size > 10_000


def test_estimate_outside_the_colour_range_is_marked(result, tmp_path):
    """An aliased depth metres away is drawn at the colour bar's end *and* crossed, so it
    cannot pass for a plausible depth (issue 24, item 7); a depth within a bin is not."""
    from PIL import Image

    from spslidar.figures import OUT_OF_RANGE, _legend_items, _title

    r = result
    saved = r.depth
    try:
        r.depth = _edited(saved, (3, 3), float(np.nanmax(r.truth)) + 5.0)
        img = Image.open(depth_figure(r, tmp_path / "o.png")).convert("RGB")
        assert _pixel(img, 1, 3, 3, r.depth.shape[0]) == OUT_OF_RANGE
        outside = np.isfinite(r.depth) & (r.depth > np.nanmax(r.truth) + 1)
        assert "outside the colour range" in " ".join(t for _, t in _legend_items(r, outside))
        assert "RMSE" in _title(r)
        # the title names the solver with the regulariser it ran ('auto' resolved)
        assert f"{r.config.solver} + {r.metrics['config']['regulariser']}," in _title(r)
    finally:
        r.depth = saved


def test_coverage_never_rounds_up_to_100_percent():
    from spslidar.metrics import percent as _percent

    assert _percent(4095 / 4096) == "99.98%"
    assert _percent(1.0) == "100%"
    assert _percent(1 / 4096) == "0.02%"
    assert _percent(0.5) == "50%"


def test_figure_without_truth(result, tmp_path):
    """A measured acquisition: estimate | reflectivity | confidence, no truth or error panel,
    and a title that says there is no ground truth."""
    import copy

    from PIL import Image

    from spslidar.figures import _title

    r = copy.copy(result)
    r.scene = copy.copy(result.scene)
    r.scene.has_truth = False
    r.metrics = {**result.metrics, "depth_rmse_m": None}
    img = Image.open(depth_figure(r, tmp_path / "n.png"))
    assert img.size[0] == 3 * (_PANEL + 70) + 20
    assert _pixel(img.convert("RGB"), 0, 0, 0, r.depth.shape[0]) == NO_RETURN  # estimate first
    assert "no ground truth" in _title(r)
    assert depth_figure(r, tmp_path / "m.png", engine="matplotlib").stat().st_size > 10_000


def test_legend_names_the_second_surface_panels_grey():
    import spslidar
    from spslidar.figures import _legend_items

    r = spslidar.run(scene="fence", size=16, code_length=1023, noise=1, compression=0.5,
                     depth="guarded")
    texts = [t for _, t in _legend_items(r, np.zeros(r.depth.shape, bool))]
    assert np.isfinite(r.depth2).any()
    assert any(t.startswith("one surface (second-surface panel") for t in texts)
    r = spslidar.run(scene="fence", size=16, code_length=1023, noise=1, compression=0.5)
    texts = [t for _, t in _legend_items(r, np.zeros(r.depth.shape, bool))]
    assert texts and not any("one surface" in t for t in texts)  # mrf: no second-surface panel


def test_no_return_is_not_the_error_panels_zero():
    """No-return pixels were white, which is also the error panel's zero: a pixel without a
    return looked like a perfect one (found 2026-11-28)."""
    from spslidar.figures import _RDBU_R, _colormap

    zero = tuple(_colormap(np.array([0.0]), -1.0, 1.0, _RDBU_R, NO_RETURN)[0])
    assert min(abs(a - b) for a, b in zip(zero, NO_RETURN, strict=True)) > 100


def test_a_flat_scene_has_a_colour_range_of_a_bin_each_side(tmp_path):
    """A wall at 25 m: the colour bars read '25 .. 25', the truth all purple and the estimate
    (25.006 m) all yellow, two maps that agree within half a bin drawn as opposites."""
    from spslidar.figures import _limits, _tick

    np.save(tmp_path / "wall.npy", np.full((8, 8), 25.0))
    r = pipeline.run(scene=str(tmp_path / "wall.npy"), size=8, code_length=1023)
    lo, hi, _, _ = _limits(r)
    bin_m = r.metrics["bin_depth_m"]
    assert lo == pytest.approx(25.0 - bin_m) and hi == pytest.approx(25.0 + bin_m)
    assert _tick(lo, lo, hi) != _tick(hi, lo, hi)  # '24.985' and '25.015'
    assert _tick(2.13, 2.13, 4.7) == "2.13"  # a wide range keeps three digits


def test_the_legend_gives_the_no_return_share_the_title_gives(result):
    from spslidar.figures import _legend_items, _outside
    from spslidar.metrics import percent

    text = [t for c, t in _legend_items(result, _outside(result, 0, 100)) if c == NO_RETURN][0]
    assert f"({percent(result.metrics['missing_fraction'])} of" in text  # as the title's


def test_run_truth_is_nan_where_the_scene_has_none(result, tmp_path):
    """run's truth.npy held the filled-in stereo holes, so reconstruct --truth scored them."""
    out = result.save(tmp_path / "o", figure=False)
    truth, valid = np.load(out / "truth.npy"), np.load(out / "valid.npy")
    assert (~valid).any() and np.isnan(truth[~valid]).all() and np.isfinite(truth[valid]).all()


def test_errors_beyond_the_error_bar_are_crossed_and_counted(tmp_path):
    """The error panel's bar is the 99th percentile of |error| (at least a bin), so the few
    pixels that carry an RMSE were drawn at its end colour like any error a bin wide: a run
    at 0.039 m, all of it two pixels at +0.6 and -0.15 m, showed a bar of +-0.015 m and
    nothing else (a sweep of unusual regimes). They are crossed, counted in the panel's title
    and named in the legend; an error within the bar is not crossed."""
    from PIL import Image

    from spslidar.figures import OUT_OF_RANGE, _beyond, _legend_items, _limits, _panels

    r = pipeline.run(scene="steps", size=16, code_length=1023, signal=50, seed=0)
    n = r.depth.shape[0]
    r.depth = _edited(r.depth, (2, 2), r.truth[2, 2] + 0.6)
    r.depth = _edited(r.depth, (9, 9), r.truth[9, 9] + 0.004)  # within the bar
    lim = _limits(r)[3]
    assert lim < 0.1
    title = [p[1] for p in _panels(r) if p[0] == "error"][0]
    assert title.startswith("error (estimate - truth): 1 px beyond the bar") and "0.6" in title
    img = Image.open(depth_figure(r, tmp_path / "e.png")).convert("RGB")
    assert _pixel(img, 2, 2, 2, n) == OUT_OF_RANGE
    assert _pixel(img, 2, 9, 9, n) != OUT_OF_RANGE
    assert any("error beyond its colour bar (1 pixel," in t
               for _, t in _legend_items(r, np.zeros((n, n), bool), _beyond(*_limits(r)[2:])))


def test_reflectivities_above_the_bar_are_counted(result):
    """The reflectivity's bar ends at its 99th percentile: the brighter pixels showed its end
    colour without a word (an audit of 2026-11-29); the panel's title now counts them."""
    from spslidar.figures import _panels, _reflectivity_range

    lo, hi = _reflectivity_range(result)
    above = int(np.count_nonzero(result.reflectivity > hi * (1 + 1e-9)))
    title = next(p[1] for p in _panels(result) if p[0] == "reflectivity")
    assert np.nanmax(result.reflectivity) > hi + 0.02 * (hi - lo)  # (well above its end)
    assert above > 0 and title.startswith(f"reflectivity: {above} px above the bar")
    # those within 2 % of the bar's end are not said: a 99th-percentile bar always leaves a
    # percent above it (a uniform wall read "11 px above the bar, to 1.02" on a bar ending
    # at 1.02, an outside audit of 2026-12-03)
    saved = result.reflectivity
    try:
        result.reflectivity = np.minimum(saved, hi * 1.01)
        title = next(p[1] for p in _panels(result) if p[0] == "reflectivity")
        assert title == "reflectivity (intensity)"
    finally:
        result.reflectivity = saved


def test_second_surface_panel_marks_no_return_and_outliers(tmp_path):
    """The second-surface panel drew pixels without any return in the grey of 'one surface',
    second surfaces beyond its bar at the end colour unmarked, and its legend rounded 1 of
    256 pixels with two surfaces to '100%' one surface (an audit of 2026-11-29)."""
    from PIL import Image

    from spslidar.figures import ONE_SURFACE, OUT_OF_RANGE, _legend_items, _outside

    r = pipeline.run(scene="fence", size=16, code_length=1023, noise=1, compression=0.5,
                     depth="guarded", seed=0)
    n = r.depth.shape[0]
    r.depth = _edited(r.depth, (0, 0), np.nan)
    r.depth2 = _edited(np.full(r.depth2.shape, np.nan), (3, 3),
                       float(np.nanmax(r.truth)) + 5.0)  # beyond the bar
    one = np.argwhere(np.isfinite(r.depth) & ~np.isfinite(r.depth2))[0]
    img = Image.open(depth_figure(r, tmp_path / "d2.png")).convert("RGB")
    panel = 4  # truth, estimate, error, reflectivity, second surface
    assert _pixel(img, panel, 0, 0, n) == NO_RETURN
    assert _pixel(img, panel, *one, n) == ONE_SURFACE
    assert _pixel(img, panel, 3, 3, n) == OUT_OF_RANGE
    texts = " ".join(t for _, t in _legend_items(r, _outside(r, *_limits_of(r))))
    assert "second surface outside the colour range (1 pixel, cross)" in texts
    assert "100%" not in texts.split("one surface (second-surface panel, ")[1].split(")")[0]
    assert depth_figure(r, tmp_path / "m2.png", engine="matplotlib").stat().st_size > 10_000


def _limits_of(r):
    from spslidar.figures import _limits

    return _limits(r)[:2]



def _big(result, n=400):
    """The 16 x 16 result blown up to ``n`` x ``n`` (each pixel a block) without a truth (a
    measured map): its left half at 10 m, its right half at 11 m, and a one-pixel pole at
    10.5 m in column 101."""
    import dataclasses
    import types

    k = n // result.depth.shape[0]
    def up(a):
        return None if a is None else np.kron(np.asarray(a, dtype=np.float64), np.ones((k, k)))
    depth = np.full((n, n), 10.0)
    depth[:, n // 2:] = 11.0
    depth[:, 101] = 10.5
    scene = types.SimpleNamespace(valid=np.zeros((n, n), dtype=bool), name="big",
                                  depth=depth, has_truth=False)
    return dataclasses.replace(result, scene=scene, depth=depth,
                               low_confidence=np.zeros((n, n), dtype=bool),
                               reflectivity=up(result.reflectivity),
                               confidence=np.ones((n, n)), depth2=None,
                               metrics={**result.metrics, "depth_rmse_m": None,
                                        "missing_fraction": 0.0, "coverage": 1.0})


def test_a_panel_larger_than_the_figure_keeps_every_column(result, tmp_path):
    """A 400 x 400 map is drawn a pixel per pixel, not resized to 320, which leaves out a
    fifth of the columns (a one-pixel pole at 512 x 512 vanished: an audit)."""
    from PIL import Image

    from spslidar.figures import _side

    big = _big(result)
    assert _side(big.depth.shape) == 400
    img = Image.open(depth_figure(big, tmp_path / "b.png")).convert("RGB")
    y = 20 + 22 + 200  # the estimate is the first panel without a truth; its middle row
    here, left, right = (img.getpixel((10 + c, y)) for c in (101, 99, 103))
    assert here != left and left == right


def test_the_title_and_the_legend_wrap_to_the_figure(result, tmp_path, monkeypatch):
    """A title longer than the figure is written on as many lines as it needs, every word of
    it, and the legend's items wrap to rows inside the figure (a long file name cut the noise
    verdict off, and a fifth panel's legend its last item: an audit)."""
    from PIL import Image, ImageDraw

    import spslidar.figures as figs

    long = " ".join(f"word{i}" for i in range(400)) + " MOSTLY NOISE"
    monkeypatch.setattr(figs, "_title", lambda r: long)
    items = [((0, 0, 0), f"a legend item of some length number {i}") for i in range(30)]
    monkeypatch.setattr(figs, "_legend_items", lambda *a, **k: items)
    img = Image.open(depth_figure(result, tmp_path / "t.png")).convert("RGB")
    draw = ImageDraw.Draw(Image.new("RGB", (1, 1)))
    lines = figs._wrap(draw, long, img.width - 20)
    assert len(lines) > 1 and " ".join(lines) == long
    assert max(draw.textlength(x) for x in lines) <= img.width - 20
    # the last legend row is inside the image: its swatch's black is drawn there
    bottom = np.asarray(img)[-40:, :, :]
    assert (bottom.sum(axis=2) == 0).any()


def test_the_confidence_panel_draws_no_return_black(result, tmp_path):
    """Without a truth the last panel is the confidence, where a pixel without a return is
    black as the legend says, not the colour map's 0 (an audit)."""
    from PIL import Image

    big = _big(result, 320)
    big.depth = _edited(big.depth, (7, 7), np.nan)
    big.confidence = _edited(big.confidence, (7, 7), 0.0)
    img = Image.open(depth_figure(big, tmp_path / "c.png")).convert("RGB")
    panel = 2  # estimate | reflectivity | confidence
    x, y = 10 + panel * (320 + 70) + 7, 20 + 22 + 7
    assert img.getpixel((x, y)) == NO_RETURN
    assert img.getpixel((x + 3, y)) != NO_RETURN


@pytest.mark.parametrize("lo, hi, labels", [
    (9.985, 10.015, ("9.985", "10.015")),  # '9.99' and '10' read as a third of the span
    (99.4, 100.6, ("99.4", "100.6")),
    (2.13, 4.7, ("2.13", "4.7")),  # three digits resolve it: kept
    (0.0, 3e-5, ("0", "3e-05")),
])
def test_colour_bar_labels_resolve_their_span(lo, hi, labels):
    from spslidar.figures import _tick

    assert (_tick(lo, lo, hi), _tick(hi, lo, hi)) == labels


@pytest.mark.parametrize("share, text", [
    (6 / 262144, "0.002%"), (1 - 1 / 262144, "99.9996%"), (1e-9, "0.0000001%"),
    (0.995, "99.50%"), (0.005, "0.50%"), (0.0, "0%"), (1.0, "100%")])
def test_percent_keeps_a_digit_of_what_is_there(share, text):
    """6 pixels of 262 144 read '0.00%' beside their dots, one missing '100.00%' (an
    audit)."""
    from spslidar.metrics import percent

    assert percent(share) == text


def test_without_a_truth_the_depth_bar_takes_in_the_depths_beside_it(result):
    """Without a truth the bar spans the 1st-99th percentile widened to the depths within a
    quarter of the span: a ramp's correct end pixels are inside it (2 % of any map were
    crossed), a return metres away is not."""
    from spslidar.figures import _limits, _outside

    big = _big(result, 320)
    ramp = np.linspace(10.0, 10.8, 320)[None, :] * np.ones((320, 1))
    big.depth = ramp
    lo, hi = _limits(big)[:2]
    assert (lo, hi) == (10.0, 10.8) and not _outside(big, lo, hi).any()
    big.depth = _edited(big.depth, (5, 5), 14.0)
    lo, hi = _limits(big)[:2]
    assert hi == 10.8 and _outside(big, lo, hi).sum() == 1


def test_a_noiseless_run_says_so_in_its_title():
    """A noiseless run's title read 'm_n=10' as a noisy run's does (an audit)."""
    from spslidar.figures import _title

    r = pipeline.run(size=16, code_length=255, noiseless=True, seed=0)
    assert "noiseless" in _title(r) and "m_n=" not in _title(r)


def test_a_title_with_a_newline_is_written_on_its_lines(result, tmp_path, monkeypatch):
    """A PTU file's name may hold a newline: measuring the title refused multi-line text and
    the figure, so reconstruct, failed (a review)."""
    import spslidar.figures as figs

    monkeypatch.setattr(figs, "_title", lambda r: "measured wall\nday2.ptu: no ground truth")
    assert depth_figure(result, tmp_path / "n.png").stat().st_size > 1000


def test_a_map_mostly_outside_the_truths_range_keeps_its_own_on_the_bar(result):
    """An uncalibrated instrument's map 2.06 m farther than its scene was drawn all end
    colour and crosses (an outside audit of 2026-12-03): where most of the estimate lies
    outside the truth's range, the bar takes in the estimate's 1st-99th percentile; a few
    outliers do not move it."""
    from spslidar.figures import _limits, _outside

    r = result
    saved, truth = r.depth, r.truth
    lo0, hi0 = float(np.min(truth[r.scene.valid])), float(np.max(truth[r.scene.valid]))
    try:
        r.depth = np.where(r.scene.valid, truth + 5.0, np.nan)  # (all beyond its range)
        lo, hi = _limits(r)[:2]
        assert lo == pytest.approx(lo0) and hi == pytest.approx(
            np.percentile(r.depth[r.scene.valid], 99))
        assert _outside(r, lo, hi).mean() < 0.02  # (the estimate's own top percent)
        r.depth = _edited(truth, (3, 3), hi0 + 5.0)  # one outlier: the truth's range
        assert _limits(r)[:2] == (lo0, hi0)
    finally:
        r.depth = saved


def test_the_title_says_what_lies_outside_the_gate_beside_mostly_noise(result):
    """A measured file's returns outside the gate were not said where the map was also
    mostly noise, and a run's scene pixels beyond its gate never (an outside audit of
    2026-12-03): both notes are said, the gate's first."""
    from spslidar.figures import _title

    m = dict(result.metrics)
    r = result
    saved = r.metrics
    try:
        r.metrics = {**m, "returns_outside_gate_fraction": 1.0, "peak_to_noise_p90": 1.0,
                     "peak_to_noise_floor": 2.0, "ptu": {"file": "x.ptu",
                                                         "counts_per_pattern": [1, 2]}}
        assert _title(r).endswith("; 100% of the returns outside the range gate; MOSTLY "
                                  "NOISE: at most a tenth of the pixels hold a return (see "
                                  "the warnings)")
    finally:
        r.metrics = saved
    gated = pipeline.run(scene="steps", size=16, code_length=1023, range_gate=(10.0, 10.3),
                         seed=0)
    beyond = int(np.count_nonzero((gated.truth < 10.0) | (gated.truth > 10.3)))
    assert 0 < beyond < gated.truth.size  # (the steps lie at 10-10.8 m: their far ones)
    assert f"; {beyond} pixels of the scene outside the range gate" in _title(gated)
    assert "outside the range gate" not in _title(result)


def test_a_gmapd_runs_title_names_its_detector():
    """A GMAPD run's title read as a linear counter's (an outside audit of 2026-12-03)."""
    from spslidar.figures import _title

    r = pipeline.run(scene="steps", depth_min=24.5, depth_max=25.5, size=8, code_length=255,
                     compression=1, detector="gmapd", dead_time=50e-9, signal=1e-4,
                     noise=1e-6, periods=200, range_gate=(24.0, 26.0), seed=0)
    assert "GMAPD (dead time 50 ns, 200 periods, pile-up corrected)" in _title(r)
    assert "GMAPD" not in _title(pipeline.run(size=8, code_length=255, seed=0))


def test_the_summary_line_says_the_gate_beside_mostly_noise():
    """The summary line's returns phrase, as the title (an outside audit of 2026-12-03)."""
    from spslidar.metrics import returns_phrase

    noise = {"peak_to_noise_p90": 1.0, "peak_to_noise_floor": 2.0}
    assert returns_phrase(noise, 1.0) == ("a depth in 100% of pixels, mostly noise (see the "
                                          "warning)")
    both = {**noise, "returns_outside_gate_fraction": 0.8}
    assert returns_phrase(both, 1.0) == ("a depth in 100% of pixels, mostly noise, 80% of the "
                                         "returns outside the range gate (see the warnings)")


def test_the_title_names_sub_bin_depths_and_a_conventional_lidars_fairness():
    """``--subbin`` moves the depths and ``--fairness power`` moved an RMSE from 0.325 to
    0.046 m, and no label said either (an outside audit of options): the title says both,
    and neither where they do not apply."""
    from spslidar.figures import _title

    small = dict(scene="steps", size=8, code_length=1023, seed=0)
    assert "argmax depth (sub-bin)" in _title(pipeline.run(**small, depth="argmax",
                                                            subbin=True))
    plain = _title(pipeline.run(**small, depth="argmax"))
    assert "argmax depth" in plain and "sub-bin" not in plain and "fairness" not in plain
    conv = _title(pipeline.run(**small, lidar="conventional", fairness="power"))
    assert "power fairness" in conv
