"""Inputs other software writes, as an audit of 2026-11-29 fed them (spslidar's outputs read
by independent readers passed; these are the inputs that were taken without a word or ended
in a traceback)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from spslidar.cli import main

SMALL = ["--scene", "steps", "--size", "8", "--code-length", "1023", "--signal", "1",
         "--noise", "0.05", "--compression", "0.5", "--depth-min", "5", "--depth-max", "5.6",
         "--no-figure"]


@pytest.fixture(scope="module")
def acquisition(tmp_path_factory):
    d = tmp_path_factory.mktemp("acq")
    assert main(["run", *SMALL, "--save-ptu", str(d / "a.ptu"), "--out", str(d / "a")]) == 0
    return d


def _files(d, code=None):
    return ["--ptu", str(d / "a.ptu"), "--patterns", str(d / "a_patterns.npy"),
            "--code", str(code or d / "a_code.npy"), "--bit-rate", "10e9",
            "--range-gate", "4.5", "6.5", "--no-figure"]


def test_save_ptu_refuses_differential_hadamard(tmp_path, capsys):
    """Its +-1 rows went into the photon rates: a 22-line traceback, 'lam < 0'."""
    assert main(["run", *SMALL, "--patterns", "hadamard", "--hadamard-realisation",
                 "differential", "--save-ptu", str(tmp_path / "d.ptu"),
                 "--out", str(tmp_path / "d")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "--hadamard-realisation shifted" in err
    assert not any(tmp_path.iterdir())


def test_a_complemented_code_is_said(acquisition, tmp_path, capsys):
    """``1 - code`` (an active-low laser gate) gave RMSE 0.53 m against 0.005 m, exit 0,
    nothing said; the right code says nothing of it."""
    inverted = tmp_path / "inv.npy"
    np.save(inverted, 1 - np.load(acquisition / "a_code.npy"))
    truth = ["--truth", str(acquisition / "a" / "truth.npy")]
    for code, out, said in ((None, "ok", False), (inverted, "inv", True)):
        assert main(["reconstruct", *_files(acquisition, code), *truth,
                     "--out", str(tmp_path / out)]) == 0
        warned = json.loads((tmp_path / out / "metrics.json").read_text())["warnings"]
        assert any("is --code complemented" in w for w in warned) is said, warned
    capsys.readouterr()


def test_a_truth_in_millimetres_is_said(acquisition, tmp_path, capsys):
    mm = tmp_path / "mm.npy"
    np.save(mm, 1000 * np.load(acquisition / "a" / "truth.npy"))
    assert main(["reconstruct", *_files(acquisition), "--truth", str(mm),
                 "--out", str(tmp_path / "r")]) == 0
    err = capsys.readouterr().err
    assert "only 0 % of the --truth depths lie near the range gate 4.5-6.5 m" in err
    assert main(["reconstruct", *_files(acquisition), "--truth",
                 str(acquisition / "a" / "truth.npy"), "--out", str(tmp_path / "m")]) == 0
    assert "--truth depths lie near" not in capsys.readouterr().err


@pytest.mark.parametrize("which,said", [
    # (--patterns and --code read an .npz since stop 66, spslidar.io.lab_arrays: its arrays
    # are named, or its one vector read as the code's bits)
    ("--patterns", "holds no array that can be --patterns (it holds: a (3,))"),
    ("--code", "all 3 bits are 0"),
    ("--truth", "it is an .npz archive (np.savez); save the one array with np.save")])
def test_an_npz_where_an_npy_is_expected_is_named(acquisition, tmp_path, capsys, which, said):
    z = tmp_path / "x.npz"
    np.savez(z, a=np.zeros(3))
    argv = _files(acquisition)
    if which == "--truth":
        argv += ["--truth", str(z)]
    else:
        argv[argv.index(which) + 1] = str(z)
    assert main(["reconstruct", *argv, "--out", str(tmp_path / "r")]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    assert said in err
    assert not (tmp_path / "r").exists()


def _use(acquisition, cal, out):
    return main(["reconstruct", *_files(acquisition), "--calibration", str(cal),
                 "--out", str(out)])


def test_calibration_without_its_checksum_is_said(acquisition, calibrated_wall, tmp_path,
                                                  capsys):
    """With content_sha256 deleted, a lag_shift edited by one bin moved every depth 15 mm
    without a word."""
    cal = json.loads((calibrated_wall / "cal.json").read_text())
    del cal["content_sha256"]
    (tmp_path / "c.json").write_text(json.dumps(cal))
    assert _use(acquisition, tmp_path / "c.json", tmp_path / "r") == 0
    assert "has no checksum (content_sha256)" in capsys.readouterr().err
    assert _use(acquisition, calibrated_wall / "cal.json", tmp_path / "r2") == 0
    assert "no checksum" not in capsys.readouterr().err


def test_calibration_delay_bins_is_checked(acquisition, calibrated_wall, tmp_path,
                                           capsys):
    cal = json.loads((calibrated_wall / "cal.json").read_text())
    del cal["content_sha256"]
    cal["delay_bins"] = 500
    (tmp_path / "c.json").write_text(json.dumps(cal))
    assert _use(acquisition, tmp_path / "c.json", tmp_path / "r") == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "delay_bins 500 disagrees with delay_s" in err


def test_calibration_with_a_byte_order_mark_is_read(acquisition, calibrated_wall, tmp_path):
    """As a Windows editor saves it ('not JSON' before)."""
    (tmp_path / "c.json").write_bytes(b"\xef\xbb\xbf"
                                      + (calibrated_wall / "cal.json").read_bytes())
    assert _use(acquisition, tmp_path / "c.json", tmp_path / "r") == 0
    a = np.load(tmp_path / "r" / "depth.npy")
    assert _use(acquisition, calibrated_wall / "cal.json", tmp_path / "r2") == 0
    np.testing.assert_array_equal(a, np.load(tmp_path / "r2" / "depth.npy"))


def test_a_missing_record_count_is_said_missing(tmp_path):
    """A header without TTResult_NumberOfRecords was said to hold a count of 0."""
    import warnings

    from spslidar.io import read_ptu_histograms, write_acquisition_ptu

    rng = np.random.default_rng(0)
    events = [np.stack([rng.integers(0, 50, 20), rng.integers(0, 64, 20)], axis=1)
              for _ in range(3)]
    path = tmp_path / "a.ptu"
    write_acquisition_ptu(path, events, 64, 1e-10, periods_per_pattern=50)
    data = path.read_bytes()
    assert data.count(b"TTResult_NumberOfRecords") == 1
    path.write_bytes(data.replace(b"TTResult_NumberOfRecords", b"TTResult_NumberOfRecordz"))
    with warnings.catch_warnings(record=True) as said:
        warnings.simplefilter("always")
        acq = read_ptu_histograms(path, 64, bin_width=1e-10)
    lines = [str(w.message) for w in said if "NumberOfRecords" in str(w.message)]
    assert len(lines) == 1 and "(TTResult_NumberOfRecords) is missing" in lines[0], lines
    assert acq.histograms.sum() == 60


def test_differential_frames_of_half_a_period_are_said():
    """Half a code period per frame was simulated as a whole period at half the rate without
    a word (an outside physics audit); an even dwell says nothing."""
    import spslidar

    common = dict(size=8, code_length=127, patterns="hadamard", noise=1.0,
                  hadamard_realisation="differential", range_gate=(1.0, 1.8),
                  depth_min=1.2, depth_max=1.6)
    said = [w for w in spslidar.measure(**common).warnings if "two frames" in w]
    assert len(said) == 1 and "half of its 1 code period:" in said[0]
    assert "even --periods" in said[0]
    assert not [w for w in spslidar.measure(**common, periods=2).warnings if "two frames" in w]
