"""End to end: noiseless recovery, PSST vs conventional, range aliasing, reproducibility."""

import json

import numpy as np
import pytest

from spslidar import pipeline
from spslidar.config import Config
from spslidar.constants import SPEED_OF_LIGHT

BIN = SPEED_OF_LIGHT * 1e-10 / 2  # 1.5 cm


@pytest.mark.parametrize("qcr", [False, True])
def test_noiseless_full_sampling_recovers_every_pixel_within_one_bin(qcr):
    r = pipeline.run(scene="steps", size=16, compression=1.0, code_length=1023, noiseless=True,
                     qcr=qcr, iterations=300)
    err = np.abs(r.depth - r.truth)
    assert np.all(np.isfinite(r.depth))
    assert err.max() <= BIN, f"max error {err.max():.4f} m"


def test_noiseless_subbin_beats_bin_quantisation():
    kw = dict(scene="ramp", size=16, compression=1.0, code_length=1023, noiseless=True,
              qcr=False, iterations=300)
    plain = pipeline.run(**kw)
    sub = pipeline.run(**kw, subbin=True)
    assert sub.depth_rmse < plain.depth_rmse


def test_psst_with_qcr_beats_conventional_at_mn10():
    kw = dict(size=32, code_length=4095, noise=10.0, seed=1)
    psst = pipeline.run(**kw, lidar="psst", qcr=True)
    conv = pipeline.run(**kw, lidar="conventional", qcr=True)
    assert psst.depth_rmse < 0.5 * conv.depth_rmse
    # same acquisition time per pattern
    assert conv.metrics["acquisition_time_per_pattern_s"] <= \
        psst.metrics["acquisition_time_per_pattern_s"]


def test_conventional_10mhz_aliases_a_20m_scene_psst_does_not():
    kw = dict(scene="camera", size=16, range_gate=(1.0, 30.0), noise=1.0, seed=2)
    conv = pipeline.run(**kw, lidar="conventional", rep_rate=10e6)
    assert conv.metrics["unambiguous_range_m"] == pytest.approx(14.99, abs=0.01)
    assert any("unambiguous range" in w for w in conv.warnings)
    shift = np.nanmedian(conv.depth - conv.truth)
    assert shift == pytest.approx(-conv.metrics["unambiguous_range_m"], abs=0.05)
    psst = pipeline.run(**kw, lidar="psst", code_length=16383)
    assert abs(np.nanmedian(psst.depth - psst.truth)) < 0.05
    assert not any("unambiguous range" in w for w in psst.warnings)


def test_seeded_runs_are_reproducible():
    kw = dict(size=16, code_length=1023)
    a, b = pipeline.run(**kw, seed=5), pipeline.run(**kw, seed=5)
    c = pipeline.run(**kw, seed=6)
    np.testing.assert_array_equal(a.depth, b.depth)
    assert not np.array_equal(a.corr, c.corr)


def test_all_solvers_run_through_the_pipeline():
    rmse = {}
    for solver in ("fista", "twist", "tval3", "gpsr"):
        r = pipeline.run(size=32, code_length=4095, solver=solver)
        assert r.metrics["solver_info"]["solver"] == solver
        rmse[solver] = r.depth_rmse
    best = min(rmse.values())
    assert max(rmse.values()) < 4 * best + 0.01, rmse


def test_save_is_atomic(tmp_path, monkeypatch):
    r = pipeline.run(size=16, code_length=1023)
    out = r.save(tmp_path / "res")
    assert sorted(p.name for p in out.iterdir()) == [
        "depth.npy", "depth.png", "metrics.json", "truth.npy"]
    m = json.loads((out / "metrics.json").read_text())
    assert m["depth_rmse_m"] == pytest.approx(r.depth_rmse)
    assert {"total", "simulate", "solve"} <= set(m["timing_s"])
    assert m["config"]["code_length"] == 1023 and m["seed"] == 0 and m["version"]

    import spslidar.figures

    def boom(*a, **k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(spslidar.figures, "depth_figure", boom)
    with pytest.raises(RuntimeError):
        r.save(tmp_path / "half")
    assert not (tmp_path / "half").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["res"]


def test_run_accepts_config_objects_and_dicts():
    cfg = Config(size=16, code_length=1023)
    a = pipeline.run(cfg)
    b = pipeline.run({"size": 16, "code-length": 1023})
    np.testing.assert_array_equal(a.depth, b.depth)
    m = pipeline.run_metrics({"size": 16, "code_length": 1023})
    assert m["depth_rmse_m"] == pytest.approx(a.depth_rmse)
