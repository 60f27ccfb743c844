"""A hostile filesystem, as an outside audit of 2026-11-30 gave it: links that dangle or loop,
paths near PATH_MAX and umasks that forbid writing. Each was refused only after the work, in a
traceback, or had a user's link replaced; now each is one line before any work, or a result
written as the user's umask asks."""

from __future__ import annotations

import errno
import json
import os
import stat
import tempfile
from pathlib import Path

import pytest

from spslidar.cli import main
from spslidar.outdir import MARKER, umask_mode

R = ["--size", "16", "--code-length", "1023", "--no-figure"]


def _one_line(capsys, *needles):
    captured = capsys.readouterr()
    err = "\n".join(e for e in captured.err.strip().splitlines() if ": warning: " not in e)
    assert len(err.splitlines()) == 1 and ": error: " in err, captured.err
    for n in needles:
        assert n in err, err
    return captured


@pytest.fixture()
def no_work(monkeypatch):
    """``calibrate``'s work, made to fail the test if it starts: a refusal comes first."""
    def work(*args, **kwargs):
        raise AssertionError("the calibration started before the refusal")

    monkeypatch.setattr("spslidar.pipeline.calibration.calibrate_ptu", work)


def _cal_args(d: Path, out) -> list[str]:
    return ["calibrate", "--ptu", str(d / "a.ptu"), "--patterns", str(d / "a_patterns.npy"),
            "--code", str(d / "a_code.npy"), "--bit-rate", "10e9", "--distance", "5",
            "--out", str(out)]


def _rec_args(d: Path, out) -> list[str]:
    return ["reconstruct", "--ptu", str(d / "a.ptu"), "--patterns", str(d / "a_patterns.npy"),
            "--code", str(d / "a_code.npy"), "--bit-rate", "10e9", "--range-gate", "4", "6",
            "--no-figure", "--out", str(out)]


def _loop(tmp_path: Path) -> Path:
    (tmp_path / "loopA").symlink_to("loopB")
    (tmp_path / "loopB").symlink_to("loopA")
    return tmp_path / "loopA"


# -- 1: calibrate --out on a link ----------------------------------------------------------

@pytest.mark.parametrize("overwrite", [[], ["--overwrite"]])
def test_calibrate_keeps_a_dangling_or_looping_link(calibrated_wall, tmp_path, capsys,
                                                    no_work, overwrite):
    """``calibrate --out dang`` (``dang -> nowhere/deep``) wrote a file where the link was,
    and so did a link loop; both are refused in one line, the links left as they were."""
    (tmp_path / "dang").symlink_to("nowhere/deep")
    for link in (tmp_path / "dang", _loop(tmp_path)):
        target = os.readlink(link)
        assert main([*_cal_args(calibrated_wall, link), *overwrite]) == 2
        captured = _one_line(capsys, f"--out {link}", "symbolic link")
        assert "wrote" not in captured.out and "system delay" not in captured.out
        assert link.is_symlink() and os.readlink(link) == target
    assert sorted(p.name for p in tmp_path.iterdir()) == ["dang", "loopA", "loopB"]


def test_calibrate_does_not_replace_a_link_to_a_calibration(calibrated_wall, tmp_path,
                                                            capsys):
    """``ln -s cal.json ourlink.json; calibrate --out ourlink.json --overwrite`` turned the
    link into a file and left cal.json as it was; refused in one line now, as ``run
    --save-ptu`` refuses a link to a PTU it wrote under another name."""
    cal = tmp_path / "cal.json"
    assert main(_cal_args(calibrated_wall, cal)) == 0
    before = cal.read_bytes()
    link = tmp_path / "ourlink.json"
    link.symlink_to("cal.json")
    capsys.readouterr()
    for overwrite in ([], ["--overwrite"]):
        assert main([*_cal_args(calibrated_wall, link), *overwrite]) == 2
        _one_line(capsys, f"--out {link}", "symbolic link", "cal.json")
        assert link.is_symlink() and os.readlink(link) == "cal.json"
        assert cal.read_bytes() == before


@pytest.mark.parametrize("kind", ["loop", "dangling"])
def test_calibrate_into_a_link_that_leads_nowhere_is_refused_first(calibrated_wall, tmp_path,
                                                                   capsys, no_work, kind):
    """``--out loopA/cal.json`` (or through a dangling link) calibrated, then failed to make
    the folder; refused before the work now."""
    if kind == "loop":
        link = _loop(tmp_path)
    else:
        link = tmp_path / "dang"
        link.symlink_to("nowhere/deep")
    assert main(_cal_args(calibrated_wall, link / "cal.json")) == 2
    captured = _one_line(capsys, f"--out {link / 'cal.json'}")
    assert "system delay" not in captured.out
    assert not (tmp_path / "nowhere").exists()


