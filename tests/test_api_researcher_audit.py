"""What an outside researcher's audit of the Python API found on 2026-12-01 (stop 69): limits
a reconstruction ignored, a cache that outlived a re-registration, and edits that changed
later results without a word."""

from __future__ import annotations

import dataclasses
import pickle

import numpy as np
import pytest

import spslidar
from spslidar.errors import ConfigError, SpslidarError
from spslidar.metrics import depth_errors, rmse
from spslidar.products import reflectivity_image


@pytest.fixture(scope="module")
def meas():
    return spslidar.measure(scene="steps", size=16, code_length=1023, noise=2, seed=1)


def test_reconstruct_prices_its_own_solve_against_the_limits_given(meas):
    """``reconstruct(m, iterations=20000, max_time=0.5)`` ran 21 s; ``max_memory`` was
    ignored, and metrics kept measure()'s estimate."""
    with pytest.raises(SpslidarError, match="this reconstruction would take .* more than "
                                            "--max-time 0.5 s"):
        spslidar.reconstruct(meas, iterations=20000, tol=0, max_time=0.5)
    with pytest.raises(SpslidarError, match="--max-memory"):
        spslidar.reconstruct(meas, max_memory=1e-6)
    short = spslidar.reconstruct(meas, iterations=10, depth="argmax")
    long = spslidar.reconstruct(meas, iterations=1000, depth="argmax")
    # the solve priced in proportion to its iterations (the depth stage is the same)
    assert long.metrics["estimate"]["time_s_reconstruct"] > \
        5 * short.metrics["estimate"]["time_s_reconstruct"]
    assert "time_s_reconstruct" not in spslidar.reconstruct(meas).metrics["estimate"]


def test_a_stage_registered_again_is_simulated_again():
    """run_shared gave the first code's measurement after the family was registered again
    under its name."""
    from spslidar.codes import CODES, make_code
    from spslidar.pipeline import clear_shared, run_shared

    kw = dict(scene="steps", size=16, code_length=1023, code="mine_again")
    try:
        with pytest.warns(RuntimeWarning, match="replaced"):
            CODES.add("mine_again", lambda k, L, r=.5, rng=None, index=0: make_code("mseq", L),
                      index=0)
            CODES.add("mine_again", lambda k, L, r=.5, rng=None, index=0:
                      make_code("mseq", L, index=100), index=0)
        first = run_shared(**kw)
        assert run_shared(**kw).metrics["measurement_reused"]
        with pytest.warns(RuntimeWarning, match="replaced"):
            CODES.add("mine_again", lambda k, L, r=.5, rng=None, index=0: make_code("mseq", L),
                      index=0)
        again = run_shared(**kw)
        assert not again.metrics["measurement_reused"]
        assert not np.array_equal(first.corr, again.corr)  # another code's data
        np.testing.assert_array_equal(again.depth, spslidar.run(**kw).depth)
    finally:
        CODES.remove("mine_again")
        clear_shared()


def test_an_infinite_depth_is_refused_by_the_metrics():
    truth = np.full((4, 4), 10.0)
    est = truth + 0.1
    est[np.eye(4, dtype=bool)] = np.inf
    with pytest.raises(ValueError, match="4 infinite depth"):
        rmse(est, truth)
    est[np.eye(4, dtype=bool)] = np.nan  # no return: left out, as documented
    assert depth_errors(est, truth)["depth_rmse_m"] == pytest.approx(0.1)


def test_reflectivity_of_a_depth_outside_the_slices_is_nan():
    from spslidar.forward import delay_to_depth

    slices = np.ones((5, 20))
    lags = np.arange(100, 120)
    depth = np.array([14.99, 0.15, -5.0, delay_to_depth(110, 1e-10),
                      delay_to_depth(99, 1e-10)])
    out = reflectivity_image(slices, depth, lags, 1e-10)
    assert np.isnan(out[:3]).all()  # each read slice 119's or 100's value
    assert out[3] == 3.0 and out[4] == 1.0  # a window holding one slice sums it


def test_a_measurements_scene_and_delays_cannot_be_rebound(meas):
    r = spslidar.reconstruct(meas, depth="argmax")
    before = r.depth_rmse
    with pytest.raises(AttributeError, match="dataclasses.replace"):
        r.scene.depth = r.scene.depth + 1.0
    with pytest.raises(AttributeError, match="simulate again"):
        meas.lags = meas.lags + 5
    assert spslidar.reconstruct(meas, depth="argmax").depth_rmse == before
    moved = dataclasses.replace(meas.scene, depth=meas.scene.depth + 1.0)  # the way given
    assert moved.depth.max() == pytest.approx(meas.scene.depth.max() + 1.0)
    back = pickle.loads(pickle.dumps(meas))  # a pickled measurement still reconstructs
    assert spslidar.reconstruct(back, depth="argmax").depth_rmse == pytest.approx(before)


def test_a_measurements_config_edited_after_it_was_simulated_is_refused():
    m = spslidar.measure(scene="steps", size=16, code_length=1023, noise=2, seed=1)
    m.config.noise = 7.0
    with pytest.raises(ConfigError, match=r"changed after it was simulated \(noise 2.0 -> "
                                          r"7.0\)"):
        spslidar.reconstruct(m)
    m.config.noise = 2.0  # put back: reconstructs
    assert np.isfinite(spslidar.reconstruct(m, depth="argmax").depth_rmse)


@pytest.mark.parametrize("case", ["other_kind", "twice", "plugin"])
def test_option_declarations_are_refused_where_they_are_registered(case):
    """An estimator's ``dead_time`` (a detector's option) was accepted, then refused every
    later ``Config()``; an option named twice kept the first silently; ``plugin`` was read
    by the command line as a module to import."""
    from spslidar.config import Config  # (checked where registered once it is imported)
    from spslidar.depth import ESTIMATORS
    from spslidar.depth.argmax import ArgmaxDepth
    from spslidar.registry import Option

    class Mine(ArgmaxDepth):
        name = "mine_opts"

    options, match = {
        "other_kind": ((Option("dead_time", 1e-9, unit="s", lo=0.0),),
                       "--detector .*gmapd.* declares it"),
        "twice": ((Option("zz_d", 1.0, lo=0, hi=2), Option("zz_d", 5.0, lo=4, hi=6)),
                  "declared twice"),
        "plugin": ((Option("plugin", 1.0),), "one of spslidar's own config keys or flags"),
    }[case]
    with pytest.raises(ValueError, match=match):
        ESTIMATORS.add("mine_opts", Mine, options=options)
    assert "mine_opts" not in ESTIMATORS.names()
    assert Config(size=16).size == 16  # every later config still builds
