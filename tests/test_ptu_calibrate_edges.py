"""Edges of the PTU reader and of ``calibrate`` found by an audit (2026-11-28): a header's
record count other than the file's records, the sync-period mismatch's advice, PicoQuant's
legacy files, ``calibrate_ptu``'s arguments in Python, ``--distance`` past its limit, a
``--fov`` whose wall spreads over more than the code's period, and ``calibrate --out`` into a
folder that does not exist yet. The files are written here (the real recordings' versions of
these checks are in ``test_realdata.py``)."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
from _warn_filters import ours_as_errors

from spslidar.cli import main
from spslidar.errors import ConfigError, SpslidarError
from spslidar.io import ptu_info, read_ptu_histograms, write_acquisition_ptu

L = 63
BW = 250e-12  # 4 GHz


def _acquisition(path, n_patterns: int = 4):
    """A T3 file of ``n_patterns`` blocks of a few photons each; its record count."""
    rng = np.random.default_rng(3)
    events = [np.stack([rng.integers(0, 50, 20), rng.integers(0, L, 20)], axis=1)
              for _ in range(n_patterns)]
    return write_acquisition_ptu(path, events, L, BW, periods_per_pattern=50)


def _set_record_count(path, count: int, extra: bytes = b"") -> None:
    """The header's TTResult_NumberOfRecords set to ``count`` (its 8-byte value follows the
    tag's 40 bytes of identifier, index and type), and ``extra`` bytes appended."""
    data = bytearray(path.read_bytes())
    at = data.find(b"TTResult_NumberOfRecords")
    assert at > 0
    struct.pack_into("<q", data, at + 40, count)
    path.write_bytes(bytes(data) + extra)


# --- 1. the header's record count against the file's records ---------------------------------


def test_records_past_the_headers_count_are_said(tmp_path):
    """A header count of 10 in a file of more records: the records after the 10th were left
    out without a word (an audit's beads file read 491 of its 104 776 records). They are still
    left out, as ptufile and PicoQuant's readers leave them, but a warning names both counts."""
    path = tmp_path / "a.ptu"
    n = _acquisition(path)
    full = read_ptu_histograms(path, L, bin_width=BW)
    _set_record_count(path, 10)
    with pytest.warns(RuntimeWarning) as said:
        part = read_ptu_histograms(path, L, bin_width=BW)
    lines = [str(w.message) for w in said]
    assert len(lines) == 1 and "\n" not in lines[0]
    assert f"the header says 10 records (TTResult_NumberOfRecords) but the file holds {n} " \
           f"whole records" in lines[0]
    assert "only the first 10 are read" in lines[0]
    assert f"correct TTResult_NumberOfRecords to {n}" in lines[0]
    assert part.n_records == 10 < full.n_records == n
    assert part.histograms.sum() < full.histograms.sum()
    assert ptu_info(path)["n_records_in_file"] == n


def test_stray_bytes_after_the_headers_records_are_said(tmp_path):
    path = tmp_path / "a.ptu"
    n = _acquisition(path)
    _set_record_count(path, n, extra=b"\x01\x02")
    with pytest.warns(RuntimeWarning, match=f"holds {n} records and 2 stray bytes"):
        acq = read_ptu_histograms(path, L, bin_width=BW)
    assert acq.n_records == n


def test_a_header_count_of_zero_reads_the_whole_file_and_says_so(tmp_path):
    """An acquisition that did not finish leaves TTResult_NumberOfRecords at 0: every whole
    record is read, as ptufile reads it, with a warning; a part of a record at the end (the
    write cut short) is left out (it was refused, so nothing of such a file could be read)."""
    path = tmp_path / "a.ptu"
    n = _acquisition(path)
    full = read_ptu_histograms(path, L, bin_width=BW)
    _set_record_count(path, 0)
    with pytest.warns(RuntimeWarning, match=f"record count .* is 0.* all {n} whole records"):
        acq = read_ptu_histograms(path, L, bin_width=BW)
    np.testing.assert_array_equal(acq.histograms, full.histograms)
    _set_record_count(path, 0, extra=b"\x00\x00\x00")
    with pytest.warns(RuntimeWarning, match="the last 3 bytes, part of a record, are left out"):
        cut = read_ptu_histograms(path, L, bin_width=BW)
    assert cut.n_records == n
    np.testing.assert_array_equal(cut.histograms, full.histograms)


def test_a_header_count_that_matches_says_nothing(tmp_path):
    path = tmp_path / "a.ptu"
    _acquisition(path)
    with ours_as_errors():
        read_ptu_histograms(path, L, bin_width=BW)


# --- 2. the sync period's mismatch says which code fits ---------------------------------------


