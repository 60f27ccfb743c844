"""depth.png: each kind of pixel without a number has its own colour (issue 15, item 6)."""

import numpy as np
import pytest

from spslidar import pipeline
from spslidar.figures import _PANEL, LOW_CONFIDENCE, NO_RETURN, NO_TRUTH, depth_figure


@pytest.fixture(scope="module")
def result():
    r = pipeline.run(scene="motorcycle", size=16, code_length=1023, noise=10, seed=0)
    # make every kind present: a pixel without return, and low-confidence ones
    r.depth[0, 0] = np.nan
    r.low_confidence = np.zeros(r.depth.shape, dtype=bool)
    r.low_confidence[5, 5] = True
    return r


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
    saved = r.depth.copy()
    try:
        r.depth[3, 3] = float(np.nanmax(r.truth)) + 5.0
        img = Image.open(depth_figure(r, tmp_path / "o.png")).convert("RGB")
        assert _pixel(img, 1, 3, 3, r.depth.shape[0]) == OUT_OF_RANGE
        outside = np.isfinite(r.depth) & (r.depth > np.nanmax(r.truth) + 1)
        assert "outside the colour range" in " ".join(t for _, t in _legend_items(r, outside))
        assert "RMSE" in _title(r)
        # the title names the solver with the regulariser it ran ('auto' resolved)
        assert f"{r.config.solver} + {r.metrics['config']['regulariser']}," in _title(r)
    finally:
        r.depth[...] = saved


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
    r.depth[2, 2] = r.truth[2, 2] + 0.6
    r.depth[9, 9] = r.truth[9, 9] + 0.004  # within the bar
    lim = _limits(r)[3]
    assert lim < 0.1
    title = [p[1] for p in _panels(r) if p[0] == "error"][0]
    assert "1 px beyond the bar" in title and "0.6" in title
    img = Image.open(depth_figure(r, tmp_path / "e.png")).convert("RGB")
    assert _pixel(img, 2, 2, 2, n) == OUT_OF_RANGE
    assert _pixel(img, 2, 9, 9, n) != OUT_OF_RANGE
    assert any("error beyond its colour bar (1 pixel," in t
               for _, t in _legend_items(r, np.zeros((n, n), bool), _beyond(*_limits(r)[2:])))


def test_reflectivities_above_the_bar_are_counted(result):
    """The reflectivity's bar ends at its 99th percentile: the brighter pixels showed its end
    colour without a word (an audit of 2026-11-29); the panel's title now counts them."""
    from spslidar.figures import _panels, _reflectivity_range

    _, hi = _reflectivity_range(result)
    above = int(np.count_nonzero(result.reflectivity > hi * (1 + 1e-9)))
    title = next(p[1] for p in _panels(result) if p[0] == "reflectivity")
    assert above > 0 and title.startswith(f"reflectivity: {above} px above the bar")


def test_second_surface_panel_marks_no_return_and_outliers(tmp_path):
    """The second-surface panel drew pixels without any return in the grey of 'one surface',
    second surfaces beyond its bar at the end colour unmarked, and its legend rounded 1 of
    256 pixels with two surfaces to '100%' one surface (an audit of 2026-11-29)."""
    from PIL import Image

    from spslidar.figures import ONE_SURFACE, OUT_OF_RANGE, _legend_items, _outside

    r = pipeline.run(scene="fence", size=16, code_length=1023, noise=1, compression=0.5,
                     depth="guarded", seed=0)
    n = r.depth.shape[0]
    r.depth[0, 0] = np.nan
    r.depth2[...] = np.nan
    r.depth2[3, 3] = float(np.nanmax(r.truth)) + 5.0  # beyond the bar
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
