"""One rule for every command that writes (issue 24, item 1): it never replaces or deletes a
file it did not write. Each command is run into a folder that already holds a user's files of
the names it writes; they must survive byte for byte, the command must exit 2 with one line,
and nothing may be left half-written. spslidar knows its own outputs by their marker
(``spslidar.outdir.MARKER``), not by their names."""

from __future__ import annotations

import errno
import json
from pathlib import Path

import numpy as np
import pytest

from spslidar.cli import main
from spslidar.outdir import MARKER

FAST = ["--size", "8", "--code-length", "127", "--no-figure"]


#: a metrics.json as a result of spslidar writes one (version and config): a folder holding it
#: looks like a result (spslidar 0.1.0 took it for one and replaced the files beside it)
LOOKALIKE = json.dumps({"version": "0.1.0", "config": {"size": 8}, "depth_rmse_m": 0.01})


def _user_files(folder: Path, names) -> dict[str, bytes]:
    folder.mkdir(parents=True, exist_ok=True)
    content = {}
    for name in names:
        text = LOOKALIKE if name == "metrics.json" else f"the user's own {name}"
        content[name] = f"{text}\n".encode()
        (folder / name).write_bytes(content[name])
    return content


def _survive(folder: Path, content: dict[str, bytes], capsys) -> None:
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1, err
    for name, data in content.items():
        assert (folder / name).read_bytes() == data, name
    assert not [p for p in folder.iterdir() if ".tmp" in p.name]


def _sweep_toml(tmp_path: Path) -> Path:
    cfg = tmp_path / "sweep.toml"
    cfg.write_text("seed = 1\n[base]\nsize = 8\ncode_length = 127\n[grid]\nnoise = [1, 10]\n")
    return cfg


@pytest.mark.parametrize("overwrite", [[], ["--overwrite"]])
def test_run_out(tmp_path, capsys, overwrite):
    """A folder that merely looks like a result (a metrics.json) is not one: even
    --overwrite leaves the user's depth.png and metrics.json."""
    out = tmp_path / "out"
    content = _user_files(out, ["depth.png", "metrics.json"])
    assert main(["run", *FAST, "--out", str(out), *overwrite]) == 2
    _survive(out, content, capsys)


@pytest.fixture(scope="module")
def acquisition(tmp_path_factory) -> Path:
    """A small PTU of a flat wall at 25 m and its two arrays, written by run --save-ptu."""
    d = tmp_path_factory.mktemp("acq")
    np.save(d / "wall.npy", np.full((8, 8), 25.0))
    assert main(["run", *FAST, "--scene", str(d / "wall.npy"), "--signal", "1", "--noise",
                 "0.01", "--save-ptu", str(d / "a.ptu"), "--out", str(d / "sim")]) == 0
    return d


@pytest.mark.parametrize("overwrite", [[], ["--overwrite"]])
def test_reconstruct_out(acquisition, tmp_path, capsys, overwrite):
    d = acquisition
    out = tmp_path / "rec"
    content = _user_files(out, ["depth.npy", "metrics.json", "points.ply", "depth.png"])
    gate = [str(v) for v in json.loads((d / "sim" / "metrics.json").read_text())["range_gate_m"]]
    capsys.readouterr()
    assert main(["reconstruct", "--ptu", str(d / "a.ptu"), "--patterns",
                 str(d / "a_patterns.npy"), "--code", str(d / "a_code.npy"),
                 "--bit-rate", "10e9", "--range-gate", *gate, "--truth",
                 str(d / "sim" / "truth.npy"), "--out", str(out), *overwrite]) == 2
    _survive(out, content, capsys)


@pytest.mark.parametrize("overwrite", [[], ["--overwrite"]])
def test_calibrate_out(acquisition, tmp_path, capsys, overwrite):
    """calibrate --out CAL.json replaces only a calibration spslidar wrote."""
    d = acquisition
    content = _user_files(tmp_path, ["cal.json"])
    capsys.readouterr()
    assert main(["calibrate", "--ptu", str(d / "a.ptu"), "--patterns",
                 str(d / "a_patterns.npy"), "--code", str(d / "a_code.npy"), "--bit-rate",
                 "10e9", "--distance", "25", "--out", str(tmp_path / "cal.json"),
                 *overwrite]) == 2
    _survive(tmp_path, content, capsys)


@pytest.mark.parametrize("overwrite", [[], ["--overwrite"]])
def test_save_ptu_companions(tmp_path, capsys, overwrite):
    """The user's x_patterns.npy and x_code.npy beside --save-ptu x.ptu survive, with or
    without --overwrite, and no result or PTU file is written."""
    content = _user_files(tmp_path, ["x_patterns.npy", "x_code.npy"])
    out = tmp_path / "r"
    assert main(["run", *FAST, "--signal", "1", "--noise", "0.01", "--save-ptu",
                 str(tmp_path / "x.ptu"), "--out", str(out), *overwrite]) == 2
    _survive(tmp_path, content, capsys)
    assert not (tmp_path / "x.ptu").exists() and not out.exists()


