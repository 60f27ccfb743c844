"""Scenes as a run records and shares them: ``procedural:SEED`` spelled in ASCII digits and
recorded by its canonical name, a scene's arrays read-only once built, its description kept
out of the warnings, measurement keys taken at their own value, the depth-window hint, sizes
and bounds read as :class:`~spslidar.Config` reads them, and the docstrings' numbers."""

from __future__ import annotations

import inspect
import json
import re

import numpy as np
import pytest

import spslidar
from spslidar.config import Config
from spslidar.errors import ConfigError, SceneError
from spslidar.scenes import load_scene


@pytest.fixture(scope="module")
def meas():
    """procedural:4 at 16 x 16, noise 5 (the audit's case)."""
    return spslidar.measure(scene="procedural:4", size=16, noise=5, seed=0)


# -- 1. the seed's spelling and the scene's name in metrics.json -------------------------------

@pytest.mark.parametrize("spec", ["procedural: 5", "procedural:+5", "procedural:5_000",
                                  "procedural:\u0663", "procedural:\uff15", "procedural:5 0"])
def test_procedural_seed_is_ascii_digits_only(spec):
    with pytest.raises(SceneError, match=r"ASCII digits 0-9 alone.*procedural:7"):
        load_scene(spec, 8)


@pytest.mark.parametrize("spec, name", [("procedural:007", "procedural:7"),
                                        ("PROCEDURAL:5", "procedural:5"),
                                        ("  procedural:5 ", "procedural:5"),
                                        ("procedural:0", "procedural:0")])
def test_procedural_seed_spellings_that_stay(spec, name):
    assert load_scene(spec, 8).name == name


def test_huge_seed_is_one_short_line():
    with pytest.raises(SceneError, match=r"a seed of 5000 characters.*from 0 to") as info:
        load_scene("procedural:" + "9" * 5000, 8)
    assert len(str(info.value)) < 200 and "\n" not in str(info.value)


def test_metrics_record_the_canonical_scene_name(tmp_path):
    r = spslidar.run(scene=" PROCEDURAL:007", size=8, code_length=255, iterations=5,
                     depth="argmax", seed=0)
    assert r.config.scene == " PROCEDURAL:007"  # what sweeps hash stays as given
    out = r.save(tmp_path / "out", figure=False)
    m = json.loads((out / "metrics.json").read_text())
    assert m["scene_name"] == "procedural:7"
    assert m["config"]["scene"] == " PROCEDURAL:007"


# -- 2. a built scene is read-only --------------------------------------------------------------

def test_result_scene_cannot_change_later_scores(meas):
    r = spslidar.reconstruct(meas)
    before = r.depth_rmse
    with pytest.raises(ValueError, match="read-only"):
        r.scene.depth[:] += 1
    with pytest.raises(ValueError, match="read-only"):
        meas.scene.reflectivity[0, 0] = 0.0
    with pytest.raises(ValueError, match="read-only"):
        r.scene.valid[0, 0] = False
    assert spslidar.reconstruct(meas).depth_rmse == before


@pytest.mark.parametrize("spec, window", [("camera", (None, None)), ("steps", (None, None)),
                                          ("room", (None, None)), ("fence", (1.0, 2.0)),
                                          ("procedural:3", (None, None)),
                                          ("motorcycle", (2.0, 3.0)),
                                          ("motorcycle", (None, None))])
def test_every_built_in_scene_is_read_only(spec, window):
    sc = load_scene(spec, 16, *window)
    arrays = [sc.depth, sc.reflectivity, sc.valid]
    arrays += [a for a in (getattr(sc, "behind_depth", None),
                           getattr(sc, "behind_reflectivity", None)) if a is not None]
    assert not any(a.flags.writeable for a in arrays)


def test_user_scene_file_is_read_only_and_callers_arrays_stay_theirs(tmp_path):
    from spslidar.scenes import Scene

    np.save(tmp_path / "d.npy", np.linspace(2.0, 3.0, 64).reshape(8, 8))
    assert not load_scene(tmp_path / "d.npy", 8).depth.flags.writeable
    mine = np.full((4, 4), 3.0)
    sc = Scene("mine", mine, np.ones((4, 4)), np.ones((4, 4), bool))
    assert mine.flags.writeable and not sc.depth.flags.writeable


# -- 3. a scene's description is no warning ------------------------------------------------------

def test_procedural_description_is_a_note_not_a_warning(meas):
    r = spslidar.reconstruct(meas)
    assert not any("is a clutter" in w for w in r.warnings + r.metrics["warnings"])
    assert r.metrics["scene_note"] == "a clutter at 2.13-5.48 m"
    assert "scene procedural:4 (a clutter at 2.13-5.48 m) 16x16" in r.summary()
    assert load_scene("steps", 8).description == ""


# -- 4. measurement keys at the measurement's own value -----------------------------------------

def test_reconstruct_takes_measurement_keys_at_their_value(meas):
    plain = spslidar.reconstruct(meas).depth_rmse
    same = spslidar.reconstruct(meas, noise=5, size=16.0, scene="procedural:4", seed=0)
    assert same.depth_rmse == plain
    # (a stage's option too: dead_time was "unknown key", an outside audit)
    for key, value in (("noise", 6), ("noise", -1), ("size", 32), ("scene", "procedural:5"),
                       ("dead_time", 1e-7)):
        with pytest.raises(ConfigError, match=f"cannot change {key}"):
            spslidar.reconstruct(meas, **{key: value})


# -- 5. the docstrings' numbers -----------------------------------------------------------------

