"""``--out`` never deletes what spslidar did not write (issue 15, item 1)."""

import json
import os
import stat
import tempfile
from pathlib import Path

import numpy as np
import pytest

from spslidar.cli import main
from spslidar.errors import SpslidarError
from spslidar.outdir import check_output, is_result, write_result_dir

FAST = ["run", "--size", "8", "--code-length", "127", "--no-figure"]


def _run(out, *extra):
    return main([*FAST, "--out", str(out), *extra])


def test_refuses_folder_with_user_files(tmp_path, capsys):
    # the reported case: --out "$PWD" in a folder holding notes and a sub-folder
    p = tmp_path / "p"
    (p / "keep").mkdir(parents=True)
    (p / "notes.md").write_text("x")
    (p / "keep" / "data.txt").write_text("y")
    assert _run(p) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a spslidar result" in err[0]
    assert (p / "notes.md").read_text() == "x"
    assert (p / "keep" / "data.txt").read_text() == "y"
    assert sorted(x.name for x in p.iterdir()) == ["keep", "notes.md"]
    assert [x.name for x in tmp_path.iterdir()] == ["p"]  # no temporary folder left


def test_out_dot_in_user_folder_is_refused(tmp_path, monkeypatch, capsys):
    (tmp_path / "mine.txt").write_text("z")
    monkeypatch.chdir(tmp_path)
    assert _run(".") == 2
    assert (tmp_path / "mine.txt").exists()
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_sibling_runs_survive(tmp_path):
    runs = tmp_path / "runs"
    assert _run(runs / "a") == 0
    before = (runs / "a" / "metrics.json").read_bytes()
    # --out runs (the parent of earlier runs) must not delete them
    assert _run(runs) == 2
    assert (runs / "a" / "metrics.json").read_bytes() == before


def test_previous_result_needs_overwrite(tmp_path, capsys):
    out = tmp_path / "r"
    assert _run(out) == 0
    assert is_result(out)
    first = (out / "metrics.json").read_bytes()
    assert _run(out, "--seed", "1") == 2
    assert "--overwrite" in capsys.readouterr().err
    assert (out / "metrics.json").read_bytes() == first
    assert _run(out, "--seed", "1", "--overwrite") == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["seed"] == 1


def test_overwrite_never_deletes_a_user_file_in_a_result(tmp_path):
    out = tmp_path / "r"
    assert _run(out) == 0
    (out / "my_notes.txt").write_text("keep me")
    assert not is_result(out)
    assert _run(out, "--overwrite") == 2
    assert (out / "my_notes.txt").read_text() == "keep me"


def test_empty_folder_and_cwd(tmp_path, monkeypatch):
    empty = tmp_path / "empty"
    empty.mkdir()
    assert _run(empty) == 0
    assert is_result(empty)
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    assert _run(".") == 0 and is_result(cwd)
    assert _run(".", "--overwrite") == 0 and is_result(cwd)


