"""Tests for spslidar.scenes: built-in scenes, user files and bad input."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from spslidar.errors import SceneError
from spslidar.scenes import BUILTIN_SCENES, Scene, load_scene
from spslidar.scenes.builtin import motorcycle_source

WINDOWS = {
    "camera": (20.0, 20.8),
    "motorcycle": (1.5, 6.0),
    "steps": (10.0, 10.6),
    "ramp": (5.0, 5.5),
    "fence": (3.0, 4.0),
    "room": (2.0, 5.0),
    "street": (2.0, 5.0),
}


def _check_scene(sc: Scene, size: int) -> None:
    assert isinstance(sc, Scene)
    assert sc.size == size
    for arr in (sc.depth, sc.reflectivity, sc.valid):
        assert arr.shape == (size, size)
    assert sc.depth.dtype == np.float64 and sc.reflectivity.dtype == np.float64
    assert sc.valid.dtype == bool
    assert np.isfinite(sc.depth).all()
    assert sc.reflectivity.min() >= 0.0 and sc.reflectivity.max() <= 1.0


@pytest.mark.parametrize("size", [32, 64])
@pytest.mark.parametrize("name", BUILTIN_SCENES)
def test_builtin_loads_inside_window(name, size):
    sc = load_scene(name, size)
    _check_scene(sc, size)
    lo, hi = WINDOWS[name]
    assert sc.depth.min() >= lo - 1e-9 and sc.depth.max() <= hi + 1e-9
    assert sc.depth_max > sc.depth_min
    assert sc.name == name


@pytest.mark.parametrize("name", ["room", "street"])
def test_wide_depth_scenes_have_one_pixel_structures(name):
    sc = load_scene(name, 64)
    assert sc.valid.all() and sc.depth_min == pytest.approx(2.0) and sc.depth_max == 5.0
    # a column that differs from both its left and right neighbours: a one-pixel pole
    d = sc.depth
    thin = (np.abs(d[:, 1:-1] - d[:, :-2]) > 0.3) & (np.abs(d[:, 1:-1] - d[:, 2:]) > 0.3)
    assert thin.sum(axis=0).max() >= 10
    assert sc.reflectivity.min() <= 0.12  # low-reflectivity regions
    # the ground recedes: depth falls monotonically down the bottom rows of the middle column
    col = d[40:, 32] if name == "room" else d[45:, 40]
    assert np.all(np.diff(col) <= 0) and col[0] - col[-1] > 1.0


def test_default_scene_is_camera():
    sc = load_scene()
    assert sc.name == "camera" and sc.size == 64


def test_camera_window_exact_and_all_valid():
    sc = load_scene("camera", 64)
    assert abs(sc.depth_min - 20.0) < 1e-3 and abs(sc.depth_max - 20.8) < 1e-3
    assert sc.valid.all()
    np.testing.assert_array_equal(sc.reflectivity, 1.0)
    assert np.unique(sc.depth).size > 50  # a real image, not a few plateaus


def test_motorcycle_depth_and_mask():
    sc = load_scene("motorcycle", 64)
    assert 1.5 < sc.depth_min < sc.depth_max < 6.0
    assert (~sc.valid).any() and sc.valid.mean() > 0.3
    # reflectivity is the left image's luminance rescaled to [0.2, 1]
    assert sc.reflectivity.min() == pytest.approx(0.2) and sc.reflectivity.max() == pytest.approx(
        1.0
    )
    # depth is filled (not zero) at invalid pixels
    assert sc.depth[~sc.valid].min() > 1.5


def test_synthetic_scenes_have_structure():
    steps = load_scene("steps", 64)
    assert np.unique(steps.depth).size >= 4
    assert np.unique(steps.reflectivity).size >= 2
    ramp = load_scene("ramp", 64)
    assert np.unique(ramp.depth).size > 500
    assert ramp.valid.all() and steps.valid.all()


@pytest.mark.parametrize("name", ["camera", "steps", "ramp", "motorcycle"])
def test_remap_window(name):
    sc = load_scene(name, 32, depth_min=3.0, depth_max=3.5)
    assert abs(sc.depth_min - 3.0) < 1e-9 and abs(sc.depth_max - 3.5) < 1e-9
    assert sc.depth.min() >= 3.0 - 1e-12 and sc.depth.max() <= 3.5 + 1e-12


def test_one_sided_window_uses_scene_default():
    sc = load_scene("camera", 32, depth_max=25.0)
    assert abs(sc.depth_min - 20.0) < 1e-9 and abs(sc.depth_max - 25.0) < 1e-9
    sc = load_scene("steps", 32, depth_min=10.3)
    assert abs(sc.depth_min - 10.3) < 1e-9 and abs(sc.depth_max - 10.6) < 1e-9
    with pytest.raises(SceneError, match="depth_min 21 m must be less than depth_max 20.8 m"):
        load_scene("camera", 32, depth_min=21.0)


def test_case_insensitive_names():
    assert load_scene("Steps", 16).name == "steps"


# ---------------------------------------------------------------------------------------------
# user files


def _ramp_depth(h: int, w: int) -> np.ndarray:
    y, x = np.mgrid[0:h, 0:w]
    return 7.0 + 0.01 * x + 0.02 * y


def test_npy_round_trip(tmp_path: Path):
    depth = _ramp_depth(40, 40)
    path = tmp_path / "d.npy"
    np.save(path, depth)
    sc = load_scene(path, 40)  # same size: no resampling
    np.testing.assert_allclose(sc.depth, depth)
    assert sc.valid.all() and np.all(sc.reflectivity == 1.0)
    assert sc.name == "d.npy"
    sc = load_scene(str(path), 20, depth_min=1.0, depth_max=2.0)
    assert abs(sc.depth_min - 1.0) < 1e-9 and abs(sc.depth_max - 2.0) < 1e-9


def test_npy_non_square_is_centre_cropped(tmp_path: Path):
    depth = np.full((30, 50), 9.0)
    depth[:, 10:40] = 4.0  # the centre 30x30 square is the 4 m block
    np.save(tmp_path / "wide.npy", depth)
    sc = load_scene(tmp_path / "wide.npy", 16)
    np.testing.assert_allclose(sc.depth, 4.0)


def test_npz_round_trip(tmp_path: Path):
    depth = _ramp_depth(32, 32)
    refl = np.linspace(0, 1, 32 * 32).reshape(32, 32)
    valid = np.ones((32, 32), dtype=bool)
    valid[5:9, 5:9] = False
    depth_nan = depth.copy()
    depth_nan[~valid] = np.nan  # unknown pixels may hold NaN
    path = tmp_path / "s.npz"
    np.savez(path, depth=depth_nan, reflectivity=refl, valid=valid)
    sc = load_scene(path, 32)
    np.testing.assert_allclose(sc.depth[valid], depth[valid])
    np.testing.assert_allclose(sc.reflectivity, refl)
    np.testing.assert_array_equal(sc.valid, valid)
    assert np.isfinite(sc.depth).all()
    small = load_scene(path, 16)
    # a user's file: a pixel is scored where at least half its 2x2 footprint is valid (all of
    # it before an outside audit of 2026-12-03, which lost 43 % of a file 95 % valid)
    share = valid.reshape(16, 2, 16, 2).mean(axis=(1, 3))
    np.testing.assert_array_equal(small.valid, share >= 0.5)
    assert (~small.valid).sum() == 1


def test_npz_depth_only(tmp_path: Path):
    np.savez(tmp_path / "only.npz", depth=np.full((8, 8), 3.0))
    sc = load_scene(tmp_path / "only.npz", 8)
    assert sc.valid.all() and np.all(sc.depth == 3.0) and np.all(sc.reflectivity == 1.0)


def test_png_round_trip(tmp_path: Path):
    from skimage import io

    img = np.tile(np.arange(0, 256, 4, dtype=np.uint8), (64, 1))
    io.imsave(tmp_path / "g.png", img, check_contrast=False)
    sc = load_scene(tmp_path / "g.png", 64)
    assert abs(sc.depth_min - 20.0) < 1e-9 and abs(sc.depth_max - 20.8) < 1e-9
    assert np.all(np.diff(sc.depth, axis=1) > 0)  # brighter = farther
    rgb = np.stack([img] * 3, axis=-1)
    io.imsave(tmp_path / "c.png", rgb, check_contrast=False)
    sc2 = load_scene(tmp_path / "c.png", 32, depth_min=1.0, depth_max=1.5)
    assert abs(sc2.depth_min - 1.0) < 1e-9 and abs(sc2.depth_max - 1.5) < 1e-9


def test_tif_round_trip(tmp_path: Path):
    from skimage import io

    img = np.tile(np.linspace(0, 1, 20, dtype=np.float32), (20, 1))
    io.imsave(tmp_path / "g.tif", img, check_contrast=False)
    sc = load_scene(tmp_path / "g.tif", 20)
    assert abs(sc.depth_min - 20.0) < 1e-9 and abs(sc.depth_max - 20.8) < 1e-9


# ---------------------------------------------------------------------------------------------
# bad input


def _one_line(exc: pytest.ExceptionInfo) -> None:
    assert "\n" not in str(exc.value)


def test_missing_file(tmp_path: Path):
    path = tmp_path / "nope.npy"
    with pytest.raises(SceneError, match="scene file not found: .*nope.npy") as info:
        load_scene(path)
    _one_line(info)
    with pytest.raises(SceneError, match="scene file not found"):
        load_scene(str(tmp_path / "nope.png"))


def test_unknown_builtin():
    with pytest.raises(SceneError, match="unknown scene 'airplane'.*camera, motorcycle.*path") as i:
        load_scene("airplane")
    _one_line(i)


@pytest.mark.parametrize("suffix, fmt", [(".npy", "npy"), (".npz", "npz"), (".png", "image")])
def test_unreadable_file(tmp_path: Path, suffix, fmt):
    path = tmp_path / f"junk{suffix}"
    path.write_bytes(b"this is not a valid file\n" * 4)
    with pytest.raises(
        SceneError,
        match=f"cannot read scene {'image' if fmt == 'image' else 'file'}"
        rf" junk\{suffix}",
    ) as info:
        load_scene(path)
    _one_line(info)


def test_unsupported_suffix(tmp_path: Path):
    path = tmp_path / "scene.csv"
    path.write_text("1,2\n3,4\n")
    with pytest.raises(SceneError, match="scene.csv has an unsupported format: use .npy"):
        load_scene(path)


def test_npz_without_depth(tmp_path: Path):
    np.savez(tmp_path / "x.npz", z=np.ones((4, 4)))
    with pytest.raises(SceneError, match="x.npz has no 'depth' array"):
        load_scene(tmp_path / "x.npz")


@pytest.mark.parametrize("shape", [(16,), (4, 4, 4)])
def test_not_2d(tmp_path: Path, shape):
    np.save(tmp_path / "a.npy", np.ones(shape))
    with pytest.raises(SceneError, match="must be a 2-D array"):
        load_scene(tmp_path / "a.npy")


@pytest.mark.parametrize("bad, count", [(np.nan, 3), (np.inf, 1), (-1.0, 5)])
def test_bad_depth_values(tmp_path: Path, bad, count):
    depth = np.full((8, 8), 5.0)
    depth[0, :count] = bad
    np.save(tmp_path / "b.npy", depth)
    with pytest.raises(
        SceneError, match=f"b.npy: {count} pixels? ha(s|ve) NaN, infinite or negative"
    ):
        load_scene(tmp_path / "b.npy")
    np.savez(tmp_path / "b.npz", depth=depth)  # no mask: every pixel must be valid
    with pytest.raises(SceneError, match=f"{count} pixel"):
        load_scene(tmp_path / "b.npz")


def test_bad_reflectivity(tmp_path: Path):
    depth = np.full((8, 8), 5.0)
    refl = np.full((8, 8), 0.5)
    refl[1, 1] = 1.5
    np.savez(tmp_path / "r.npz", depth=depth, reflectivity=refl)
    with pytest.raises(SceneError, match=r"1 reflectivity values are NaN or lie outside \[0, 1\]"):
        load_scene(tmp_path / "r.npz")
    np.savez(tmp_path / "s.npz", depth=depth, reflectivity=np.ones((4, 8)))
    with pytest.raises(SceneError, match=r"reflectivity has shape \(4, 8\), depth has \(8, 8\)"):
        load_scene(tmp_path / "s.npz")


def test_bad_valid_mask(tmp_path: Path):
    depth = np.full((8, 8), 5.0)
    np.savez(tmp_path / "v.npz", depth=depth, valid=np.zeros((8, 8), dtype=bool))
    with pytest.raises(SceneError, match="marks no pixel as valid"):
        load_scene(tmp_path / "v.npz")
    np.savez(tmp_path / "w.npz", depth=depth, valid=np.ones((2, 2), dtype=bool))
    with pytest.raises(SceneError, match="valid mask has shape"):
        load_scene(tmp_path / "w.npz")


@pytest.mark.parametrize("size", [3, 0, -1, 2049, 32.5, float("nan"), True])
def test_bad_size(size):
    with pytest.raises(SceneError, match="size"):
        load_scene("steps", size)


def test_bad_window():
    with pytest.raises(SceneError, match="depth_min must be >= 0 m"):
        load_scene("steps", 16, depth_min=-1.0, depth_max=2.0)
    with pytest.raises(SceneError, match="depth_min 3 m must be less than depth_max 3 m"):
        load_scene("steps", 16, depth_min=3.0, depth_max=3.0)
    with pytest.raises(SceneError, match="depth_min 4 m must be less than depth_max 3 m"):
        load_scene("steps", 16, depth_min=4.0, depth_max=3.0)
    with pytest.raises(SceneError, match="depth_max must be a finite number"):
        load_scene("steps", 16, depth_max=float("nan"))


def test_bad_scene_type():
    with pytest.raises(SceneError, match="built-in name"):
        load_scene(42)


def test_scene_dataclass_validates():
    with pytest.raises(SceneError, match="square"):
        Scene("x", np.ones((4, 5)), np.ones((4, 5)), np.ones((4, 5), dtype=bool))
    with pytest.raises(SceneError, match="reflectivity"):
        Scene("x", np.ones((4, 4)), 2 * np.ones((4, 4)), np.ones((4, 4), dtype=bool))


@pytest.mark.parametrize("name", ["camera", "motorcycle"])
@pytest.mark.parametrize("size", [32, 64])
def test_shipped_scene_cache_matches_scikit_image(name, size):
    """The precomputed built-ins (spslidar/data/builtin_scenes.npz) equal a fresh computation
    from scikit-image's sample data; regenerate with ``python -m spslidar.scene_build``."""
    from spslidar import scene_cache

    shipped = scene_cache.lookup(name, size)
    assert shipped is not None, "the cache file is missing from the installation"
    from spslidar.scene_build import compute

    fresh = compute(name, size)
    assert shipped.keys() == fresh.keys()
    # a thousandth of a 1.5 cm bin in metres (the camera's grey levels span its 0.8 m window:
    # 1.5e-5 m of it is 1.9e-5 of grey), not the 1e-12 the arithmetic gives today (1.8e-15 m
    # measured): a resize or sample image changed in a new scikit-image at that level is
    # no scene error of consequence (an audit of the tests)
    tol = {"grey": 1.9e-5, "depth": 1.5e-5, "reflectivity": 1e-5, "source_shape": 0}
    for key in shipped:
        if shipped[key].dtype == bool:
            assert np.array_equal(shipped[key], fresh[key]), key
            continue
        np.testing.assert_allclose(
            shipped[key], fresh[key], rtol=0, atol=tol[key],
            err_msg=f"{key}: regenerate the cache with python -m spslidar.scene_build")


