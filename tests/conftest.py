"""Fixtures several test modules share."""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.cli import main


@pytest.fixture(scope="session")
def calibrated_wall(tmp_path_factory):
    """A flat wall at 5 m (8x8, a 1023-bit code at 10 GHz) written by ``run --save-ptu`` as
    ``a.ptu`` with its ``a_patterns.npy`` and ``a_code.npy``, and its calibration
    ``cal.json``."""
    d = tmp_path_factory.mktemp("wall")
    np.save(d / "wall.npy", np.full((8, 8), 5.0))
    assert main(["run", "--scene", str(d / "wall.npy"), "--size", "8", "--code-length", "1023",
                 "--signal", "1", "--noise", "0.05", "--compression", "0.5", "--range-gate",
                 "4", "6", "--no-figure", "--save-ptu", str(d / "a.ptu"),
                 "--out", str(d / "w")]) == 0
    assert main(["calibrate", "--ptu", str(d / "a.ptu"), "--patterns",
                 str(d / "a_patterns.npy"), "--code", str(d / "a_code.npy"), "--bit-rate",
                 "10e9", "--distance", "5", "--out", str(d / "cal.json")]) == 0
    return d


@pytest.fixture
def plugin_state(monkeypatch, tmp_path_factory):
    """The plugins a test loads are left behind it: ``--plugin`` records the file in
    ``spslidar.plugins._LOADED``, puts its folder on ``sys.path`` and imports it (and its
    siblings) into ``sys.modules``, which later tests' code fingerprints and tracebacks read
    (two tests leaked them: an audit of the tests). Test files of plugins use it autouse."""
    import sys

    import spslidar.plugins as plugins

    monkeypatch.setattr(sys, "path", list(sys.path))
    loaded = dict(plugins._LOADED)
    before = set(sys.modules)
    yield
    plugins._LOADED.clear()
    plugins._LOADED.update(loaded)
    base = str(tmp_path_factory.getbasetemp())
    for name in set(sys.modules) - before:
        if (name.startswith("spslidar_plugin")
                or str(getattr(sys.modules[name], "__file__", "") or "").startswith(base)):
            del sys.modules[name]