def test_a_sync_period_mismatch_names_the_code_length_that_fits(tmp_path):
    path = tmp_path / "a.ptu"
    _acquisition(path)
    with pytest.raises(ConfigError, match="sync period") as info:
        read_ptu_histograms(path, L - 1, bin_width=BW)
    assert "(+1 bins, tolerance 0.5); the file's sync period is 63.00 bins at 4 GHz: a " \
           "63-bit code fits it" in str(info.value)
    assert "\n" not in str(info.value)


def test_the_fitting_code_lengths_in_words():
    from spslidar.io.ptu_blocks import _fitting_codes

    assert _fitting_codes(1562.5, 16e-12, 0.5).endswith(
        "1562.50 bins at 62.5 GHz: a 1562- or 1563-bit code fits it (or check the bit rate)")
    assert "no whole number of bits fits it within 0.1 bins (the nearest, 1562, is +0.3" in \
        _fitting_codes(1562.3, 16e-12, 0.1)
    assert "codes of 1558 to 1567 bits fit it" in _fitting_codes(1562.3, 16e-12, 5)


# --- 3. PicoQuant's legacy files are named -----------------------------------------------------


@pytest.mark.parametrize("name, head, said, todo", [
    ("x.ht3", b"HydraHarp", "a legacy HydraHarp .ht3 file (PicoQuant's format before PTU)",
     "convert it to PTU"),
    ("x.pt3", b"PicoHarp 300", "a legacy PicoHarp 300 .pt3 file", "convert it to PTU"),
    ("x.dat", b"PicoHarp 300", "a legacy PicoHarp 300 .pt3/.pt2/.phd file", "convert it"),
    ("x.t3r", b"TimeHarp 200", "a legacy TimeHarp 200 .t3r file",
     "PTU has no TimeHarp 200 record type"),
    ("x.phu", b"PQHISTO\0", "a PicoQuant histogram file (.phu)", "record the lidar in T3"),
])
def test_legacy_picoquant_files_are_named(tmp_path, name, head, said, todo):
    """Refused as "not a readable PicoQuant PTU file (... magic=b'HydraHar')", which said
    neither what the file is nor what to do."""
    path = tmp_path / name
    path.write_bytes(head.ljust(16, b"\0") + b"2.0\0\0\0" + bytes(600))
    for read in (lambda: read_ptu_histograms(path, L), lambda: ptu_info(path)):
        with pytest.raises(ConfigError) as info:
            read()
        msg = str(info.value)
        assert said in msg and todo in msg and "\n" not in msg and "magic=" not in msg


# --- 4-7. calibrate ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def wall(tmp_path_factory):
    """A flat target at 25 m through a delayed instrument: 8x8, a 255-bit code at 10 GHz."""
    d = tmp_path_factory.mktemp("edges")
    np.save(d / "wall.npy", np.full((8, 8), 25.0))
    assert main(["run", "--scene", str(d / "wall.npy"), "--size", "8", "--code-length", "255",
                 "--noise", "0.02", "--compression", "0.5", "--range-gate", "24", "26",
                 "--no-figure", "--signal", "1", "--system-delay", "13.74e-9", "--irf",
                 "gaussian:150e-12,tail:400e-12,weight:0.3", "--save-ptu",
                 str(d / "wall.ptu"), "--out", str(d / "run")]) == 0
    return d


def _files(d) -> list[str]:
    return ["--ptu", str(d / "wall.ptu"), "--patterns", str(d / "wall_patterns.npy"),
            "--code", str(d / "wall_code.npy"), "--bit-rate", "10e9"]


@pytest.mark.parametrize("kwargs, match", [
    ({"distance": "25"}, "--distance must be a number of metres, got '25'"),
    ({"distance": True}, "--distance must be a number of metres"),
    ({"distance": [25.0]}, "--distance must be a number of metres"),
    ({"distance": 25.0, "pulse_width": float("nan")}, "pulse_width must be .* in \\(0, 1\\]"),
    ({"distance": 25.0, "pulse_width": "0.5"}, "pulse_width must be a number of bins"),
    ({"distance": 25.0, "pulse_width": 3.0}, "pulse_width must be .* got 3"),
    ({"distance": 25.0, "allow_binning": "no"}, "allow_binning must be True or False"),
])
def test_calibrate_ptu_refuses_bad_arguments_in_one_line(wall, kwargs, match):
    """In Python a distance given as text was a TypeError (np.isfinite on a str), a NaN
    pulse width a ValueError ('cannot convert float NaN to integer'), a pulse width of 3 bins
    and allow_binning='no' were taken."""
    from spslidar.pipeline.calibration import calibrate_ptu

    kwargs = dict(kwargs)
    distance = kwargs.pop("distance")
    with pytest.raises(ConfigError, match=match) as info:
        calibrate_ptu(wall / "wall.ptu", np.load(wall / "wall_patterns.npy"),
                      np.load(wall / "wall_code.npy"), 10e9, distance, **kwargs)
    assert "\n" not in str(info.value)