@pytest.mark.parametrize("window", [(None, None), (3.0, 4.0), (1.0, None), (None, 30.0)])
def test_cached_and_computed_scenes_are_the_same_scene(window, monkeypatch):
    """Loading through the cache gives what the scikit-image path gives, in any depth window
    (the remap is applied after the cache, as after the resize).

    Depth and reflectivity agree to 1.5e-5 (m), not bit for bit: the anti-aliased resize
    sums in an order that depends on the NumPy/SciPy release and the CPU's SIMD kernels
    (measured: up to 1.8e-15 m on 1165 motorcycle pixels with numpy 2.4.6 / scipy 1.17.1),
    while a scene error of physical consequence is a thousandth of a 1.5 cm bin (1.5e-5 m).
    The valid mask is a set of pixels and must be equal."""
    from spslidar import scene_cache

    for name in ("camera", "motorcycle"):
        cached = load_scene(name, 64, *window)
        with monkeypatch.context() as m:
            m.setattr(scene_cache, "lookup", lambda *_: None)
            computed = load_scene(name, 64, *window)
        for key in ("depth", "reflectivity"):
            np.testing.assert_allclose(getattr(cached, key), getattr(computed, key),
                                       rtol=0, atol=1.5e-5, err_msg=f"{name} {key}")
        assert np.array_equal(cached.valid, computed.valid), name
        assert cached.notes == computed.notes


