"""Procedural scenes (``procedural:SEED``) and the two-surface ``fence`` scene: deterministic
per seed, valid, wide in depth with the structures they promise, and the fence's second
surface simulated and found end to end."""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.errors import SceneError
from spslidar.scenes import load_scene
from spslidar.scenes.procgen import LayeredScene


def _thin_columns(d: np.ndarray) -> int:
    """Most pixels in one column that stand 0.3 m off both horizontal neighbours."""
    thin = (np.abs(d[:, 1:-1] - d[:, :-2]) > 0.3) & (np.abs(d[:, 1:-1] - d[:, 2:]) > 0.3)
    return int(thin.sum(axis=0).max())


@pytest.mark.parametrize("seed", [0, 7, 123456789])
def test_same_seed_same_scene_other_seed_other_scene(seed):
    a, b = load_scene(f"procedural:{seed}", 48), load_scene(f"procedural:{seed}", 48)
    np.testing.assert_array_equal(a.depth, b.depth)
    np.testing.assert_array_equal(a.reflectivity, b.reflectivity)
    other = load_scene(f"procedural:{seed + 1}", 48)
    assert not np.array_equal(a.depth, other.depth)
    assert a.name == f"procedural:{seed}"


def test_procedural_scenes_are_valid_wide_and_cluttered():
    thin, dark, bright = [], [], []
    for seed in range(10):
        sc = load_scene(f"procedural:{seed}", 64)
        assert sc.valid.all() and np.isfinite(sc.depth).all()
        assert 0.05 <= sc.reflectivity.min() and sc.reflectivity.max() <= 1.0
        assert 1.4 <= sc.depth_min and sc.depth_max <= 6.5
        assert sc.depth_max - sc.depth_min >= 1.5  # a wide-depth scene
        # a receding floor: the bottom row is near (unless an object stands in front)
        assert sc.depth[-1, 32] < sc.depth[40, 32] - 0.3 or sc.depth[-1, 32] <= sc.depth_min + 0.5
        thin.append(_thin_columns(sc.depth))
        dark.append(np.mean(sc.reflectivity < 0.2))
        bright.append(np.mean(sc.reflectivity > 0.7))
    assert np.mean(np.array(thin) >= 5) >= 0.8  # one-pixel poles, legs or slats in most
    assert np.mean(np.array(dark) > 0.005) >= 0.7  # dark objects in most ...
    assert np.mean(np.array(bright) > 0.005) >= 0.7  # ... and bright ones


def test_procedural_scene_window_and_sizes():
    sc = load_scene("procedural:3", 16, 7.0, 8.0)
    assert sc.depth.min() == pytest.approx(7.0) and sc.depth.max() == pytest.approx(8.0)
    # the same layout at another size: same depth range to within the sampling
    a, b = load_scene("procedural:3", 32), load_scene("procedural:3", 64)
    assert abs(a.depth_max - b.depth_max) < 1e-9


@pytest.mark.parametrize("spec", ["procedural:x", "procedural:-1", "procedural:",
                                  "procedural", "procedural:1.5"])
def test_bad_seeds_are_one_clear_error(spec):
    with pytest.raises(SceneError, match="procedural"):
        load_scene(spec, 16)


def test_fence_scene_has_two_surfaces_behind_the_mesh():
    sc = load_scene("fence", 64)
    assert isinstance(sc, LayeredScene)
    two = sc.two_surface
    assert 0.3 < two.mean() < 0.6
    np.testing.assert_allclose(sc.depth[two], 3.0)
    np.testing.assert_allclose(sc.behind_depth[two], 4.0)
    assert np.isnan(sc.behind_depth[~two]).all() and (sc.behind_reflectivity[~two] == 0).all()
    w = load_scene("fence", 16, 10.0, 12.0)
    assert np.nanmax(w.behind_depth) == pytest.approx(12.0)
    with pytest.raises(SceneError, match="behind"):
        LayeredScene("bad", np.full((4, 4), 3.0), np.ones((4, 4)), np.ones((4, 4), bool),
                     behind_depth=np.full((4, 4), 2.0), behind_reflectivity=np.ones((4, 4)))


def test_fence_second_surface_end_to_end():
    import spslidar

    r = spslidar.run(scene="fence", size=32, noise=1, compression=0.5, depth="guarded", seed=1)
    sc = r.scene
    two = sc.two_surface
    # the first surface is what the RMSE scores: the mesh, found on nearly every pixel
    assert r.depth_rmse < 0.05
    assert r.depth2 is not None and r.depth2.shape == (32, 32)
    found = np.isfinite(r.depth2)
    # the wall behind the mesh: found on most mesh pixels, within two bins (3 cm) where found
    assert found[two].mean() > 0.6
    assert np.all(np.abs(r.depth2[two & found] - 4.0) < 0.03)
    # few second surfaces where there is one (the solid posts, rail and the open wall)
    assert found[~two].mean() < 0.1
    assert r.metrics["two_surface_fraction"] == pytest.approx(found.mean())
