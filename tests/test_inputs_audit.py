"""Inputs from a second sweep of every command by someone who did not write them
(2026-11-28): gates too narrow or too wide, files that collide, arrays of the wrong kind,
options the configuration ignores, calibration files edited by hand. Each is one line and
exit 2 with nothing written, or a one-line warning; never a traceback."""

from __future__ import annotations

import pytest

from spslidar.cli import main
from spslidar.constants import MAX_GATE_BINS
from spslidar.correlate import gate_lags
from spslidar.errors import ConfigError

FAST = ["--size", "8", "--code-length", "127", "--no-figure"]


def _one_line(capsys) -> str:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    return err[0]


@pytest.mark.parametrize("args,match", [
    (["--range-gate", "0", "1e9"], "beyond any lidar range"),
    (["--range-gate", "0", "1e7"], "beyond any lidar range"),
    (["--range-gate", "0", "1e6"], "delay bins"),
    (["--depth-min", "1e7", "--depth-max", "2e7"], "--depth-min must be in"),
    (["--depth-min", "2e6", "--depth-max", "2.0001e6"], "--depth-min must be in"),
])
def test_a_gate_or_window_beyond_any_range_is_refused_before_any_array(tmp_path, capsys,
                                                                       args, match):
    """A gate of 1e9 m asked for a 497 GiB array of lags before the memory check ran; a
    window at 2e6 m ran although a scene file there is refused."""
    out = tmp_path / "o"
    assert main(["run", *FAST, "--out", str(out), *args]) == 2
    assert match in _one_line(capsys)
    assert not out.exists()


def test_gate_lags_counts_before_it_allocates():
    bw = 1e-13  # the fastest bit rate allowed: 1e6 m is 6.7e10 bins
    with pytest.raises(ConfigError, match="delay bins"):
        gate_lags((0.0, 1e6), bw)
    bins = MAX_GATE_BINS * 1.001 * 299_792_458.0 * bw / 2  # just past the cap
    with pytest.raises(ConfigError, match="delay bins"):
        gate_lags((0.0, bins), bw)
    assert gate_lags((1.0, 2.0), 1e-10).size == 69  # bins 66 (floor of 66.7) to 134 (ceil)