def test_save_ptu_replaces_its_own_files_only_with_overwrite(tmp_path, capsys):
    args = ["run", *FAST, "--signal", "1", "--noise", "0.01", "--save-ptu",
            str(tmp_path / "y.ptu")]
    assert main([*args, "--out", str(tmp_path / "r1")]) == 0
    first = (tmp_path / "y.ptu").read_bytes()
    assert main([*args, "--out", str(tmp_path / "r2")]) == 2  # exists: needs --overwrite
    assert main([*args, "--seed", "1", "--out", str(tmp_path / "r3"), "--overwrite"]) == 0
    assert (tmp_path / "y.ptu").read_bytes() != first  # ours, so replaced
    # a file of ours that the user changed since is theirs now
    (tmp_path / "y_code.npy").write_bytes(b"edited by the user")
    assert main([*args, "--out", str(tmp_path / "r4"), "--overwrite"]) == 2
    assert (tmp_path / "y_code.npy").read_bytes() == b"edited by the user"
    capsys.readouterr()


def _disk_full_after_the_header(fh, header, records):
    """The PTU writer's body on a disk that fills up after the header."""
    fh.write(header)
    fh.flush()
    raise OSError(errno.ENOSPC, "No space left on device")


def test_save_ptu_on_a_full_disk_leaves_nothing(tmp_path, monkeypatch, capsys):
    """A write that fails half-way (ENOSPC) leaves no partial PTU, no arrays, no result."""
    import spslidar.io.ptu_write as writer

    monkeypatch.setattr(writer, "_dump", _disk_full_after_the_header)
    out = tmp_path / "r"
    assert main(["run", *FAST, "--signal", "1", "--noise", "0.01", "--save-ptu",
                 str(tmp_path / "z.ptu"), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "No space left" in err[0], err
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_save_ptu_arrays_on_a_full_disk_leave_nothing(tmp_path, monkeypatch, capsys):
    """The disk fills up while the patterns are written, after the PTU: nothing is left."""
    real_save = np.save

    def save(file, arr, *a, **k):
        if np.asarray(arr).ndim == 3:  # the (M, N, N) patterns
            raise OSError(errno.ENOSPC, "No space left on device")
        return real_save(file, arr, *a, **k)

    monkeypatch.setattr(np, "save", save)
    assert main(["run", *FAST, "--signal", "1", "--noise", "0.01", "--save-ptu",
                 str(tmp_path / "z.ptu"), "--out", str(tmp_path / "r")]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == []


def test_ptu_writer_keeps_the_old_file_on_a_full_disk(tmp_path, monkeypatch):
    """The Python API: write_ptu_t3 onto an existing file that fails half-way leaves that
    file as it was, and no temporary file."""
    import spslidar.io.ptu_write as writer

    path = tmp_path / "x.ptu"
    kwargs = {"nsync": [0, 1, 2], "dtime": [3, 4, 5], "resolution_s": 1e-10,
              "sync_rate_hz": 1e6}
    assert writer.write_ptu_t3(path, **kwargs) == 3
    before = path.read_bytes()
    monkeypatch.setattr(writer, "_dump", _disk_full_after_the_header)
    with pytest.raises(OSError, match="No space left"):
        writer.write_ptu_t3(path, **{**kwargs, "dtime": [6, 7, 8]})
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["x.ptu"]


def test_sweep_out(tmp_path, capsys):
    out = tmp_path / "sw"
    content = _user_files(out, ["results.csv", "report.md"])
    assert main(["sweep", str(_sweep_toml(tmp_path)), "--out", str(out),
                 "--no-progress"]) == 2
    _survive(out, content, capsys)
    assert sorted(p.name for p in out.iterdir()) == ["report.md", "results.csv"]


def test_sweep_resumes_in_its_own_folder(tmp_path, capsys):
    out = tmp_path / "sw"
    cfg = str(_sweep_toml(tmp_path))
    assert main(["sweep", cfg, "--out", str(out), "--no-progress"]) == 0
    assert json.loads((out / MARKER).read_text())["kind"] == "sweep"
    first = (out / "results.csv").read_text()
    assert main(["sweep", cfg, "--out", str(out), "--no-progress"]) == 0  # resumes: cached
    assert (out / "results.csv").read_text() == first
    capsys.readouterr()


def test_sweep_of_an_older_version_is_refused_with_the_reason(tmp_path, capsys):
    """A sweep folder of spslidar 0.1.0 (no marker) is not known to be ours: refused in one
    line that says why, nothing in it changed."""
    out = tmp_path / "sw"
    cfg = str(_sweep_toml(tmp_path))
    assert main(["sweep", cfg, "--out", str(out), "--no-progress"]) == 0
    (out / MARKER).unlink()
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    capsys.readouterr()
    assert main(["sweep", cfg, "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "before 0.2.0" in err[0], err
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def test_reproduce_out(tmp_path, capsys):
    out = tmp_path / "rep"
    content = _user_files(out, ["report.md"])
    assert main(["reproduce", "snr", "--quick", "--out", str(out), "--no-progress"]) == 2
    _survive(out, content, capsys)
    assert sorted(p.name for p in out.iterdir()) == ["report.md"]


def test_a_sweep_folder_is_not_a_report_folder(tmp_path, capsys):
    out = tmp_path / "sw"
    assert main(["sweep", str(_sweep_toml(tmp_path)), "--out", str(out),
                 "--no-progress"]) == 0
    before = (out / "results.csv").read_bytes()
    assert main(["reproduce", "snr", "--quick", "--out", str(out), "--no-progress"]) == 2
    assert "spslidar sweep" in capsys.readouterr().err
    assert (out / "results.csv").read_bytes() == before


def test_result_marker_lists_what_was_written(tmp_path):
    out = tmp_path / "r"
    assert main(["run", *FAST, "--out", str(out)]) == 0
    meta = json.loads((out / MARKER).read_text())
    assert meta["kind"] == "result" and len(meta["id"]) == 32
    assert set(meta["files"]) == {p.name for p in out.iterdir()} - {MARKER}
    np.load(out / "depth.npy")  # the result itself is intact


def test_ptu_writer_on_a_real_failed_write(tmp_path):
    """The same with a write the operating system refuses (a file size limit of 4 kB, as a
    full disk would): the old file stays and no partial or temporary file is left."""
    import subprocess
    import sys

    pytest.importorskip("resource")  # POSIX only
    code = """
import os, resource, signal, sys
import numpy as np
from spslidar.io.ptu_write import write_ptu_t3
path, kw = sys.argv[1], {"resolution_s": 1e-10, "sync_rate_hz": 1e6}
signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
resource.setrlimit(resource.RLIMIT_FSIZE, (4096, resource.RLIM_INFINITY))
try:
    write_ptu_t3(path, nsync=np.arange(100000), dtime=np.zeros(100000, int), **kw)
except OSError:
    sys.exit(3)
"""
    from spslidar.io.ptu_write import write_ptu_t3

    path = tmp_path / "x.ptu"
    write_ptu_t3(path, nsync=[0, 1, 2], dtime=[3, 4, 5], resolution_s=1e-10, sync_rate_hz=1e6)
    before = path.read_bytes()
    assert subprocess.run([sys.executable, "-c", code, str(path)], timeout=60).returncode == 3
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["x.ptu"]


def test_overwrite_keeps_a_file_someone_edited_in_a_previous_result(tmp_path, capsys):
    """--overwrite replaced a depth.npy and an edited metrics.json a user had copied over a
    previous result's (an audit of 2026-11-28): the marker now keeps each file's SHA-256."""
    from spslidar.cli import main

    out = tmp_path / "r"
    args = ["run", "--size", "8", "--code-length", "63", "--no-figure", "--out", str(out)]
    assert main(args) == 0
    capsys.readouterr()
    np.save(out / "depth.npy", np.zeros((3, 3)))
    mine = (out / "depth.npy").read_bytes()
    assert main([*args, "--overwrite"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "depth.npy changed since spslidar wrote it" in err[0], err
    assert (out / "depth.npy").read_bytes() == mine
    (out / "depth.npy").unlink()  # moved away: the result is replaced
    assert main([*args, "--overwrite"]) == 0


@pytest.mark.parametrize("hashes", [True, False])
def test_overwrite_keeps_a_file_its_marker_lists_without_a_checksum(tmp_path, capsys, hashes):
    """A file the marker lists without a SHA-256 cannot be told from a user's: --overwrite
    deleted a user's notes.txt added to the list, and with the marker's hashes gone (an
    earlier version's, or one written by hand) any listed file (an outside audit of
    2026-12-03). Refused in one line, the file kept."""
    out = tmp_path / "r"
    args = ["run", "--size", "8", "--code-length", "63", "--no-figure", "--out", str(out)]
    assert main(args) == 0
    capsys.readouterr()
    (out / "notes.txt").write_text("mine")
    meta = json.loads((out / MARKER).read_text())
    meta["files"].append("notes.txt")
    if not hashes:
        del meta["sha256"]
    (out / MARKER).write_text(json.dumps(meta))
    assert main([*args, "--overwrite"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "notes.txt" in err[0] and "records no checksum" in err[0], err
    assert (out / "notes.txt").read_text() == "mine"