def test_motorcycle_source_is_what_the_built_in_scene_is_resized_from():
    """The full-resolution source (used by benchmarks/depth_bounds.py to find mixed-depth
    pixels) is a valid-masked depth in the motorcycle's native window, and the 32 px scene's
    valid truth lies within the source's range."""
    from spslidar import scenes

    depth, lum, valid = scenes.motorcycle_source()
    assert depth.shape == lum.shape == valid.shape and valid.dtype == bool
    assert 0.0 <= lum.min() and lum.max() <= 1.0
    assert np.all(depth[~valid] == 0) and np.all(depth[valid] > 0)
    lo, hi = float(depth[valid].min()), float(depth[valid].max())
    s = scenes.load_scene("motorcycle", size=32)
    assert lo - 1e-9 <= s.depth[s.valid].min() and s.depth[s.valid].max() <= hi + 1e-9


# ------------------------------------------------------------- a user's file at another size
def _file(tmp_path, name, arr):
    np.save(tmp_path / name, arr)
    return str(tmp_path / name)


def test_a_resized_file_holds_only_depths_the_file_holds(tmp_path):
    """A bilinear resize turned a one-pixel pole at 8 m before a 10 m wall into a surface at
    9.7-9.9 m, and a 2 m step up-sampled into four flying pixels; each was scored as the
    truth (an audit of 2026-11-28)."""
    pole = np.full((64, 64), 10.0)
    pole[:, 32] = 8.0
    step = np.full((8, 8), 10.0)
    step[:, 4:] = 8.0
    ramp = np.add.outer(np.linspace(5.0, 9.0, 48), np.linspace(0.0, 1.0, 48))
    for arr, size in ((pole, 16), (pole, 32), (pole, 24), (step, 32), (step, 12), (ramp, 20)):
        s = load_scene(_file(tmp_path, "f.npy", arr), size)
        assert np.isin(s.depth, arr).all(), (arr.shape, size)
        assert any("is resized to" in n for n in s.notes)
    # the pole is dropped where it is a quarter of a footprint, kept where it is half
    assert set(np.unique(load_scene(_file(tmp_path, "p.npy", pole), 16).depth)) == {10.0}
    half = load_scene(_file(tmp_path, "p.npy", pole), 32).depth
    assert (half[:, 16] == 8.0).all() and (np.delete(half, 16, axis=1) == 10.0).all()
    # up-sampling is each file pixel repeated: the step stays a step
    up = load_scene(_file(tmp_path, "s.npy", step), 32).depth
    np.testing.assert_array_equal(up, np.repeat(np.repeat(step, 4, 0), 4, 1))


