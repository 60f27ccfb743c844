"""Output folders under interrupts, other filesystems and races (the audit of the output
folders: an interrupted ``reproduce`` that could not resume, ``--out`` on another filesystem,
a user's ``results.csv`` replaced by ``sweep``, an interrupted ``run --overwrite``, a user's
file where ``--save-ptu`` puts its marker, an empty folder in a read-only parent)."""

from __future__ import annotations

import errno
import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest

from spslidar.cli import main
from spslidar.errors import SpslidarError
from spslidar.experiments import reproduce
from spslidar.experiments.reproduce import reproduce_main
from spslidar.experiments.reproduce import runner as reproduce_runner
from spslidar.experiments.sweep import engine as sweep_engine
from spslidar.outdir import MARKER, write_result_dir

#: spslidar.outdir.TMP_PREFIX (spelled out: the tests run against the code before it too)
TMP_PREFIX = ".spslidar-tmp-"

FAST = ["run", "--size", "16", "--code-length", "127", "--no-figure"]
#: few enough photons for --save-ptu
PTU = ["--signal", "0.5", "--noise", "0.01", "--save-ptu"]


def _run(out, *extra) -> int:
    return main([*FAST, "--out", str(out), *extra])


def _files(folder: Path) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


# --------------------------------------------------------------------------------------------
# 1. reproduce: interrupted between its files and its marker; figures all or nothing
# --------------------------------------------------------------------------------------------

_CALLS = {"n": 0}


def _exp_toy_files(ctx):
    """A toy experiment writing the standard CSV and PNG (different content on each call)."""
    from spslidar.experiments.report import Claim
    from spslidar.experiments.reproduce.context import write_rows
    from spslidar.experiments.reproduce.plotting import new_figure, save_figure

    _CALLS["n"] += 1
    name = ctx.current
    write_rows(ctx, name, [{"a": _CALLS["n"]}])
    fig = new_figure(1, 1)
    fig.add_subplot(1, 1, 1).plot([0, _CALLS["n"]])
    save_figure(ctx, name, fig, f"toy {_CALLS['n']}")
    return f"## {name}\n\n{ctx.mode}\n", [Claim(name, "toy", "p", "o", "consistent")]


def _exp_toy_a(ctx):
    ctx.current = "toya"
    return _exp_toy_files(ctx)


def _exp_toy_b(ctx):
    ctx.current = "toyb"
    return _exp_toy_files(ctx)


@pytest.fixture
def toys(monkeypatch):
    reg = reproduce.EXPERIMENT_REGISTRY
    monkeypatch.setattr(reg, "_entries", dict(reg._entries))  # restored after the test
    reg.add("toya", f"{__name__}:_exp_toy_a", "Toy A", "a toy", in_all=False)
    reg.add("toyb", f"{__name__}:_exp_toy_b", "Toy B", "a toy", in_all=False)


def test_reproduce_interrupted_after_its_files_resumes(tmp_path, toys, monkeypatch):
    """Ctrl-C after an experiment wrote its CSV and PNG but before the marker recorded them
    left files the next run refused as "not written by spslidar reproduce": every later
    experiment in the folder was blocked. Their SHA-256 is now in the marker before they are
    moved into place."""
    out = tmp_path / "r"
    assert reproduce_main("toya", out, quick=True, progress=False) == 0

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    with monkeypatch.context() as m:
        m.setattr(reproduce_runner, "write_section", interrupted)
        with pytest.raises(KeyboardInterrupt):
            reproduce_main("toyb", out, quick=True, progress=False)
    assert (out / "toyb" / "toyb.csv").is_file() and (out / "toyb" / "toyb.png").is_file()
    assert reproduce_main("toyb", out, quick=True, progress=False) == 0  # resumes
    meta = json.loads((out / MARKER).read_text())
    assert {"toyb/toyb.csv", "toyb/toyb.png"} <= set(meta["written"])
    assert "pending" not in meta
    # a user's edit of the file is still refused
    (out / "toyb" / "toyb.csv").write_text("mine\n")
    with pytest.raises(SpslidarError, match="toyb/toyb.csv was not written by spslidar"):
        reproduce_main("toyb", out, quick=True, progress=False)
    assert (out / "toyb" / "toyb.csv").read_text() == "mine\n"


