"""A real instrument (issue 20, items 2-3): a system delay and an IRF simulated by
``run --system-delay --irf``, measured by ``calibrate`` on a flat wall at 25 m, and removed by
``reconstruct --calibration`` without a ground truth."""

from __future__ import annotations

import json

import numpy as np
import pytest

from spslidar.cli import main
from spslidar.constants import SPEED_OF_LIGHT

DELAY = 13.74e-9  # s: 137.4 bins, 2.06 m
INSTRUMENT = ["--system-delay", str(DELAY), "--irf", "gaussian:150e-12,tail:400e-12,weight:0.3"]
COMMON = ["--size", "16", "--code-length", "1023", "--signal", "1", "--noise", "0.02",
          "--compression", "0.5", "--range-gate", "24", "30", "--no-figure"]


@pytest.fixture(scope="module")
def acquisitions(tmp_path_factory):
    d = tmp_path_factory.mktemp("cal")
    np.save(d / "wall.npy", np.full((16, 16), 25.0))
    scene = ["--scene", "steps", "--depth-min", "24.5", "--depth-max", "25.5"]
    assert main(["run", "--scene", str(d / "wall.npy"), *COMMON, *INSTRUMENT, "--save-ptu",
                 str(d / "wall.ptu"), "--out", str(d / "wallrun")]) == 0
    assert main(["run", *scene, *COMMON, *INSTRUMENT, "--save-ptu", str(d / "scene.ptu"),
                 "--out", str(d / "scenerun")]) == 0
    assert main(["calibrate", "--ptu", str(d / "wall.ptu"), "--patterns",
                 str(d / "wall_patterns.npy"), "--code", str(d / "wall_code.npy"),
                 "--bit-rate", "10e9", "--distance", "25", "--out", str(d / "cal.json")]) == 0
    return d


def _reconstruct(d, *extra, gate=("24", "26")):
    out = d / f"rec{len(list(d.glob('rec*')))}"
    assert main(["reconstruct", "--ptu", str(d / "scene.ptu"), "--patterns",
                 str(d / "scene_patterns.npy"), "--code", str(d / "scene_code.npy"),
                 "--bit-rate", "10e9", "--range-gate", *gate, "--out", str(out),
                 "--no-figure", *extra]) == 0
    err = np.load(out / "depth.npy") - np.load(d / "scenerun" / "truth.npy")
    return json.loads((out / "metrics.json").read_text()), err


def test_calibration_measures_the_delay_and_irf(acquisitions):
    cal = json.loads((acquisitions / "cal.json").read_text())
    # the delay to a fifth of a bin (3 mm): the IRF's tail moves its peak a little
    assert cal["delay_s"] == pytest.approx(DELAY, abs=0.2e-10)
    assert sum(cal["irf_values"]) == pytest.approx(1.0, rel=1e-9)
    assert 1 <= cal["irf_fwhm_bins"] <= 4  # 1.5 bins FWHM, sampled
    assert cal["measured_from"]["ptu"] == "wall.ptu" and len(cal["measured_from"]["sha256"]) == 64


def test_calibrated_reconstruction_removes_the_delay(acquisitions, capsys):
    """Without calibration the depths are 2.06 m off (outside a true-metre gate: garbage);
    with it the bias is gone (measured: 1.3 cm) and the median error within a bin (3.7 mm;
    an ideal instrument: 1.1 mm). Offset removed by hand, for comparison: RMSE 0.25 m against
    0.21 m calibrated (the IRF still blurs the slices the solver sees)."""
    m, err = _reconstruct(acquisitions, "--calibration", str(acquisitions / "cal.json"))
    assert m["calibration"]["lag_shift"] == 137 and m["depth_rmse_m"] is None
    assert abs(np.nanmean(err)) < 0.03
    assert np.nanmedian(np.abs(err)) <= 0.012
    off = DELAY * SPEED_OF_LIGHT / 2
    _, raw = _reconstruct(acquisitions, gate=(str(24 + off), str(26 + off)))
    assert np.nanmedian(raw) == pytest.approx(off, abs=0.05)  # the uncorrected offset
    capsys.readouterr()


@pytest.mark.parametrize("spec,match", [
    ("lorentz:1e-10", "gaussian:FWHM"),
    ("gaussian:abc", "must be a number"),
    ("gaussian:1e-3", "150 m"),
    ("gaussian:1e-10,tail:1e-10,weight:2", "weight"),
    ("missing.npy", "not found"),
])
def test_bad_irf_specs(spec, match, tmp_path, capsys):
    assert main(["run", "--size", "8", "--irf", spec, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and match in err[0], err


def test_calibrate_refuses(acquisitions, tmp_path, capsys):
    base = ["calibrate", "--ptu", str(acquisitions / "wall.ptu"), "--patterns",
            str(acquisitions / "wall_patterns.npy"), "--code", str(acquisitions / "wall_code.npy"),
            "--distance", "25"]
    # an existing file that is not a calibration is never replaced
    mine = tmp_path / "mine.json"
    mine.write_text("{}")
    assert main([*base, "--bit-rate", "10e9", "--out", str(mine), "--overwrite"]) == 2
    assert mine.read_text() == "{}"
    # a wrong bit rate: the file's resolution disagrees
    assert main([*base, "--bit-rate", "5e9", "--out", str(tmp_path / "c.json")]) == 2
    assert not (tmp_path / "c.json").exists()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2


def test_irf_kernel_is_normalised_and_centred():
    from spslidar.instrument import irf_kernel, parse_irf

    offsets, values = irf_kernel(parse_irf("gaussian:150e-12,tail:400e-12,weight:0.3"),
                                 1e-10, 1023)
    assert values.sum() == pytest.approx(1.0, rel=1e-12)
    mean = float(np.dot(offsets + 0.5, values))  # a photon uniform in its bin: +0.5
    # ex-Gaussian mean: 0.3 * 4 bins of tail (the Gaussian is centred)
    assert mean == pytest.approx(0.5 + 0.3 * 4.0, abs=0.05)


def test_calibrate_refuses_a_users_file_before_the_work(tmp_path, monkeypatch, capsys):
    """--out X --overwrite over a file that is not a calibration: refused before the PTU is
    read (it was refused only after the whole calibration had run)."""
    import spslidar.pipeline.calibration as calibration

    def never(*a, **k):
        raise AssertionError("the calibration ran before the output was checked")

    monkeypatch.setattr(calibration, "calibrate_ptu", never)
    mine = tmp_path / "mine.json"
    mine.write_text('{"not": "a calibration"}')
    assert main(["calibrate", "--ptu", str(tmp_path / "none.ptu"), "--patterns", "p.npy",
                 "--code", "mseq", "--code-length", "127", "--bit-rate", "10e9",
                 "--distance", "25", "--out", str(mine), "--overwrite"]) == 2
    assert "not a spslidar calibration" in capsys.readouterr().err
    assert mine.read_text() == '{"not": "a calibration"}'
