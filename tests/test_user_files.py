"""One rule for every command that writes (issue 24, item 1): it never replaces or deletes a
file it did not write. Each command is run into a folder that already holds a user's files of
the names it writes; they must survive byte for byte, the command must exit 2 with one line,
and nothing may be left half-written. spslidar knows its own outputs by their marker
(``spslidar.outdir.MARKER``), not by their names."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from spslidar.cli import main
from spslidar.outdir import MARKER

FAST = ["--size", "8", "--code-length", "127", "--no-figure"]


def _user_files(folder: Path, names) -> dict[str, bytes]:
    folder.mkdir(parents=True, exist_ok=True)
    content = {}
    for name in names:
        content[name] = f"the user's own {name}\n".encode()
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


def test_reconstruct_out(tmp_path, capsys):
    pytest.importorskip("ptufile")
    sim = tmp_path / "sim"
    assert main(["run", *FAST, "--signal", "1", "--noise", "0.01", "--save-ptu",
                 str(tmp_path / "a.ptu"), "--out", str(sim)]) == 0
    out = tmp_path / "rec"
    content = _user_files(out, ["depth.npy", "metrics.json", "points.ply"])
    gate = [str(v) for v in json.loads((sim / "metrics.json").read_text())["range_gate_m"]]
    assert main(["reconstruct", "--ptu", str(tmp_path / "a.ptu"), "--patterns",
                 str(tmp_path / "a_patterns.npy"), "--code", str(tmp_path / "a_code.npy"),
                 "--bit-rate", "10e9", "--range-gate", *gate, "--out", str(out),
                 "--overwrite"]) == 2
    _survive(out, content, capsys)


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


def test_save_ptu_on_a_full_disk_leaves_nothing(tmp_path, monkeypatch, capsys):
    """A write that fails half-way (ENOSPC) leaves no partial PTU, no arrays, no result."""
    import errno

    import spslidar.io.ptu_write as writer

    def full(*a, **k):
        with open(a[0], "wb") as fh:
            fh.write(b"PQTTTR\0\0partial")
        raise OSError(errno.ENOSPC, "No space left on device", str(a[0]))

    monkeypatch.setattr(writer, "write_ptu_t3", full)
    out = tmp_path / "r"
    assert main(["run", *FAST, "--signal", "1", "--noise", "0.01", "--save-ptu",
                 str(tmp_path / "z.ptu"), "--out", str(out)]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1
    assert sorted(p.name for p in tmp_path.iterdir()) == []


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