def test_save_png_interrupted_leaves_no_partial_file(tmp_path):
    """fig.savefig wrote the PNG in place: Ctrl-C while it wrote left a truncated one."""
    from spslidar.experiments.reproduce.plotting import new_figure, save_png

    fig = new_figure(1, 1)

    def partial(fname, **kwargs):
        with open(fname, "wb") as fh:
            fh.write(b"\x89PNG\r\n\x1a\n truncated")
        raise KeyboardInterrupt

    fig.savefig = partial
    with pytest.raises(KeyboardInterrupt):
        save_png(fig, tmp_path / "f.png")
    assert list(tmp_path.iterdir()) == []
    fig = new_figure(1, 1)
    save_png(fig, tmp_path / "f.png")
    assert (tmp_path / "f.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert [p.name for p in tmp_path.iterdir()] == ["f.png"]


# --------------------------------------------------------------------------------------------
# 2 and 6. --out on another filesystem; an empty folder in a read-only parent
# --------------------------------------------------------------------------------------------


def test_out_linked_to_another_filesystem(tmp_path):
    """--out a link to a folder on another filesystem failed after all the work with
    "Invalid cross-device link: <temporary path>"."""
    if not os.path.isdir("/dev/shm"):
        pytest.skip("no /dev/shm")
    other = Path(tempfile.mkdtemp(dir="/dev/shm"))
    try:
        if os.stat(other).st_dev == os.stat(tmp_path).st_dev:
            pytest.skip("/dev/shm is on the same filesystem as tmp_path")
        link = tmp_path / "out"
        link.symlink_to(other, target_is_directory=True)
        assert _run(link) == 0
        assert (other / "depth.npy").is_file() and (other / MARKER).is_file()
        assert sorted(p.name for p in tmp_path.iterdir()) == ["out"]  # nothing left beside
        assert not [p for p in other.iterdir() if p.name.startswith(TMP_PREFIX)]
        assert _run(link, "--overwrite", "--seed", "1") == 0
    finally:
        shutil.rmtree(other, ignore_errors=True)


def test_cross_device_moves_fall_back_to_a_copy(tmp_path, monkeypatch, capsys):
    """A move the filesystem refuses as cross-device (EXDEV) is done by a copy under a
    temporary name moved into place: the run is not lost."""
    real = os.replace

    def replace(src, dst, *args, **kwargs):
        if Path(src).parent != Path(dst).parent:
            raise OSError(errno.EXDEV, "Invalid cross-device link", str(src))
        return real(src, dst, *args, **kwargs)

    out = tmp_path / "out"
    out.mkdir()
    monkeypatch.setattr(os, "replace", replace)
    assert _run(out) == 0, capsys.readouterr().err
    assert {"depth.npy", "metrics.json", MARKER} <= set(_files(out))
    assert sorted(p.name for p in out.iterdir() if p.name.startswith(".")) == [MARKER]


def test_empty_folder_in_a_read_only_parent(tmp_path, monkeypatch, capsys):
    """A writable empty --out inside a read-only folder was refused (the temporary folder
    went into the parent), though any new or empty folder is accepted. (Root writes
    everywhere, so the parent's refusal is simulated.)"""
    parent = tmp_path / "ro"
    out = parent / "out"
    out.mkdir(parents=True)

    def deny(real):
        def wrapper(*args, dir=None, **kwargs):
            if dir is not None and Path(dir) == parent:
                raise PermissionError(errno.EACCES, "Permission denied", str(dir))
            return real(*args, dir=dir, **kwargs)
        return wrapper

    for name in ("mkdtemp", "mkstemp", "TemporaryFile"):
        monkeypatch.setattr(tempfile, name, deny(getattr(tempfile, name)))
    assert _run(out) == 0, capsys.readouterr().err
    assert (out / "depth.npy").is_file()
    assert sorted(p.name for p in parent.iterdir()) == ["out"]


# --------------------------------------------------------------------------------------------
# 3 and 7. sweep: a user's results.csv; interrupted before any run
# --------------------------------------------------------------------------------------------


def _sweep_config(tmp_path) -> Path:
    config = tmp_path / "sweep.toml"
    config.write_text("seed = 1\n[base]\nsize = 16\ncode_length = 127\n"
                      "[grid]\nnoise = [1.0]\n")
    return config


def test_sweep_refuses_an_edited_results_csv(tmp_path, capsys):
    """sweep replaced a user's edited results.csv without a word (its marker kept no
    SHA-256)."""
    config, out = _sweep_config(tmp_path), tmp_path / "s"
    assert main(["sweep", str(config), "--out", str(out), "--no-progress"]) == 0
    assert main(["sweep", str(config), "--out", str(out), "--no-progress"]) == 0  # its own
    (out / "results.csv").write_text("my notes\n")
    capsys.readouterr()
    assert main(["sweep", str(config), "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "results.csv was not written by spslidar sweep" in err[0], err
    assert (out / "results.csv").read_text() == "my notes\n"


def test_sweep_interrupted_between_csv_and_marker_resumes(tmp_path, monkeypatch, capsys):
    """The CSV's SHA-256 is in the marker before the CSV is moved into place: an interrupt
    before the marker's final record does not make it a user's file."""
    from spslidar import outdir

    config, out = _sweep_config(tmp_path), tmp_path / "s"
    assert main(["sweep", str(config), "--out", str(out), "--no-progress"]) == 0
    (out / "results.csv").unlink()

    def interrupted(*args, **kwargs):
        raise KeyboardInterrupt

    with monkeypatch.context() as m:
        m.setattr(outdir, "record_outputs", interrupted)
        assert main(["sweep", str(config), "--out", str(out), "--no-progress"]) == 130
    assert (out / "results.csv").is_file()
    capsys.readouterr()
    assert main(["sweep", str(config), "--out", str(out), "--no-progress"]) == 0, \
        capsys.readouterr().err


def test_sweep_interrupted_before_any_run_leaves_no_folder(tmp_path, monkeypatch, capsys):
    """Ctrl-C before the first run finished left a folder of a marker and an empty runs/,
    with a line saying the finished runs were cached."""
    def interrupted(func, points, out_dir, **kwargs):
        (Path(out_dir) / "runs").mkdir(parents=True, exist_ok=True)
        raise KeyboardInterrupt

    monkeypatch.setattr(sweep_engine, "run_sweep", interrupted)
    config, out = _sweep_config(tmp_path), tmp_path / "s"
    assert main(["sweep", str(config), "--out", str(out), "--no-progress"]) == 130
    assert not out.exists()
    assert "nothing was written" in capsys.readouterr().err  # (was: "runs ... cached")
    empty = tmp_path / "empty"
    empty.mkdir()
    assert main(["sweep", str(config), "--out", str(empty), "--no-progress"]) == 130
    assert list(empty.iterdir()) == []  # the user's empty folder stays, empty
    assert "nothing was written" in capsys.readouterr().err
    # a folder of the user's files, interrupted before the sweep read it: not a cache (the
    # line said "the runs that finished are cached", an outside audit of 2026-12-03)
    from spslidar.experiments.sweep import command as sweep_command

    def checking(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(sweep_command, "_validate_run_points", checking)
    theirs = tmp_path / "theirs"
    theirs.mkdir()
    (theirs / "notes.txt").write_text("mine")
    assert main(["sweep", str(config), "--out", str(theirs), "--no-progress"]) == 130
    assert "nothing was written" in capsys.readouterr().err
    assert [p.name for p in theirs.iterdir()] == ["notes.txt"]


# --------------------------------------------------------------------------------------------
# 4. run --overwrite interrupted during its moves
# --------------------------------------------------------------------------------------------


def _interrupt_on_move(monkeypatch, out: Path, after: int) -> None:
    """Raise KeyboardInterrupt at the ``after``-th move of a file into ``out``."""
    real, seen = os.replace, {"n": 0}

    def replace(src, dst, *args, **kwargs):
        if Path(dst).parent == out and Path(dst).name != MARKER \
                and not Path(dst).name.startswith("."):
            seen["n"] += 1
            if seen["n"] == after:
                raise KeyboardInterrupt
        return real(src, dst, *args, **kwargs)

    monkeypatch.setattr(os, "replace", replace)


def test_overwrite_interrupted_during_the_moves_is_undone(tmp_path, monkeypatch, capsys):
    """Ctrl-C during run --overwrite's moves left a mix of both results, said "nothing was
    written", and the next --overwrite blamed the user ("confidence.npy changed since
    spslidar wrote it"). The moves are now undone: the line is true, the folder is the old
    result, and the next --overwrite works."""
    out = tmp_path / "r"
    assert _run(out) == 0
    before = _files(out)
    capsys.readouterr()
    with monkeypatch.context() as m:
        _interrupt_on_move(m, out, after=3)
        assert _run(out, "--overwrite", "--seed", "1") == 130
    err = [e for e in capsys.readouterr().err.splitlines() if "warning" not in e]
    assert err == ["spslidar run: interrupted; nothing was written"], err
    assert _files(out) == before
    assert sorted(p.name for p in out.iterdir()) == sorted(before)  # no temporary folder
    assert _run(out, "--overwrite", "--seed", "1") == 0, capsys.readouterr().err
    assert _files(out)["depth.npy"] != before["depth.npy"]


def test_overwrite_killed_during_the_moves_can_be_replaced(tmp_path, monkeypatch, capsys):
    """A replacement killed during its moves (no clean-up: power lost) leaves a mix the
    marker knows: files of the old or of the new result both count as spslidar's."""
    from spslidar import outdir

    out = tmp_path / "r"
    assert _run(out) == 0
    before = _files(out)
    with monkeypatch.context() as m:
        m.setattr(outdir, "_undo_swap", lambda *a, **k: None, raising=False)
        _interrupt_on_move(m, out, after=3)
        assert _run(out, "--overwrite", "--seed", "1") == 130
    for p in list(out.iterdir()):  # what a killed process leaves: the temporary folder too
        if p.name.startswith(TMP_PREFIX):
            shutil.rmtree(p)
    mixed = _files(out)
    assert mixed != before
    capsys.readouterr()
    assert _run(out, "--overwrite", "--seed", "2") == 0, capsys.readouterr().err
    (out / "confidence.npy").write_bytes(b"edited")  # a user's edit is still refused
    assert _run(out, "--overwrite") == 2
    assert (out / "confidence.npy").read_bytes() == b"edited"


# --------------------------------------------------------------------------------------------
# 5. --save-ptu's marker; 7. two runs racing on one new folder
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("overwrite", [False, True])
def test_save_ptu_never_replaces_a_users_file_named_as_its_marker(tmp_path, capsys, overwrite):
    """The hidden marker beside the PTU (.NAME.ptu.spslidar.json) replaced a user's file of
    that name without a word."""
    ptu = tmp_path / "scan.ptu"
    mine = tmp_path / ".scan.ptu.spslidar.json"
    mine.write_text("my own notes\n")
    args = [*PTU, str(ptu), *(["--overwrite"] if overwrite else [])]
    assert _run(tmp_path / "run", *args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a marker spslidar wrote" in err[0], err
    assert mine.read_text() == "my own notes\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == [mine.name]


def test_save_ptu_marker_of_spslidar_is_replaced(tmp_path):
    ptu = tmp_path / "scan.ptu"
    assert _run(tmp_path / "a", *PTU, str(ptu)) == 0
    first = ptu.read_bytes()
    assert _run(tmp_path / "b", *PTU, str(ptu), "--overwrite", "--seed", "1") == 0
    assert ptu.read_bytes() != first
    meta = json.loads((tmp_path / ".scan.ptu.spslidar.json").read_text())
    assert "previous_sha256" not in meta and set(meta["sha256"]) == {
        "scan.ptu", "scan_patterns.npy", "scan_code.npy"}


def test_race_on_a_new_folder_names_no_api_words(tmp_path):
    """Two runs on one new --out: the loser said "out_dir ...: pass overwrite=True"."""
    out = tmp_path / "new"

    def winner(tmp):
        np.save(tmp / "depth.npy", np.zeros(2))

    def loser(tmp):
        np.save(tmp / "depth.npy", np.ones(2))
        write_result_dir(out, winner)  # the other run finishes first

    with pytest.raises(SpslidarError) as info:
        write_result_dir(out, loser, option="out_dir", replace="overwrite=True")
    message = str(info.value)
    assert "overwrite=True" not in message and "out_dir" not in message
    assert "another command" in message
    assert np.load(out / "depth.npy").tolist() == [0.0, 0.0]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["new"]


def test_result_save_names_the_callers_words(tmp_path):
    """``Result.save`` refuses in the words of its caller: ``out_dir`` from Python, ``--out``
    from the command line (which passes them)."""
    import spslidar

    result = spslidar.run(size=8, code_length=255)
    (tmp_path / "mine.txt").write_text("a user's file")
    with pytest.raises(SpslidarError, match="out_dir"):
        result.save(tmp_path)
    with pytest.raises(SpslidarError, match="--out") as info:
        result.save(tmp_path, option="--out", replace="--overwrite")
    assert "out_dir" not in str(info.value)
    assert (tmp_path / "mine.txt").read_text() == "a user's file"