def test_a_file_at_the_size_is_simulated_as_it_is(tmp_path):
    arr = np.random.default_rng(0).uniform(5.0, 9.0, (16, 16))
    s = load_scene(_file(tmp_path, "f.npy", arr), 16)
    np.testing.assert_array_equal(s.depth, arr)
    assert s.notes == []


def test_depths_given_where_the_mask_says_do_not_score_are_simulated(tmp_path):
    """A ramp valid at one pixel was simulated as a flat wall at that pixel's depth: the
    depths at invalid pixels were replaced by the nearest valid one's."""
    ramp = np.add.outer(np.linspace(10.0, 11.0, 16), np.zeros(16))
    valid = np.zeros((16, 16), bool)
    valid[3, 3] = True
    holes = ramp.copy()
    holes[8:, :] = np.nan  # no depth given there: filled from the nearest valid pixel
    np.savez(tmp_path / "z.npz", depth=ramp, valid=valid)
    np.savez(tmp_path / "h.npz", depth=holes, valid=valid)
    np.testing.assert_array_equal(load_scene(str(tmp_path / "z.npz"), 16).depth, ramp)
    filled = load_scene(str(tmp_path / "h.npz"), 16).depth
    np.testing.assert_array_equal(filled[:8], ramp[:8])
    assert np.isfinite(filled).all()