# -- 2: --out through a symlink loop --------------------------------------------------------

@pytest.mark.parametrize("command", ["run", "reconstruct"])
def test_out_through_a_symlink_loop_is_refused_first(calibrated_wall, tmp_path, capsys,
                                                     command):
    """``--out loopA/sub`` ran the whole work, then ended in ``RuntimeError: Symlink loop``
    (exit 1)."""
    out = _loop(tmp_path) / "sub"
    argv = ["run", *R, "--out", str(out)] if command == "run" else _rec_args(calibrated_wall,
                                                                             out)
    assert main(argv) == 2
    captured = _one_line(capsys, f"--out {out}", "loop")
    assert "RMSE" not in captured.out and "wrote" not in captured.out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["loopA", "loopB"]


def _resolve_as_python_3_13(monkeypatch):
    """Python 3.13's non-strict ``Path.resolve``: a loop handed back unresolved, no error."""
    import pathlib

    real = pathlib.Path.resolve

    def resolve(self, strict=False):
        try:
            return real(self, strict=strict)
        except (RuntimeError, OSError) as exc:
            if strict or not (isinstance(exc, RuntimeError) or exc.errno == errno.ELOOP):
                raise
            return pathlib.Path(os.path.abspath(self))

    monkeypatch.setattr(pathlib.Path, "resolve", resolve)


@pytest.mark.parametrize("nested", [True, False])
def test_out_through_a_symlink_loop_is_refused_first_on_python_3_13(tmp_path, capsys,
                                                                    monkeypatch, nested):
    """From Python 3.13 a non-strict resolve does not raise on a loop: the run did its work
    and then failed on its temporary folder's name (a portability audit). The deepest part
    that exists is resolved strictly first, in every Python."""
    _resolve_as_python_3_13(monkeypatch)
    out = _loop(tmp_path) / "sub" if nested else _loop(tmp_path)
    assert main(["run", *R, "--out", str(out)]) == 2
    captured = _one_line(capsys, f"--out {out}", "loop")
    assert "RMSE" not in captured.out and "wrote" not in captured.out
    assert sorted(p.name for p in tmp_path.iterdir()) == ["loopA", "loopB"]


# -- 3: paths near PATH_MAX -----------------------------------------------------------------

def _path_max_here() -> int:
    try:
        return int(os.pathconf(tempfile.gettempdir(), "PC_PATH_MAX"))
    except (OSError, ValueError, AttributeError):
        return 0


#: the two tests below build paths of about 4 000 bytes: Linux's PATH_MAX (macOS's is 1 024)
_LINUX_PATHS = pytest.mark.skipif(_path_max_here() != 4096, reason="PATH_MAX is not 4096 here")


def _deep(tmp_path: Path, size: int) -> Path:
    """A folder whose absolute path is ``size`` bytes long (made)."""
    d = tmp_path
    while len(os.fsencode(d)) < size - 201:
        d = d / ("d" * 199)
    d = d / ("e" * (size - len(os.fsencode(d)) - 1))
    d.mkdir(parents=True)
    assert len(os.fsencode(d)) == size
    return d


@_LINUX_PATHS
def test_out_near_path_max_is_refused_first_and_the_limit_is_exact(tmp_path, capsys):
    """An ``--out`` of 4070 bytes ran, then failed naming
    ``.../.ooo....tmp-cqd0r6rx/reflectivity.npy`` (File name too long). Now one line before
    the work, saying how long the path may be; a path of that length is written."""
    parent = _deep(tmp_path, 3990)
    out = parent / ("o" * (4070 - 3991))
    assert main(["run", *R, "--out", str(out)]) == 2
    captured = _one_line(capsys, "--out", "bytes")
    assert "RMSE" not in captured.out
    err = captured.err
    most = int(err.split("of at most ")[1].split(" bytes")[0])
    assert 3991 < most < 4070
    assert [p.name for p in parent.iterdir()] == []
    fits = parent / ("o" * (most - 3991))
    assert main(["run", *R, "--out", str(fits)]) == 0
    assert (fits / "reflectivity.npy").is_file()
    capsys.readouterr()
    # replacing it puts the temporary folder inside it, one level deeper: refused first too
    before = {p.name: p.read_bytes() for p in fits.iterdir()}
    assert main(["run", *R, "--out", str(fits), "--overwrite"]) == 2
    _one_line(capsys, f"--out {fits}", "of at most")
    assert {p.name: p.read_bytes() for p in fits.iterdir()} == before
    # an existing folder: its temporary folder and the files in it are checked too
    folder = _deep(tmp_path / "x", 4060)
    assert main(["run", *R, "--out", str(folder)]) == 2
    _one_line(capsys, f"--out {folder}", "of at most")
    assert not any(folder.iterdir())