def test_calibrate_ptu_checks_its_arguments_before_the_file(tmp_path):
    """Refused before the file is read (here there is none)."""
    from spslidar.pipeline.calibration import calibrate_ptu

    rng = np.random.default_rng(0)
    pats, code = rng.integers(0, 2, (8, 16)), rng.integers(0, 2, 31)
    code[:2] = 0, 1
    for kwargs, match in (({}, "--distance"), ({"target": "range", "fov_deg": 10.0}, "--fov"),
                          ({"target": "sphere"}, "--target"),
                          ({"target": "plane", "fov_deg": 179.9}, "code's period of 31 bins")):
        distance = "far" if match == "--distance" else 25.0
        with pytest.raises(ConfigError, match=match):
            calibrate_ptu(tmp_path / "none.ptu", pats, code, 10e9, distance, **kwargs)


def test_a_distance_past_the_limit_says_the_range(wall, tmp_path, capsys):
    out = tmp_path / "c.json"
    assert main(["calibrate", *_files(wall), "--distance", "1e7", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["spslidar calibrate: error: --distance must be a distance in metres in "
                   "[0, 1e+06], got 1e+07"]
    assert not out.exists()


def test_a_field_of_view_wider_than_the_codes_period_is_refused(wall, tmp_path, capsys):
    """--fov 179.9 put the wall's corners 2e6 bins behind its centre in a 255-bin period, and
    the calibration was written without a word."""
    out = tmp_path / "c.json"
    assert main(["calibrate", *_files(wall), "--distance", "25", "--target", "plane",
                 "--fov", "179.9", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    assert "--fov 179.9 puts a flat wall at 25 m over" in err[0]
    assert "more than the code's period of 255 bins" in err[0]
    assert not out.exists()


def test_a_field_of_view_within_the_period_is_taken():
    """The bound is the period: 30 degrees at 25 m spreads an 8x8 wall over 80 bins of 255."""
    from spslidar.pipeline.target import measure_geometry

    rng = np.random.default_rng(0)
    phi = rng.integers(0, 2, (8, 64)).astype(float)
    code = rng.integers(0, 2, 255)
    geo = measure_geometry(np.ones((8, 255)), phi, code, 1e-10, 25.0, (8, 8), fov_deg=30.0)
    assert geo["model"] == "plane" and 50 < geo["spread_bins"] < 255
    with pytest.raises(ConfigError, match="more than the code's period of 255 bins"):
        measure_geometry(np.ones((8, 255)), phi, code, 1e-10, 25.0, (8, 8), fov_deg=60.0)


def test_calibrate_makes_the_missing_folders_of_out(wall, tmp_path, capsys):
    """'calibrate --out nodir/cal.json' was refused ("the folder nodir does not exist") where
    'reconstruct --out nodir/a/b' makes its folders."""
    out = tmp_path / "nodir" / "a" / "cal.json"
    assert main(["calibrate", *_files(wall), "--distance", "25", "--out", str(out)]) == 0
    assert json.loads(out.read_text())["kind"] == "spslidar-calibration"
    # the rules for a file that is there hold as before
    assert main(["calibrate", *_files(wall), "--distance", "25", "--out", str(out)]) == 2
    assert "exists; use --overwrite" in capsys.readouterr().err


def test_calibrate_makes_no_folder_when_it_fails(wall, tmp_path, capsys):
    out = tmp_path / "nodir" / "cal.json"
    assert main(["calibrate", *_files(wall), "--distance", "-1", "--out", str(out)]) == 2
    assert not (tmp_path / "nodir").exists()
    # a file in a folder's place is still refused
    (tmp_path / "file").write_text("mine")
    assert main(["calibrate", *_files(wall), "--distance", "25", "--out",
                 str(tmp_path / "file" / "sub" / "cal.json")]) == 2
    assert "is not a folder" in capsys.readouterr().err
    assert (tmp_path / "file").read_text() == "mine"


def test_a_failed_write_removes_the_folders_it_made(tmp_path, monkeypatch):
    import spslidar.outwrite as outdir
    from spslidar.pipeline.calibration_file import write_calibration

    def full(path, text):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(outdir, "atomic_write_text", full)
    (tmp_path / "kept").mkdir()
    with pytest.raises(SpslidarError, match="cannot write .*No space left on device"):
        write_calibration({"kind": "spslidar-calibration"}, tmp_path / "kept" / "a" / "b" /
                          "cal.json")
    assert list(tmp_path.iterdir()) == [tmp_path / "kept"]
    assert list((tmp_path / "kept").iterdir()) == []
