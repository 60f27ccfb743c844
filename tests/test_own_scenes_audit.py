"""A researcher's own scenes, as real datasets come (an outside audit of 2026-11-29): zeros
for "no data", millimetres, resized textures, scenes at the lidar, RGB images. Each test
failed before its mend."""

from __future__ import annotations

import json

import numpy as np
import pytest

import spslidar
from spslidar.cli import main
from spslidar.errors import ConfigError, SceneError
from spslidar.scenes import load_scene


def _plane():
    y, x = np.mgrid[0:16, 0:16]
    return 30 + 0.05 * x + 0.02 * y


def test_zero_holes_in_a_depth_map_are_refused_with_the_valid_mask_hint(tmp_path, capsys):
    """0 is "no data" in many depth datasets; such holes were simulated as a surface at 0 m
    and scored (coverage 100 %, the truth from 0 m, no word). One line, exit 2, nothing
    written; the same depths marked invalid in an .npz run."""
    d = _plane()
    d[2:6, 3:9] = 0.0
    np.save(tmp_path / "holes.npy", d)
    out = tmp_path / "o"
    assert main(["run", "--scene", str(tmp_path / "holes.npy"), "--size", "16",
                 "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "24 pixels have a depth of 0 m" in err[0] and "'valid'" in err[0]
    assert not out.exists()
    with pytest.raises(SceneError, match="depth of 0 m"):
        spslidar.run(scene=str(tmp_path / "holes.npy"), size=16)
    np.savez(tmp_path / "holes.npz", depth=d, valid=d > 0)
    r = spslidar.run(scene=str(tmp_path / "holes.npz"), size=16, seed=0)
    assert r.metrics["n_valid"] == 256 - 24 and r.depth_rmse < 0.02
    # --depth-min maps the file's nearest depth to it: 0 is a depth there; --depth-max alone
    # keeps the nearest depth, 0 m (it let the holes through, a review)
    assert load_scene(str(tmp_path / "holes.npy"), 16, depth_min=2.0, depth_max=5.0).depth.min() \
        == pytest.approx(2.0)
    with pytest.raises(SceneError, match="depth of 0 m"):
        load_scene(str(tmp_path / "holes.npy"), 16, depth_max=12.0)


def test_a_truth_with_zeros_for_no_data_is_refused():
    """``reconstruct --truth`` scored a truth's zeros (a 16x16 plane read 9.29 m for 0.028)."""
    from spslidar.pipeline.real import _check_truth

    t = _plane()
    t[0, 0] = 0.0
    with pytest.raises(ConfigError, match=r"1 depths of 0 m.*NaN"):
        _check_truth(t, 16)
    t[0, 0] = np.nan
    assert np.isnan(_check_truth(t, 16)[0, 0])


def test_a_scene_in_millimetres_is_asked_about_its_units(tmp_path):
    """2500-3550 "m" (millimetres): every warning said to lengthen the code (following it
    left an RMSE of 137 m). Checked on the plan, before the 48 s simulation."""
    from spslidar.config import Config
    from spslidar.pipeline.plan import timeline

    y, x = np.mgrid[0:16, 0:16]
    np.save(tmp_path / "mm.npy", (2500 + 50 * x + 20 * y).astype(np.uint16))
    scene = load_scene(str(tmp_path / "mm.npy"), 16)
    warns: list[str] = []
    timeline(Config(size=16), scene, warns)
    said = [w for w in warns if "are the scene's depths in metres?" in w]
    assert len(said) == 1 and "2.5-3.55 m" in said[0]
    metres: list[str] = []  # the camera at 20 m beyond a 1023-bit code's 15 m: no question
    timeline(Config(size=16, code_length=1023), load_scene("camera", 16), metres)
    assert any("unambiguous range" in w for w in metres)
    assert not any("in metres?" in w for w in metres)  # (it asked, a review)


def test_result_truth_is_nan_where_the_scene_has_none(tmp_path):
    """The API's truth held the fill (the nearest pixel's depth) at the holes, which
    ``truth.npy`` writes NaN: a user's own RMSE scored them."""
    d = _plane()
    d[2:6, 3:9] = np.nan
    np.savez(tmp_path / "h.npz", depth=d, valid=np.isfinite(d))
    r = spslidar.run(scene=str(tmp_path / "h.npz"), size=16, seed=0)
    assert np.isnan(r.truth).sum() == 24
    assert np.sqrt(np.nanmean((r.depth - r.truth) ** 2)) == pytest.approx(r.depth_rmse)
    with pytest.raises(ValueError):
        r.truth[0, 0] = 1.0  # read-only, as before
    r.save(tmp_path / "o", figure=False)
    np.testing.assert_array_equal(np.load(tmp_path / "o" / "truth.npy"), r.truth)


def test_the_reflectivity_is_resized_with_the_depth_it_belongs_to(tmp_path):
    """Bilinear beside the depth's median: a 0/1 texture up-sampled to greys of 0.25-0.75, a
    pixel given the dark surface's depth took the bright one's light."""
    y, x = np.mgrid[0:8, 0:8]
    np.savez(tmp_path / "up.npz", depth=np.where(x < 4, 30.0, 32.0),
             reflectivity=((x + y) % 2).astype(float))
    s = load_scene(str(tmp_path / "up.npz"), 16)
    assert set(np.unique(s.reflectivity)) == {0.0, 1.0}
    np.testing.assert_array_equal(s.reflectivity[::2, ::2], ((x + y) % 2))
    d = np.where(np.arange(32)[None, :] < 16, 10.0, 12.0) * np.ones((32, 1))
    a = np.where(d == 10.0, 0.1, 0.9)
    np.savez(tmp_path / "half.npz", depth=d, reflectivity=a)
    s = load_scene(str(tmp_path / "half.npz"), 10)
    np.testing.assert_array_equal(s.reflectivity, np.where(s.depth == 10.0, 0.1, 0.9))


@pytest.mark.parametrize("size", [16, 13, 8])
def test_a_pixel_collects_its_footprints_mean_reflectivity_on_its_surface(tmp_path, size):
    """A 0.2 / 1.0 striped texture on a flat wall halved in size read 1.0 everywhere and its
    mirror image 0.2 (the median's one source pixel, the same place in every footprint: an
    audit of 2026-11-30); a pixel collects its footprint's mean, and a mirrored file gives the
    mirrored scene. Where the footprint spans two surfaces only the one taken counts."""
    stripes = np.where(np.arange(32) % 2 == 0, 0.2, 1.0) * np.ones((32, 1))
    flat = np.full((32, 32), 20.0)
    np.savez(tmp_path / "s.npz", depth=flat, reflectivity=stripes)
    np.savez(tmp_path / "m.npz", depth=flat, reflectivity=stripes[:, ::-1])
    a = load_scene(str(tmp_path / "s.npz"), size).reflectivity
    b = load_scene(str(tmp_path / "m.npz"), size).reflectivity
    np.testing.assert_allclose(b, a[:, ::-1], atol=1e-12)
    assert a.mean() == pytest.approx(0.6, abs=0.02)  # (odd footprints: 0.47-0.73 each)
    if 32 % size == 0:
        np.testing.assert_allclose(a, 0.6, atol=1e-12)
    # two surfaces 2 m apart in each 4x4 footprint: the nearer 8 pixels of 0.3 and 0.5
    # (mean 0.4) are the surface taken; the far ones' 0.9 is not mixed in
    y, x = np.mgrid[0:32, 0:32]
    depth = np.where(y % 4 < 2, 10.0, 12.0)
    refl = np.where(y % 4 < 2, np.where(x % 2 == 0, 0.3, 0.5), 0.9)
    np.savez(tmp_path / "two.npz", depth=depth, reflectivity=refl)
    s = load_scene(str(tmp_path / "two.npz"), 8)
    np.testing.assert_allclose(s.depth, 10.0)
    np.testing.assert_allclose(s.reflectivity, 0.4, atol=1e-12)


def test_a_scene_at_the_lidar_gets_a_gate_of_sixteen_slices(tmp_path):
    """The near end cannot go below 0 m: what it lost is added at the far end (a scene 3 cm
    away had 13 slices, under the 16 the docs promise)."""
    np.save(tmp_path / "near.npy", _plane() * 1e-3)
    r = spslidar.run(scene=str(tmp_path / "near.npy"), size=16, seed=0)
    assert r.metrics["range_gate_m"][0] == 0.0 and r.metrics["n_slices"] >= 16
    far = spslidar.run(size=16, seed=0)  # away from 0 m the gate is as it was
    assert far.metrics["range_gate_m"] == pytest.approx([19.9550311313, 20.8449688687])


def test_an_rgb_image_is_not_said_to_be_a_float_or_16_bit_one(tmp_path):
    """The note for float TIFFs and 16-bit PNGs read the type after the RGB image was made
    grey: an 8-bit RGB PNG was "(float64, 0 .. 1)"."""
    import imageio.v3 as iio
    rng = np.random.default_rng(0)
    iio.imwrite(tmp_path / "rgb.png", rng.integers(0, 255, (16, 16, 3), dtype=np.uint8))
    iio.imwrite(tmp_path / "g16.png", rng.integers(0, 65535, (16, 16), dtype=np.uint16))
    assert load_scene(str(tmp_path / "rgb.png"), 16).notes == []
    (note,) = load_scene(str(tmp_path / "g16.png"), 16).notes
    assert "(uint16, " in note


def test_the_cli_writes_nan_truth_and_scores_the_same(tmp_path):
    """The CLI and the API agree on the holes."""
    d = _plane()
    d[0, :4] = np.nan
    np.savez(tmp_path / "h.npz", depth=d, valid=np.isfinite(d))
    assert main(["run", "--scene", str(tmp_path / "h.npz"), "--size", "16", "--no-figure",
                 "--out", str(tmp_path / "o")]) == 0
    t = np.load(tmp_path / "o" / "truth.npy")
    m = json.loads((tmp_path / "o" / "metrics.json").read_text())
    assert np.isnan(t).sum() == 4 and m["n_valid"] == 252


def test_a_jpeg_scene_is_said_to_be_lossy(tmp_path):
    """A JPEG was taken as a scene without a word while the help named only PNG and TIFF (an
    outside audit): its compression moves grey levels, so it is said; a PNG is not."""
    import imageio.v3 as iio

    img = (np.tile(np.arange(16), (16, 1)) * 16).astype(np.uint8)
    for name in ("s.jpg", "s.png"):
        iio.imwrite(tmp_path / name, img)
        r = spslidar.run(scene=str(tmp_path / name), size=16, code_length=1023, seed=0)
        said = [w for w in r.warnings if "is a JPEG" in w]
        assert len(said) == (name.endswith(".jpg"))
