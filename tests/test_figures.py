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