def test_the_built_in_motorcycle_keeps_its_bilinear_resize():
    """The benchmarks' motorcycle is resized as it was measured (its anti-aliased edge pixels
    are part of issue 21's numbers)."""
    s = load_scene("motorcycle", 24)
    src, _, _ = motorcycle_source()
    assert not np.isin(s.depth[s.valid], src).all()


def test_what_a_users_file_holds_beside_the_scene_is_said(tmp_path):
    """A misspelt 'reflectance' ran at reflectivity 1 without a word; a float TIFF of
    metres was mapped into 20-20.8 m without one (an audit of 2026-11-28)."""
    import skimage.io

    d = np.full((16, 16), 10.0)
    np.savez(tmp_path / "t.npz", depth=d, reflectance=np.full((16, 16), 0.5))
    s = load_scene(str(tmp_path / "t.npz"), 16)
    assert np.all(s.reflectivity == 1.0)
    assert any("reflectance ignored" in n for n in s.notes)
    skimage.io.imsave(tmp_path / "m.tif", np.linspace(3, 4, 256).reshape(16, 16).astype("f4"))
    s = load_scene(str(tmp_path / "m.tif"), 16)
    assert any("read as grey levels mapped onto 20-20.8 m" in n for n in s.notes)


def test_masks_and_holes_a_user_writes(tmp_path):
    d = np.full((16, 16), 10.0)
    v = np.ones((16, 16))
    v[0, 0] = np.nan  # was cast to True, and the depth under it blamed
    np.savez(tmp_path / "v.npz", depth=d, valid=v)
    with pytest.raises(SceneError, match="valid mask must hold booleans or 0/1"):
        load_scene(str(tmp_path / "v.npz"), 16)
    holes = d.copy()
    holes[0, 0] = np.nan
    np.save(tmp_path / "h.npy", holes)
    with pytest.raises(SceneError, match="belong in an .npz with a 'valid' mask"):
        load_scene(str(tmp_path / "h.npy"), 16)
    # reflectivity NaN where the depth is unknown too: accepted (no return there)
    valid = np.ones((16, 16), bool)
    valid[0, 0] = False
    refl = np.full((16, 16), 0.5)
    refl[0, 0] = np.nan
    np.savez(tmp_path / "r.npz", depth=holes, reflectivity=refl, valid=valid)
    s = load_scene(str(tmp_path / "r.npz"), 16)
    assert s.reflectivity[0, 0] == 0.0 and s.reflectivity[0, 1] == 0.5
    refl[0, 1] = np.nan  # at a valid pixel: refused
    np.savez(tmp_path / "r.npz", depth=holes, reflectivity=refl, valid=valid)
    with pytest.raises(SceneError, match="NaN or lie outside"):
        load_scene(str(tmp_path / "r.npz"), 16)
    np.save(tmp_path / "f.npy", d)
    with pytest.raises(SceneError, match=r"depth_min 10 m \(the scene's own: not given\)"):
        load_scene(str(tmp_path / "f.npy"), 16, depth_max=5.0)


def test_a_whole_float_size_is_a_size_as_config_takes_it():
    """``run(size=16.0)`` ran while ``load_scene(..., 16.0)`` was refused (an audit of
    2026-11-28): both take a whole float."""
    assert load_scene("camera", 16.0).depth.shape == (16, 16)