@pytest.mark.parametrize("out", ["", "   "])
def test_empty_out_is_one_line(out, capsys):
    assert main([*FAST, "--out", out]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


def test_out_is_a_file(tmp_path, capsys):
    f = tmp_path / "f.txt"
    f.write_text("mine")
    assert _run(f) == 2
    assert f.read_text() == "mine"


def test_permissions_follow_umask(tmp_path):
    old = os.umask(0o022)
    try:
        out = tmp_path / "r"
        assert _run(out) == 0
    finally:
        os.umask(old)
    assert stat.S_IMODE(out.stat().st_mode) == 0o755
    assert stat.S_IMODE((out / "depth.npy").stat().st_mode) == 0o644
    assert stat.S_IMODE((out / "metrics.json").stat().st_mode) == 0o644


def test_failed_fill_leaves_nothing(tmp_path):
    out = tmp_path / "r"

    def fill(tmp):
        np.save(tmp / "depth.npy", np.zeros(3))
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        write_result_dir(out, fill)
    assert list(tmp_path.iterdir()) == []


def test_interrupt_exits_130_with_one_line(tmp_path, monkeypatch, capsys):
    import spslidar.pipeline as pipeline

    def boom(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(pipeline, "run", boom)
    out = tmp_path / "r"
    assert _run(out) == 130
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "interrupted" in err[0]
    assert not out.exists()


def test_check_output_messages(tmp_path):
    (tmp_path / "x").write_text("")
    with pytest.raises(SpslidarError, match="not a spslidar result"):
        check_output(tmp_path)
    assert check_output(tmp_path / "new") == tmp_path / "new"


def test_result_of_an_older_version_is_not_replaced(tmp_path, capsys):
    """A result folder written before markers existed (0.1.0: no marker) is not known to be
    spslidar's: --overwrite refuses it in one line saying why, and nothing in it changes."""
    out = tmp_path / "r"
    assert _run(out) == 0
    (out / ".spslidar-output.json").unlink()
    before = {p.name: p.read_bytes() for p in out.iterdir()}
    capsys.readouterr()
    assert _run(out, "--seed", "1", "--overwrite") == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "before version 0.2.0" in err[0], err
    assert {p.name: p.read_bytes() for p in out.iterdir()} == before


def test_replaced_result_marker_lists_the_new_files(tmp_path):
    """Replacing a result: files the old marker listed and the new run did not write are
    removed, the new marker names exactly what is there, with a new id."""
    out = tmp_path / "r"
    assert _run(out) == 0
    first = json.loads((out / ".spslidar-output.json").read_text())
    (out / "confidence.npy").unlink()  # a file of ours the user removed: not an error
    assert _run(out, "--overwrite", "--seed", "2") == 0
    second = json.loads((out / ".spslidar-output.json").read_text())
    assert second["id"] != first["id"] and second["kind"] == "result"
    assert set(second["files"]) == {p.name for p in out.iterdir()} - {".spslidar-output.json"}


def _writer_meanwhile(folder, write):
    """A thread that holds the output's lock, as another command's swap does, writes into
    ``folder`` after a moment, then lets go; returns a fill that waits until it holds it."""
    import threading
    import time

    from spslidar.outlock import folder_lock

    holding = threading.Event()

    def other():
        with folder_lock(folder.parent):
            holding.set()
            time.sleep(0.3)
            write()

    thread = threading.Thread(target=other)

    def fill(tmp):
        (tmp / "depth.npy").write_bytes(b"x")
        thread.start()
        holding.wait(5)

    return fill, thread


def test_a_swap_waits_for_another_writers_and_checks_what_it_left(tmp_path):
    """Two runs into one folder interleaved between the last check and the swap (an outside
    audit of 2026-11-29: one run's files under the other's marker, refused as edited ever
    after). The second writer now waits for the first and finds its files: into a folder
    that was empty, it says another command wrote there; over a result it replaces it only
    with --overwrite, cleanly."""
    out = tmp_path / "out"
    out.mkdir()
    fill, thread = _writer_meanwhile(out, lambda: (out / "theirs.txt").write_text("x"))
    with pytest.raises(SpslidarError, match="another command wrote into this folder"):
        write_result_dir(out, fill)
    thread.join()
    assert sorted(p.name for p in out.iterdir()) == ["theirs.txt"]

    prev = tmp_path / "prev"
    write_result_dir(prev, lambda tmp: (tmp / "depth.npy").write_bytes(b"old"))

    def fill_while_another_replaces(tmp):
        (tmp / "depth.npy").write_bytes(b"x")
        write_result_dir(prev, lambda t: (t / "depth.npy").write_bytes(b"b"), overwrite=True)

    write_result_dir(prev, fill_while_another_replaces, overwrite=True)
    assert (prev / "depth.npy").read_bytes() == b"x" and is_result(prev)


def test_an_interrupt_as_the_files_marker_is_written_leaves_the_folder_as_it_was(tmp_path,
                                                                                 monkeypatch):
    """``--save-ptu``'s marker was written before the clean-up's reach: an interrupt just
    after it left a marker listing files that do not exist (an outside audit, 2026-11-29)."""
    from spslidar import outfiles

    def write(tmps):
        for t in tmps:
            t.write_bytes(b"x")

    real = outfiles.atomic_write_text

    def cut(path, text):
        real(path, text)
        raise KeyboardInterrupt

    monkeypatch.setattr(outfiles, "atomic_write_text", cut)
    with pytest.raises(KeyboardInterrupt):
        outfiles.write_files([tmp_path / "a.ptu"], write)
    assert list(tmp_path.iterdir()) == []


def test_a_name_too_long_for_its_temporary_name_is_refused_before_the_work(tmp_path, capsys):
    long = tmp_path / ("a" * 245)
    assert main(["run", "--size", "8", "--code-length", "127", "--out", str(long)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "at most 241 bytes" in err[-1]
    assert list(tmp_path.iterdir()) == []


def test_a_signal_while_the_plugins_load_is_one_line(tmp_path):
    """Before the command's own handlers (plugins, the parser) a signal was a traceback or
    an exit without a word (an outside audit of 2026-11-29)."""
    import subprocess
    import sys

    plug = tmp_path / "slow.py"
    plug.write_text("import os, signal\nos.kill(os.getpid(), signal.SIGINT)\n")
    done = subprocess.run([sys.executable, "-c", "import sys; from spslidar.cli import main; "
                           "sys.exit(main())", "--plugin", str(plug), "run", "--size", "8"],
                          capture_output=True, text=True, timeout=120, cwd=tmp_path)
    assert done.returncode == 130
    assert done.stderr.strip().splitlines() == ["spslidar: interrupted; nothing was written"]


def test_a_lock_held_on_the_outputs_folder_by_another_tool_does_not_hold_the_run(tmp_path):
    """``flock DIR spslidar run --out DIR/a`` (the way flock(1) serialises jobs) held the
    folder's own lock in the parent process, and the run waited for it forever after its work
    (an audit of 2026-11-30): spslidar locks a file of its own, named by the folder, in the
    temporary folder; nothing is written beside the output."""
    import threading

    from spslidar.outlock import lock_file

    fcntl = pytest.importorskip("fcntl")

    parent = tmp_path / "jobs"
    parent.mkdir()
    fd = os.open(parent, os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_EX)  # another tool's lock on the folder itself
    done = []
    try:
        t = threading.Thread(target=lambda: done.append(write_result_dir(
            parent / "a", lambda tmp: (tmp / "depth.npy").write_bytes(b"x"))), daemon=True)
        t.start()
        t.join(30)
    finally:
        os.close(fd)
    assert done, "the write waited for the folder's own lock"
    assert sorted(p.name for p in parent.iterdir()) == ["a"]
    lock = lock_file(parent)
    assert lock.parent.parent == Path(tempfile.gettempdir())
    assert not lock.exists()  # (removed by its holder: they piled up, a review of 2026-11-30)
    assert lock_file(str(parent) + "/") == lock  # one lock per folder, however it is written


def test_writers_that_queue_on_a_removed_lock_file_are_still_one_at_a_time(tmp_path):
    """The lock file goes when its holder lets go: four threads writing one folder's lock in
    turn never hold it together, and none is left behind (a review of 2026-11-30)."""
    import threading
    import time

    from spslidar.outlock import folder_lock, lock_file

    inside, most, lock = [0], [0], threading.Lock()

    def writer():
        for _ in range(20):
            with folder_lock(tmp_path) as held:
                assert held
                with lock:
                    inside[0] += 1
                    most[0] = max(most[0], inside[0])
                time.sleep(0.001)
                with lock:
                    inside[0] -= 1

    threads = [threading.Thread(target=writer) for _ in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(60)
    assert most[0] == 1
    assert not lock_file(tmp_path).exists()
