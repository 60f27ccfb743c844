"""Pattern files whose layout a reader could take two ways, said rather than read silently
(an outside audit of orientation conventions, 2026-12-01): a ``.mat`` that SciPy wrote, and
images with an orientation tag."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image
from scipy import io as sio

from spslidar.io.lab_arrays import read_patterns_file


@pytest.fixture
def patterns():
    rng = np.random.default_rng(12)
    return (rng.random((9, 8, 8)) < 0.5).astype(np.uint8)


def test_a_scipy_written_mat_matrix_is_said_and_read_as_matlab_stores_it(tmp_path,
                                                                         patterns):
    """Row-major rows from Python in a .mat read as the transposed map with exit 0."""
    m = patterns.shape[0]
    rows = patterns.reshape(m, -1, order="F")  # MATLAB's P(:)' rows: read right
    sio.savemat(tmp_path / "a.mat", {"A": rows})
    with pytest.warns(UserWarning, match=r"written by SciPy .* not MATLAB: its 9 x 64 matrix "
                                         r"is read as MATLAB stores one"):
        got = read_patterns_file(tmp_path / "a.mat")
    np.testing.assert_array_equal(np.asarray(got).reshape(patterns.shape), patterns)
    # a stack has one layout whoever wrote it: nothing to say
    sio.savemat(tmp_path / "s.mat", {"S": np.moveaxis(patterns, 0, -1)})
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        np.testing.assert_array_equal(
            np.asarray(read_patterns_file(tmp_path / "s.mat")).reshape(patterns.shape),
            patterns)


def test_an_image_orientation_tag_is_said_and_not_applied(tmp_path, patterns):
    """A TIFF or PNG tagged to be shown turned half a turn was read as stored, the map turned
    without a word."""
    import tifffile

    folder = tmp_path / "png"
    folder.mkdir()
    for i, p in enumerate(patterns):
        img = Image.fromarray((p * 255).astype(np.uint8))
        exif = Image.Exif()
        exif[274] = 3 if i == 0 else 1
        img.save(folder / f"p{i}.png", exif=exif)
    with pytest.warns(UserWarning, match=r"1 of 9 image files carry an orientation tag "
                                         r"\(3; 1 is as stored\).* e\.g\. p0\.png: they are "
                                         r"read as stored"):
        got = read_patterns_file(folder)
    np.testing.assert_array_equal(np.asarray(got), patterns)  # as stored
    tif = tmp_path / "stack.tif"
    tifffile.imwrite(tif, patterns * 255, extratags=[(274, 3, 1, 3, True)])
    with pytest.warns(UserWarning, match=r"orientation tag \(3;"):
        got = read_patterns_file(tif)
    np.testing.assert_array_equal(np.asarray(got), patterns)