@_LINUX_PATHS
def test_calibrate_out_near_path_max_is_refused_first(calibrated_wall, tmp_path, capsys,
                                                     no_work):
    """Its temporary file (``.NAME.XXXXXXXX.tmp``) is the longer path: checked first."""
    parent = _deep(tmp_path, 4075)
    out = parent / "cal.json"
    assert main(_cal_args(calibrated_wall, out)) == 2
    captured = _one_line(capsys, f"--out {out}", "of at most")
    assert "system delay" not in captured.out
    assert not any(parent.iterdir())


# -- 4: the umask ---------------------------------------------------------------------------

@pytest.fixture()
def umask():
    old = os.umask(0o022)
    os.umask(old)
    yield os.umask
    os.umask(old)


def test_a_read_only_umask_gives_a_complete_read_only_result(tmp_path, capsys, umask,
                                                             monkeypatch):
    """Under umask 0222 the folder was made 0555 before its files were written into it: the
    run failed after the work (as non-root). The folder is writable while it is filled, and
    gets the umask's mode last."""
    from spslidar import outdir

    real = outdir.write_result_dir
    modes = []

    def spy(out, fill, *args, **kwargs):
        def watched(tmp):
            modes.append(stat.S_IMODE(os.stat(tmp).st_mode))
            fill(tmp)
        return real(out, watched, *args, **kwargs)

    monkeypatch.setattr("spslidar.pipeline.results.write_result_dir", spy)
    out = tmp_path / "ro"
    umask(0o222)
    try:
        assert main(["run", *R, "--out", str(out)]) == 0
        mode = umask_mode()
    finally:
        umask(0o022)
    assert modes and modes[0] & 0o700 == 0o700, oct(modes[0])  # writable while filled
    assert mode == 0o555 and stat.S_IMODE(out.stat().st_mode) == mode
    meta = json.loads((out / MARKER).read_text())
    assert set(meta["files"]) == {p.name for p in out.iterdir()} - {MARKER}
    assert "reflectivity.npy" in meta["files"]
    assert all(stat.S_IMODE(p.stat().st_mode) == 0o444 for p in out.iterdir())
    assert [p.name for p in tmp_path.iterdir()] == ["ro"]
    # replaced under the same umask: the old files are moved aside into a folder that must
    # be writable (mkdir's 0777 less the umask was 0555: as non-root, the moves failed)
    real_move, asides = outdir._move, []

    def move(src, dst):
        asides.append(stat.S_IMODE(os.stat(src.parent / outdir.ASIDE).st_mode))
        real_move(src, dst)

    monkeypatch.setattr(outdir, "_move", move)
    out.chmod(0o755)
    umask(0o222)
    try:
        assert main(["run", *R, "--out", str(out), "--overwrite"]) == 0
    finally:
        umask(0o022)
    assert asides and all(m & 0o700 == 0o700 for m in asides), [oct(m) for m in asides]
    assert all(stat.S_IMODE(p.stat().st_mode) == 0o444 for p in out.iterdir())
    assert [p.name for p in tmp_path.iterdir()] == ["ro"]
    assert not any(p.name.startswith(outdir.TMP_PREFIX) for p in out.iterdir())
    # missing folders on the way are made as mkdir -p makes them: writable by their owner
    # (0555 under this umask: as non-root, the next one could not be made in the first)
    deep = tmp_path / "p" / "q" / "r"
    umask(0o222)
    try:
        assert main(["run", *R, "--out", str(deep)]) == 0
    finally:
        umask(0o022)
    assert [stat.S_IMODE(p.stat().st_mode) for p in (deep.parent.parent, deep.parent,
                                                      deep)] == [0o755, 0o755, 0o555]
    assert (deep / "reflectivity.npy").is_file()


def test_umask_0777_leaves_no_temporary_folder(tmp_path, capsys, umask):
    """Umask 0777 left a hidden ``.NAME.tmp-*`` folder of mode 000 behind (as non-root);
    now the result is written, with the folder's mode (000) applied last."""
    out = tmp_path / "none"
    umask(0o777)
    try:
        rc = main(["run", *R, "--out", str(out)])
    finally:
        umask(0o022)
    try:
        assert rc == 0, capsys.readouterr().err
        assert [p.name for p in tmp_path.iterdir()] == ["none"]
        assert stat.S_IMODE(out.stat().st_mode) == 0
        if os.geteuid() == 0:  # (non-root cannot look inside a folder of mode 000)
            assert (out / MARKER).is_file() and (out / "reflectivity.npy").is_file()
    finally:
        out.chmod(0o755)