def test_procgen_docstring_numbers_hold():
    from spslidar.pipeline.plan import _plan
    from spslidar.scenes import procgen
    from spslidar.scenes.builtin import _band

    doc = " ".join(procgen.__doc__.split())
    lo, hi = map(int, re.search(r"holds (\d+)-(\d+) range slices", doc).groups())
    sc = load_scene("procedural:43", 64)
    slices = _plan(Config(scene="procedural:43", size=64), sc, [], announce=False).lags.size
    assert lo <= slices <= hi  # 142 (the docstring said 150-250)
    span_lo, span_hi = map(float, re.search(r"([\d.]+)-([\d.]+) m at 4 x 4", doc).groups())
    for seed in (0, 1, 2):
        s4 = load_scene(f"procedural:{seed}", 4)
        assert span_lo <= s4.depth_max - s4.depth_min <= span_hi
    assert "max(1/64, 1/N)" in doc
    for size, px in ((32, 1), (64, 1), (128, 2), (512, 8)):
        t = (np.arange(size) + 0.5) / size
        assert _band(t, 0.3, size).sum() == px


def test_result_reflectivity_docstring_says_it_can_pass_one(meas):
    from spslidar.pipeline.results import Result

    assert np.nanmax(spslidar.reconstruct(meas).reflectivity) > 1.0
    src = " ".join(inspect.getsource(Result).split())
    assert "not bounded by 1" in src and "alpha in [0, 1]" not in src


# -- 6. the depth window's hint -----------------------------------------------------------------

@pytest.mark.parametrize("spec, window, hinted", [("procedural:3", (None, 1.0), "depth_min"),
                                                 ("fence", (None, 1.0), "depth_min"),
                                                 ("fence", (5.0, None), "depth_max")])
def test_depth_window_error_says_which_bound_is_the_scenes(spec, window, hinted):
    with pytest.raises(SceneError, match="depth window is empty") as info:
        load_scene(spec, 8, *window)
    msg = str(info.value)
    assert re.search(rf"{hinted} [\d.]+ m \(the scene's own: not given\)", msg), msg


# -- 7. numbers as Config reads them; a path that is not one -------------------------------------

def test_load_scene_refuses_bools_as_config_does():
    for key in ("depth_min", "depth_max"):
        for flag in (True, np.True_):  # (True was read as a 1 m bound)
            with pytest.raises(SceneError, match=f"{key} must be a number of metres, got "):
                load_scene("steps", 16, **{key: flag})
        with pytest.raises(ConfigError):
            Config(**{key: True})
    for size in (True, np.True_):
        with pytest.raises(SceneError, match="scene size must be an integer"):
            load_scene("steps", size)


def test_save_refuses_a_non_path_in_one_line(meas, tmp_path):
    r = spslidar.reconstruct(meas)
    for bad in (5, None, b"out"):
        with pytest.raises(ConfigError, match=r"out_dir must be a folder path .* got "):
            r.save(bad)
    assert list(tmp_path.iterdir()) == []


def test_a_sweep_takes_one_scene_spelled_two_ways_as_one():
    """``procedural:007`` and ``procedural:7`` are one scene: a grid listing both is refused
    as a value listed twice, and a point's seed and cache key do not depend on the spelling
    (they were two seeds and two cache files)."""
    from spslidar.errors import ConfigError
    from spslidar.experiments.sweep.command import _seeded
    from spslidar.experiments.sweep.grid import _check_grid, point_key
    from spslidar.scenes import scene_spec

    assert scene_spec(" PROCEDURAL:007 ") == "procedural:7"
    assert scene_spec("Camera") == "camera" and scene_spec("runs/x.npy") == "runs/x.npy"
    assert scene_spec("procedural:+5") == "procedural:+5"  # refused later, as written
    with pytest.raises(ConfigError, match="the same value twice"):
        _check_grid({"scene": ["procedural:7", "procedural:007"]})
    a, b = _seeded([{"scene": "procedural:007", "size": 8}, {"scene": "procedural:7",
                                                            "size": 8}],
                   [{}, {}], frozenset(), 0)
    assert a == b and point_key(a) == point_key(b)


def test_unscored_surfaces_outside_the_default_gate_are_said(tmp_path, capsys):
    """The default gate is the truth's: a scene of one valid pixel at 20.4 m whose 255 other
    pixels (no truth, but reflecting) lie at 20 m had them outside the gate without a word,
    its figure all noise (an audit). Now a warning counts them."""
    from spslidar.cli import main

    depth = np.full((16, 16), 20.0)
    depth[8, 8] = 20.4
    valid = np.zeros((16, 16), dtype=bool)
    valid[8, 8] = True
    np.savez(tmp_path / "one.npz", depth=depth, reflectivity=np.ones((16, 16)), valid=valid)
    assert main(["run", "--scene", str(tmp_path / "one.npz"), "--size", "16",
                 "--code-length", "255", "--no-figure", "--out", str(tmp_path / "o")]) == 0
    err = capsys.readouterr().err
    assert "255 pixels without a ground truth (not scored) have surfaces outside" in err


@pytest.mark.parametrize("window, depth", [({"depth_min": 5.0}, 6.0),
                                           ({"depth_min": 5.0, "depth_max": 5.5}, 5.5),
                                           ({"depth_max": 9.0}, 6.0)])
def test_a_flat_scene_keeps_its_depth_in_a_window(tmp_path, window, depth):
    """A file flat at 6 m has no depth range to map onto a window: it keeps its depth where
    the window holds it and goes to the nearer end where not, and a note says which (it
    went to depth_min: 6 m given --depth-min 5 was simulated at 5 m without a word; an
    audit of 2026-11-29)."""
    from spslidar.scenes import load_scene

    np.save(tmp_path / "flat.npy", np.full((8, 8), 6.0))
    scene = load_scene(str(tmp_path / "flat.npy"), 8, **window)
    assert np.all(scene.depth == depth)
    assert any("is flat at 6 m" in note for note in scene.notes)
