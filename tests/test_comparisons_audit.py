"""Comparing code families and pattern kinds as an outside researcher would (audits of
2026-12-01, stop 69): the reflectivity must not depend on the code's own sidelobes, and a
sweep over ``dtype`` must compare the same photons."""

from __future__ import annotations

import numpy as np
import pytest

import spslidar
from spslidar.codes import make_code
from spslidar.correlate import auto_replica, make_replica, window_response


def _window_by_hand(code, kind, half=1):
    """The filter's output at lags -half..half off a unit return, by a plain loop of shifted
    dot products (no FFT): sum_t s(t + k) f(t) / sum_t s(t) f(t)."""
    s = np.asarray(code, float)
    f = make_replica(s, kind)
    peak = float(s @ f)
    return sum(float(np.roll(s, -k) @ f) / peak for k in range(-half, half + 1))


@pytest.mark.parametrize("family,length,index", [("mseq", 1023, 0), ("gold", 1023, 2),
                                                 ("gold", 2047, 2), ("gold", 1023, 700)])
def test_the_window_response_is_the_codes_own_correlation(family, length, index):
    code = make_code(family, length, index=index)
    kind = auto_replica(code)
    assert window_response(code, kind) == pytest.approx(_window_by_hand(code, kind), abs=1e-12)


def test_the_window_response_of_known_codes():
    # an m-sequence's bipolar replica has no sidelobes: 1; the default Gold member at 1023
    # bits has 63 / 1023 of its peak at lags +-1, read as 0.0625 each through the replica
    assert window_response(make_code("mseq", 1023), "bipolar") == pytest.approx(1.0)
    assert window_response(make_code("gold", 1023, index=2), "bipolar") == pytest.approx(1.125)
    pulse = np.zeros(100, np.uint8)
    pulse[0] = 1
    assert window_response(pulse, "unipolar") == 1.0  # the conventional lidar
    # an m-sequence's unipolar replica: its plateau of 1/2 is taken away, nothing is left
    assert window_response(make_code("mseq", 1023), "unipolar") == pytest.approx(1.0)


@pytest.mark.parametrize("code", ["gold", "mseq"])
def test_a_noiseless_wall_reads_its_reflectivity_through_any_code(tmp_path, code):
    """A wall of reflectivity 1 read 1.125 through the default Gold member at 1023 bits and
    1.000 through an m-sequence; now 1 through both (noiseless, 100 % patterns: within 1 %,
    the regulariser's shrinkage measured at 0.01 %)."""
    np.savez(tmp_path / "wall.npz", depth=np.full((16, 16), 10.0),
             reflectivity=np.full((16, 16), 0.6))
    r = spslidar.run(scene=str(tmp_path / "wall.npz"), size=16, compression=1.0,
                     noiseless=True, range_gate=(9.5, 10.5), code=code, code_length=1023)
    assert np.median(r.reflectivity) == pytest.approx(0.6, rel=0.01)


def test_a_sweep_over_dtype_compares_the_same_photons(tmp_path):
    """float32 and float64 points drew other seeds, and a sweep's RMSE gap between them was
    noise (0.154 against 0.101 m); the measurement does not depend on dtype."""
    from spslidar.experiments.sweep import load_sweep_config
    from spslidar.experiments.sweep.command import _seeded, paired_keys

    toml = tmp_path / "s.toml"
    toml.write_text('seed = 1\n[base]\nsize = 16\n[grid]\ndtype = ["float32", "float64"]\n'
                    'noise = [1, 5]\n')
    points = load_sweep_config(toml).points()
    seeds = {(p["dtype"], p["noise"]): p["seed"]
             for p in _seeded(points, [{}] * len(points), paired_keys(), 1)}
    assert seeds["float32", 1] == seeds["float64", 1] != seeds["float32", 5]
    assert seeds["float32", 5] == seeds["float64", 5]
    single, double = (spslidar.measure(size=8, code_length=1023, seed=3, dtype=d)
                      for d in ("float32", "float64"))
    np.testing.assert_array_equal(single.sim["corr"], double.sim["corr"])


def test_the_summary_gives_the_patterns_share_it_ran():
    """``--compression 0.006`` at 16x16 ran 2 patterns and said 0.6 % (2 of 256 is 0.78 %),
    so a curve against the summary's share misplaced its small points."""
    from spslidar.patterns import pattern_share

    assert pattern_share(2, 16) == "0.781" and pattern_share(256, 32) == "25"
    r = spslidar.run(scene="steps", size=16, compression=0.006, patterns="hadamard",
                     code_length=1023)
    assert "2 hadamard patterns (0.781%)" in r.summary()
