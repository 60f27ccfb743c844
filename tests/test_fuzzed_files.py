"""Files a user hands the commands, damaged the way a fuzzer damages them (an outside audit of
2026-11-30: 701 bounded CLI calls, 56 tracebacks from about 12 causes). Each is refused in
one line with exit status 2, before any output is written; none is a traceback, a hang or
an unbounded allocation."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from spslidar.cli import main
from spslidar.errors import ConfigError
from spslidar.io import read_ptu_histograms, write_acquisition_ptu

L, BW = 127, 1e-10


def _ptu(path, n_patterns=3):
    """A small HydraHarp T3 acquisition of ``n_patterns`` marker blocks (spslidar's writer)."""
    rng = np.random.default_rng(0)
    events = [np.stack([rng.integers(0, 50, 40), rng.integers(0, L, 40)], axis=1)
              for _ in range(n_patterns)]
    write_acquisition_ptu(path, events, L, BW, periods_per_pattern=50)
    return path


def _retag(path, ident: str, typ: int, raw8: bytes) -> None:
    """Give the header tag ``ident`` the type ``typ`` and the 8 bytes ``raw8``."""
    data = bytearray(path.read_bytes())
    at = data.find(ident.encode().ljust(32, b"\0"))
    assert at > 0
    data[at + 36:at + 48] = struct.pack("<I", typ) + raw8
    path.write_bytes(bytes(data))


def _one_line(capsys, status, *needles):
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2 and len(err) == 1 and "Traceback" not in err[0], err
    for needle in needles:
        assert needle in err[0], err
    return err[0]


@pytest.fixture
def inputs(tmp_path):
    rng = np.random.default_rng(0)
    np.save(tmp_path / "p.npy", rng.integers(0, 2, (3, 4, 4)).astype(np.uint8))
    np.save(tmp_path / "c.npy", rng.integers(0, 2, L).astype(np.uint8))
    return tmp_path


def _reconstruct(inputs, ptu, *extra):
    return main(["reconstruct", "--ptu", str(ptu), "--patterns", str(inputs / "p.npy"),
                 "--code", str(inputs / "c.npy"), "--bit-rate", "10e9", "--range-gate", "0.1",
                 "1.5", "--out", str(inputs / "out"), *extra])


@pytest.mark.parametrize("tag, typ, raw8, said", [
    # Measurement_Mode 0 beside T3 records: ptufile decoded them as T2 (a traceback)
    ("Measurement_Mode", 0x10000008, struct.pack("<q", 0), "Measurement_Mode 0"),
    ("Measurement_Mode", 0x10000008, struct.pack("<q", 99), "neither T2 (2) nor T3 (3)"),
    # numeric tags retyped: int() / float() of NaN, a string or inf
    ("TTResult_NumberOfRecords", 0x20000008, struct.pack("<d", float("nan")),
     "TTResult_NumberOfRecords must be a finite whole number"),
    ("MeasDesc_GlobalResolution", 0x20000008, struct.pack("<d", float("inf")),
     "MeasDesc_GlobalResolution must be a finite number"),
    ("MeasDesc_Resolution", 0x20000008, struct.pack("<d", float("nan")),
     "MeasDesc_Resolution must be a finite number"),
    # a dtime unit of 1e-300 s: 1e290 units a bin overflowed the binning
    ("MeasDesc_Resolution", 0x20000008, struct.pack("<d", 1e-300), "dtime field"),
])
def test_a_damaged_header_value_is_one_line(inputs, capsys, tag, typ, raw8, said):
    ptu = _ptu(inputs / "a.ptu")
    _retag(ptu, tag, typ, raw8)
    _one_line(capsys, _reconstruct(inputs, ptu, "--allow-binning"), said)
    assert not (inputs / "out").exists()


def test_an_absurd_sync_period_is_one_line(inputs, capsys):
    """A sync period of 1e299 s read as 1e309 bins: the mismatch's message ceiled infinity."""
    ptu = _ptu(inputs / "a.ptu")
    _retag(ptu, "MeasDesc_GlobalResolution", 0x20000008, struct.pack("<d", 1e299))
    line = _one_line(capsys, _reconstruct(inputs, ptu), "sync period")
    assert "check the header" in line


def test_a_header_tag_claiming_gigabytes_is_refused_before_it_is_read(tmp_path):
    """A comment tag claiming 3.5 GB in a sparse file of that size was read whole (3.4 GB)."""
    ptu = _ptu(tmp_path / "a.ptu")
    data = bytearray(ptu.read_bytes())
    at = data.find(b"File_Comment".ljust(32, b"\0"))
    assert at > 0
    big = 2**31
    struct.pack_into("<q", data, at + 40, big)
    with open(ptu, "wb") as fh:  # sparse: the data the tag claims, then nothing real
        fh.write(bytes(data))
        fh.truncate(len(data) + big)
    with pytest.raises(ConfigError, match="more than a header tag holds"):
        read_ptu_histograms(ptu, L, bin_width=BW)


def test_a_file_of_markers_alone_is_refused(inputs, capsys):
    """Markers and no photon: exit 0 with an all-NaN map before, and a word about
    --marker-edge; calibrate refused the same file."""
    ptu = inputs / "dark.ptu"
    write_acquisition_ptu(ptu, [np.zeros((0, 2), int)] * 3, L, BW, periods_per_pattern=50)
    _one_line(capsys, _reconstruct(inputs, ptu), "no photons on the channel")
    assert not (inputs / "out").exists()


def _raw_npy(path, header: str) -> None:
    """A .npy file whose header is ``header`` as written, followed by 64 zero bytes."""
    h = header.encode()
    h += b" " * (63 - (10 + len(h)) % 64) + b"\n"
    path.write_bytes(b"\x93NUMPY\x01\x00" + struct.pack("<H", len(h)) + h + b"\0" * 64)


@pytest.mark.parametrize("header, said", [
    ("{'descr': '<f8', 'fortran_order': False, 'shape': (-1, 4, 4), }", "corrupt .npy"),
    ("{{{{{{{{{{", "does not parse"),
])
@pytest.mark.parametrize("option", ["--patterns", "--code", "--truth"])
def test_a_corrupt_npy_header_is_one_line(inputs, capsys, header, said, option):
    _ptu(inputs / "a.ptu")
    _raw_npy(inputs / "bad.npy", header)
    args = {"--patterns": str(inputs / "p.npy"), "--code": str(inputs / "c.npy")}
    args[option] = str(inputs / "bad.npy")
    status = main(["reconstruct", "--ptu", str(inputs / "a.ptu"), "--bit-rate", "10e9",
                   "--range-gate", "0.1", "1.5", "--out", str(inputs / "out"),
                   *[x for kv in args.items() for x in kv]])
    _one_line(capsys, status, said)


@pytest.mark.parametrize("make", ["npz", "empty", "header"])
def test_an_irf_file_is_read_as_any_other_array(tmp_path, capsys, make):
    """--irf read with a bare np.load: an .npz renamed .npy or an empty file was a
    traceback."""
    irf = tmp_path / "irf.npy"
    if make == "npz":
        np.savez(tmp_path / "irf.npz", a=np.ones(3))
        (tmp_path / "irf.npz").rename(irf)
    elif make == "empty":
        irf.write_bytes(b"")
    else:
        _raw_npy(irf, "{{{{")
    status = main(["run", "--size", "8", "--code-length", "127", "--irf", str(irf),
                   "--out", str(tmp_path / "out")])
    _one_line(capsys, status, "--irf")
    assert not (tmp_path / "out").exists()


def test_a_deflated_scene_archive_is_refused_before_it_inflates(tmp_path, monkeypatch):
    """A 2.2 MB .npz of a deflated 14000x14000 depth took 3.4 GB before its refusal: the
    archive's declared sizes are read first (here the machine is said to have 10 MB)."""
    import spslidar.machine as machine
    from spslidar.errors import SceneError
    from spslidar.scenes.files import _load_npz

    np.savez_compressed(tmp_path / "bomb.npz", depth=np.full((1000, 1000), 5.0))
    assert (tmp_path / "bomb.npz").stat().st_size < 100_000
    monkeypatch.setattr(machine, "available_memory", lambda: 10e6)
    with pytest.raises(SceneError, match="inflate to"):
        _load_npz(tmp_path / "bomb.npz", "bomb.npz")


@pytest.mark.parametrize("where", ["config", "sweep"])
def test_toml_nested_too_deeply_is_one_line(tmp_path, capsys, where):
    deep = "[" * 5000 + "]" * 5000
    if where == "config":
        (tmp_path / "deep.toml").write_text(f"size = 16\nx = {deep}\n")
        status = main(["run", "--config", str(tmp_path / "deep.toml"),
                       "--out", str(tmp_path / "out")])
    else:
        (tmp_path / "deep.toml").write_text(f"[grid]\nnoise = {deep}\n")
        status = main(["sweep", str(tmp_path / "deep.toml"), "--out", str(tmp_path / "out")])
    _one_line(capsys, status, "nested too deeply")


@pytest.mark.parametrize("damage", ["deep", "huge", "fifo"])
def test_a_damaged_marker_is_a_users_file_not_a_hang_or_a_traceback(tmp_path, damage):
    """An output folder's marker nested 100 000 deep gave a RecursionError, a FIFO of its name
    hung the command, a 3 GB sparse one took 3.2 GB: each is read as no marker of
    spslidar's."""
    import os

    from spslidar.outwrite import MARKER, MAX_RECORD_BYTES, read_marker

    path = tmp_path / MARKER
    if damage == "deep":
        path.write_text('{"a":' * 100_000 + "1" + "}" * 100_000)
    elif damage == "huge":
        with open(path, "wb") as fh:
            fh.truncate(MAX_RECORD_BYTES + 1)
    else:
        os.mkfifo(path)
    assert read_marker(tmp_path) is None


def test_a_calibration_with_an_absurd_delay_is_refused(calibrated_wall, tmp_path):
    """lag_shift 10**30 with delay_s 1e20 (the checksum resealed) overflowed the lags."""
    import hashlib

    from spslidar.pipeline.calibration_file import load_calibration

    cal = json.loads((calibrated_wall / "cal.json").read_text(encoding="utf-8"))
    cal.update(lag_shift=10**30, delay_s=1e20, delay_bins=1e30, lag_fraction=0.0)
    body = {k: v for k, v in cal.items() if k != "content_sha256"}
    body["content_sha256"] = hashlib.sha256(
        json.dumps(body, sort_keys=True).encode()).hexdigest()
    (tmp_path / "cal.json").write_text(json.dumps(body), encoding="utf-8")
    code = np.load(calibrated_wall / "a_code.npy")
    with pytest.raises(ConfigError, match="beyond any instrument's system delay"):
        load_calibration(tmp_path / "cal.json", 10e9, code)


@pytest.mark.skipif(not __import__("os").path.exists("/proc/self/mem"),
                    reason="needs Linux's /proc/self/mem (a file whose reads fail)")
def test_a_ptu_that_cannot_be_read_is_named_not_the_output(inputs, capsys):
    """A read error on --ptu was said as "Input/output error: while writing --out"."""
    line = _one_line(capsys, _reconstruct(inputs, "/proc/self/mem"), "/proc/self/mem")
    assert "--out" not in line


def test_the_reproductions_cache_reads_runs_as_the_sweeps_does(tmp_path):
    """``reproduce`` read its cached runs with a bare json.loads: a file nested 100 000 deep
    was a RecursionError (a FIFO would have hung), where the sweep's reader now passes over
    them (a review)."""
    from types import SimpleNamespace

    from spslidar.experiments.reproduce.context import cached_runs

    runs = tmp_path / "runs"
    runs.mkdir()
    (runs / "a.json").write_text('{"a":' * 100_000 + "1" + "}" * 100_000)
    (runs / "b.json").write_text(json.dumps({"code": "x", "params": {"noise": 1},
                                             "result": {"rmse": 0.1}}))
    assert cached_runs(SimpleNamespace(cache=tmp_path, code="x")) == [{"noise": 1,
                                                                        "rmse": 0.1}]
