"""A hostile but realistic user's inputs, as an outside audit of 2026-11-29 gave them: each
ended in a traceback, left files behind after a refusal, hung, or replaced a result without a
word. Bad input is one line and exit 2, before any work."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import numpy as np
import pytest

from spslidar.cli import main
from spslidar.errors import ConfigError, SpslidarError

B = ["--size", "8", "--code-length", "127", "--no-figure"]


def _one_line(capsys, *needles):
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1, err
    for n in needles:
        assert n in err, err
    return err


def test_out_named_as_the_ptu_marker_is_refused_before_any_work(tmp_path, capsys, monkeypatch):
    """``--out .q.ptu.spslidar.json --save-ptu q.ptu`` wrote the PTU, its arrays and its marker
    (where --out pointed), then refused the folder, leaving them all."""
    monkeypatch.chdir(tmp_path)
    assert main(["run", *B, "--out", ".q.ptu.spslidar.json", "--save-ptu", "q.ptu"]) == 2
    _one_line(capsys, "would be the --out folder")
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("name", [".", "..", "/"])
def test_save_ptu_naming_a_folder_is_one_line(tmp_path, capsys, name):
    assert main(["run", *B, "--out", str(tmp_path / "o"), "--save-ptu", name]) == 2
    _one_line(capsys, "--save-ptu must name a file")
    assert not (tmp_path / "o").exists()


def test_patterns_without_contrast_are_one_line(tmp_path, capsys):
    """``--pattern-sigma 1e-10``: float32 patterns that are all 0.5, a zero operator, and a
    Lipschitz ValueError out of the solver."""
    assert main(["run", *B, "--pattern-sigma", "1e-10", "--out", str(tmp_path / "o")]) == 2
    _one_line(capsys, "nothing to reconstruct", "--pattern-sigma 1e-10")
    assert not (tmp_path / "o").exists()


def test_a_vanishing_rep_rate_is_one_line(tmp_path, capsys):
    """``--rep-rate 1e-300``: an OverflowError out of int(inf), and in a sweep's pre-check a
    traceback that ended the whole sweep."""
    assert main(["run", *B, "--lidar", "conventional", "--rep-rate", "1e-300",
                 "--out", str(tmp_path / "o")]) == 2
    _one_line(capsys, "--rep-rate 1e-300 Hz", "exceeds the acquisition time")
    toml = tmp_path / "s.toml"
    toml.write_text('[base]\nsize = 8\ncode_length = 127\nlidar = "conventional"\n'
                    '[grid]\nrep_rate = [1e-300, 1e8]\n')
    assert main(["sweep", str(toml), "--out", str(tmp_path / "s"), "--no-progress"]) == 2
    _one_line(capsys, "--rep-rate 1e-300 Hz")


def test_a_sweep_of_another_grid_does_not_replace_the_first_ones_table(tmp_path, capsys):
    a, b = tmp_path / "a.toml", tmp_path / "b.toml"
    head = "seed = 1\n[base]\nsize = 8\ncode_length = 127\n[grid]\n"
    a.write_text(head + "noise = [1, 5]\n")
    b.write_text(head + "noise = [1, 5, 10]\n")
    out = tmp_path / "S"
    run = ["--out", str(out), "--no-progress"]
    assert main(["sweep", str(a), *run]) == 0
    first = (out / "results.csv").read_bytes()
    assert main(["sweep", str(a), *run]) == 0  # the same sweep resumes
    capsys.readouterr()
    assert main(["sweep", str(b), *run]) == 2
    _one_line(capsys, "holds the results.csv of another sweep", "--overwrite")
    assert (out / "results.csv").read_bytes() == first
    assert main(["sweep", str(b), *run, "--overwrite"]) == 0
    assert len((out / "results.csv").read_text().splitlines()) == 4


def _env_main(argv, **env):
    code = "import sys\nfrom spslidar.cli import main\nraise SystemExit(main(sys.argv[1:]))\n"
    return subprocess.run([sys.executable, "-c", code, *argv], capture_output=True, text=True,
                          env={**os.environ, **env}, timeout=120)


def test_a_plugin_of_the_environment_that_fails_is_one_line():
    """``SPSLIDAR_PLUGINS=nosuch spslidar --help`` was a 10-line traceback out of ``import
    spslidar``; in Python an unknown stage now says which plugin failed."""
    proc = _env_main(["run", "--help"], SPSLIDAR_PLUGINS="nosuch_plugin_here")
    assert proc.returncode == 2
    assert proc.stderr.strip() == ("spslidar: error: plugin nosuch_plugin_here failed to "
                                   "import: ModuleNotFoundError: No module named "
                                   "'nosuch_plugin_here'")
    code = ("import spslidar\ntry:\n    spslidar.Config(code='legendre')\n"
            "except Exception as e:\n    print(e)\n")
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env={**os.environ, "SPSLIDAR_PLUGINS": "nosuch_plugin_here"},
                          timeout=120)
    assert "unknown code 'legendre'" in proc.stdout
    assert "plugin nosuch_plugin_here failed to import" in proc.stdout


def test_a_damaged_reproduce_map_is_run_again(tmp_path, capsys):
    """A depth map cut short in the cache was a traceback on this and every later run."""
    from spslidar.experiments.reproduce import reproduce_main

    assert reproduce_main("fig2", tmp_path, quick=True, progress=False) == 0
    maps = sorted((tmp_path / "cache" / "maps").glob("*.npy"))
    with open(maps[0], "r+b") as fh:
        fh.truncate(100)
    assert reproduce_main("fig2", tmp_path, quick=True, progress=False) == 0
    assert np.load(maps[0]).ndim == 2
    capsys.readouterr()


def test_config_streams_and_devices(tmp_path, capsys):
    """A config from bash's ``<(...)`` (a pipe) was "not found"; ``/dev/zero`` ran out of
    memory."""
    from spslidar.config import read_toml
    from spslidar.experiments.sweep import load_sweep_config

    r, w = os.pipe()
    os.write(w, b"noise = 3\n")
    os.close(w)
    try:
        assert read_toml(f"/dev/fd/{r}")["noise"] == 3
    finally:
        os.close(r)
    if os.path.exists("/dev/zero"):
        with pytest.raises(ConfigError, match="holds more than 16 MiB: not a TOML config"):
            read_toml("/dev/zero")
        with pytest.raises(ConfigError, match="sweep config /dev/zero holds more than"):
            load_sweep_config("/dev/zero")


def test_patterns_given_a_folder_is_said(tmp_path):
    from spslidar.pipeline.real import load_patterns

    # (a folder is read as one image per pattern since stop 66: this one holds none)
    with pytest.raises(ConfigError, match="is a folder with no image in it"):
        load_patterns(tmp_path)


# -- calibration files edited by hand ----------------------------------------------------------
def _edited(calibrated_wall, tmp_path, **change):
    cal = json.loads((calibrated_wall / "cal.json").read_text())
    cal.pop("content_sha256")
    cal.update(change)
    path = tmp_path / "c.json"
    path.write_text(json.dumps(cal))
    return path


@pytest.mark.parametrize("change,why", [
    ({"irf_offsets": [-10**20, 0]}, "incomplete or damaged (OverflowError"),
    ({"delay_s": 1e300}, "beyond any instrument"),
])
def test_calibration_numbers_past_any_range_are_refused(calibrated_wall, tmp_path, change, why):
    """An offset of 21 digits was an OverflowError traceback; a delay of 1e300 s overflowed
    to inf and passed the consistency check (exit 0, metrics.json said 1e+300)."""
    from spslidar.pipeline.calibration_file import load_calibration

    code = np.load(calibrated_wall / "a_code.npy")
    with pytest.raises(ConfigError, match=why.replace("(", r"\(")):
        load_calibration(_edited(calibrated_wall, tmp_path, **change), 10e9, code)


def test_a_lag_shift_periods_away_from_its_delay_is_named(calibrated_wall, tmp_path):
    """A lag_shift ten code periods off its delay agrees with it modulo the period; it is
    refused, and said as such (not as 'disagree with delay_s ... by 0 bins': a review)."""
    from spslidar.pipeline.calibration_file import load_calibration

    cal = json.loads((calibrated_wall / "cal.json").read_text())
    code = np.load(calibrated_wall / "a_code.npy")
    path = _edited(calibrated_wall, tmp_path, lag_shift=cal["lag_shift"] + 10 * code.size)
    with pytest.raises(ConfigError, match="more than two code periods from delay_s"):
        load_calibration(path, 10e9, code)


def test_calibration_files_that_are_no_files(calibrated_wall, tmp_path):
    """A deeply nested JSON file was a RecursionError, ``/dev/zero`` a MemoryError, and a FIFO
    as ``calibrate --out F --overwrite`` hung the command."""
    from spslidar.pipeline.calibration_file import check_calibration_out, load_calibration

    code = np.load(calibrated_wall / "a_code.npy")
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(ConfigError, match="is not a calibration file"):
        load_calibration(deep, 10e9, code)
    with pytest.raises(SpslidarError, match="is not a spslidar calibration"):
        check_calibration_out(deep, overwrite=True)
    if os.path.exists("/dev/zero"):
        with pytest.raises(ConfigError, match="not a regular file"):
            load_calibration("/dev/zero", 10e9, code)
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    with pytest.raises(SpslidarError, match="is not a spslidar calibration"):
        check_calibration_out(fifo, overwrite=True)


# -- messages: one line, naming what the user gave ---------------------------------------------
def test_a_signal_below_float32s_reach_is_one_line(tmp_path, capsys):
    """``--signal 1e-20`` leaked NumPy's overflow warnings and ran; ``1e-300`` leaked four and
    blamed the weight."""
    for signal in ("1e-20", "1e-300"):
        assert main(["run", *B, "--signal", signal, "--out", str(tmp_path / "o")]) == 2
        _one_line(capsys, f"--signal {signal} photons per pulse is too small",
                  "raise --signal")
    assert main(["run", *B, "--signal", "1e-12", "--out", str(tmp_path / "o")]) == 0
    assert "overflow" not in capsys.readouterr().err


def test_a_huge_pattern_sigma_leaks_no_overflow(tmp_path, capsys):
    from spslidar.patterns.dense import make_patterns

    phi = make_patterns("gaussian", 64, 64, np.random.default_rng(0), sigma=1e308)
    assert set(np.unique(phi).tolist()) <= {0.0, 1.0}
    assert main(["run", *B, "--pattern-sigma", "1e308", "--out", str(tmp_path / "o")]) == 0
    assert "overflow" not in capsys.readouterr().err


def test_max_memory_with_a_unit_in_a_toml(tmp_path, capsys):
    """``max_memory = "500MB"`` was "must be a number" where the command line takes units."""
    from spslidar.config import Config

    assert Config(max_memory="500MB").max_memory == pytest.approx(0.5)
    assert Config(max_memory="1.5GiB").max_memory == pytest.approx(1.5 * 2**30 / 1e9)
    with pytest.raises(ConfigError, match="not a memory size: '2XB'"):
        Config(max_memory="2XB")
    with pytest.raises(SystemExit) as exc:
        main(["run", *B, "--max-memory", "2XB", "--out", str(tmp_path / "o")])
    assert exc.value.code == 2
    _one_line(capsys, "argument --max-memory: not a memory size: '2XB'")


def test_a_damaged_tif_scene_is_one_line(tmp_path, capsys):
    """A TIFF of a header and garbage logged tifffile's "invalid offset" and was then "got
    shape (0,)"."""
    bad = tmp_path / "bad.tif"
    bad.write_bytes(b"II*\x00garbage")
    assert main(["run", *B, "--scene", str(bad), "--out", str(tmp_path / "o")]) == 2
    _one_line(capsys, "cannot read scene image bad.tif")


def test_a_plugin_replacing_a_builtin_is_said_in_one_line(tmp_path, capsys, monkeypatch):
    import spslidar.plugins as plugins
    from spslidar.depth import ESTIMATORS

    entry = ESTIMATORS.get("argmax")
    rep = tmp_path / "rep_argmax.py"
    rep.write_text("from spslidar.depth import ESTIMATORS\n"
                   "from spslidar.depth.argmax import ArgmaxDepth\n"
                   "ESTIMATORS.add('argmax', ArgmaxDepth, 'argmax', 'mine')\n")
    monkeypatch.setenv(plugins.ENV, "")
    try:
        with pytest.raises(SystemExit):
            main(["--plugin", str(rep), "run", "--help"])
    finally:
        ESTIMATORS._entries["argmax"] = entry
        plugins._LOADED.clear()
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("spslidar --plugin: warning: the depth "
                                               "estimator 'argmax'"), err


@pytest.mark.parametrize("argv,prog", [
    (["reproduce", "snr", "fig2", "--out", "r"], "spslidar reproduce"),
    (["snr", "--bogus"], "spslidar snr"),
    (["--bogus"], "spslidar")])
def test_an_unrecognised_argument_is_said_by_its_command(argv, prog, capsys):
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    _one_line(capsys, f"{prog}: error: unrecognized arguments", f"(see {prog} --help)")


def test_snr_is_not_told_to_lower_periods(capsys):
    assert main(["snr", "--method", "histogram", "--signal", "1e7"]) == 2
    err = _one_line(capsys, "lower --signal or --noise")
    assert "--periods" not in err


def test_a_calibration_target_at_the_lidar_fits_no_wall():
    """``calibrate --distance 1e-300`` said "the field of view must lie in (0, 180) degrees,
    got 180.0", of an option never given."""
    from spslidar.pipeline.target import MAX_FIT_FOV, _fov_of_spread

    assert _fov_of_spread(1.0, 0.0, 8) == 180.0 >= MAX_FIT_FOV
    assert 0 < _fov_of_spread(1.0, 1e6, 8) < MAX_FIT_FOV


def test_a_calibration_with_a_byte_order_mark_can_be_replaced(calibrated_wall, tmp_path):
    """Read with a byte-order mark by ``--calibration``, it was "not a spslidar calibration"
    to ``calibrate --overwrite``, which read it without."""
    from spslidar.pipeline.calibration_file import check_calibration_out

    bom = tmp_path / "bom.json"
    bom.write_bytes(b"\xef\xbb\xbf" + (calibrated_wall / "cal.json").read_bytes())
    assert check_calibration_out(bom, overwrite=True) == bom


def test_running_out_of_memory_is_one_line(tmp_path, capsys, monkeypatch):
    """An allocation past what the machine had free was NumPy's traceback and exit 1 (an
    audit of memory limits: --save-ptu, the GMAPD, a 0-150 m gate under `ulimit -v`)."""
    import spslidar.cli as cli

    def starved(args):
        raise MemoryError("Unable to allocate 14.2 MiB for an array with shape (57, 32766) "
                          "and data type float64")

    monkeypatch.setitem(cli.COMMANDS, "run", starved)
    assert main(["run", *B, "--out", str(tmp_path / "o")]) == 2
    _one_line(capsys, "spslidar run: error: out of memory (Unable to allocate 14.2 MiB",
              "--max-memory")
    assert not (tmp_path / "o").exists()


def test_save_ptu_refuses_a_bright_acquisition_before_the_solve(tmp_path, capsys, monkeypatch):
    """The photon cap of --save-ptu was checked once the solve and the depth stage were done
    (34 s into a 128x128 run, an audit): now once the acquisition is simulated."""
    import spslidar.pipeline as pipeline

    def no_solve(*a, **k):
        raise AssertionError("reconstructed before the photon cap was checked")

    monkeypatch.setattr(pipeline, "reconstruct", no_solve)
    ptu = tmp_path / "bright.ptu"
    assert main(["run", *B, "--noise", "1000", "--save-ptu", str(ptu),
                 "--out", str(tmp_path / "o")]) == 2
    _one_line(capsys, "--save-ptu writes photon by photon", "exceed 2e+07")
    assert not ptu.exists() and not (tmp_path / "o").exists()


def test_save_ptu_of_a_gmapd_advises_a_shorter_dwell(monkeypatch):
    """A GMAPD's flux per dead time is its operating point: the refusal told it to lower
    --signal / --noise, which took it out of the 1-10 photons per dead time where it works
    (an outside audit of stop 68); it says --periods."""
    from types import SimpleNamespace

    from spslidar.errors import ConfigError
    from spslidar.pipeline.export import check_ptu_photons

    def meas(detector, periods=10**6):
        return SimpleNamespace(
            acq=SimpleNamespace(period=1023, n_periods=periods),
            sim={"noise_per_bin": np.full(4, 0.01), "signal_counts": np.full(4, 1e7)},
            config=SimpleNamespace(detector=detector))

    with pytest.raises(ConfigError, match=r"lower --periods \(the dwell: a GMAPD keeps its "):
        check_ptu_photons(meas("gmapd"))
    # (the photons reaching it, which it draws one by one, not the file's detections: an
    # outside audit of 2026-12-03 read them as the file's)
    with pytest.raises(ConfigError, match=r"expected photons reaching the detector \(each "
                                          r"drawn, though its dead time records fewer\)"):
        check_ptu_photons(meas("gmapd"))
    with pytest.raises(ConfigError, match=r"lower --periods, or --signal / --noise$"):
        check_ptu_photons(meas("linear"))
    # at one period (the default) there is no dwell to shorten: a shorter code or fewer
    # patterns (the real-data page's advice was refused as "lower --periods", an audit of
    # the docs of 2026-12-01)
    with pytest.raises(ConfigError, match=r"; use a shorter --code-length or fewer patterns "
                                          r"\(--compression, --size\) \(a GMAPD"):
        check_ptu_photons(meas("gmapd", 1))
    with pytest.raises(ConfigError, match=r"; lower --signal / --noise, or use a shorter "
                                          r"--code-length or fewer patterns"):
        check_ptu_photons(meas("linear", 1))


def test_a_librarys_notice_of_its_future_is_not_the_runs_warning(tmp_path, capsys,
                                                                   monkeypatch):
    """A library's deprecation or FutureWarning raised during a run (as a newer release may
    add) is neither a line of the command's nor a warning in metrics.json (a test plugin
    making scikit-image warn so failed 7 tests counting the lines, an audit of
    2026-11-29); a library's RuntimeWarning still is both."""
    import json
    import warnings

    import spslidar.pipeline.chain as sim

    here = sim.simulate_correlations

    def noisy(*a, **k):
        # raised as if from a library's file (warn_explicit names the file)
        warnings.warn_explicit("argument x is deprecated", FutureWarning,
                               "/site-packages/lib/mod.py", 10)
        warnings.warn_explicit("argument y will go", DeprecationWarning,
                               "/site-packages/lib/mod.py", 11)
        warnings.warn_explicit("overflow in a library", RuntimeWarning,
                               "/site-packages/lib/mod.py", 12)
        # as libraries raise their notices, naming their caller's line (spslidar's own
        # file: it was taken for spslidar's warning, a review)
        warnings.warn("argument z is deprecated", FutureWarning, stacklevel=2)
        return here(*a, **k)

    monkeypatch.setattr(sim, "simulate_correlations", noisy)
    out = tmp_path / "o"
    assert main(["run", "--size", "8", "--code-length", "127", "--no-figure",
                 "--out", str(out)]) == 0
    err = capsys.readouterr().err
    kept = json.loads((out / "metrics.json").read_text())["warnings"]
    assert "deprecated" not in err and "will go" not in err
    assert not any("deprecated" in w or "will go" in w for w in kept)
    assert "overflow in a library (RuntimeWarning in mod.py:12)" in err
    assert any("overflow in a library" in w for w in kept)


def _cli_process(args, tmp_path, shell_tail="", env=None):
    """The CLI as its own process (the streams are real descriptors), with ``shell_tail``
    (redirections, a pipe) after it; returns (status of the spslidar process, stderr)."""
    import os
    import shlex
    import subprocess
    import sys

    cmd = " ".join(shlex.quote(a) for a in [sys.executable, "-m", "spslidar", *args])
    script = f"{cmd} {shell_tail}; echo \"status=${{PIPESTATUS[0]}}\" >&3"
    proc = subprocess.run(["bash", "-c", f"exec 3>{shlex.quote(str(tmp_path / 'status'))}; "
                           + script], capture_output=True, text=True, timeout=300,
                          env={**os.environ, **(env or {})}, cwd=tmp_path)
    status = int((tmp_path / "status").read_text().strip().split("=")[1])
    return status, proc.stderr


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
@pytest.mark.parametrize("tail,env", [
    ("2>/dev/full", {"PYTHONUNBUFFERED": ""}),  # a log on a full disk: the warnings fail
    ("2>/dev/full", {"PYTHONUNBUFFERED": "1"}),
    (">/dev/full", {"PYTHONUNBUFFERED": ""}),  # stdout on a full disk
    (">/dev/full", {"PYTHONUNBUFFERED": "1"}),
    ("| head -c 1 >/dev/null", {"PYTHONUNBUFFERED": "1"}),  # a pipe closed early
    ("", {"PYTHONIOENCODING": "ascii"}),  # a path the stream cannot encode
])
def test_streams_that_refuse_writes_leave_the_result_written(tmp_path, tail, env):
    """A warning written to a full disk threw the finished run away (exit 1 or 120, no output,
    no word), stdout on a full disk or a closed pipe after the outputs were written said
    "error: ... while writing --out" (they were complete), and an ASCII stdout a traceback
    (an outside audit of 2026-11-30): the result is written and the status is 0."""
    out = "r\u00e9s"
    status, err = _cli_process(["run", "--size", "16", "--code-length", "1023", "--no-figure",
                                "--out", out], tmp_path, tail, env)
    assert status == 0, err
    assert "Traceback" not in err and "Exception ignored" not in err and "error" not in err
    assert {p.name for p in (tmp_path / out).iterdir()} >= {"depth.npy", "metrics.json",
                                                            "points.ply"}


def test_a_newline_in_a_path_keeps_the_error_on_one_line(tmp_path, capsys, monkeypatch):
    """A path holding a newline split the one-line error over two lines (an audit of stop 60,
    left then): it is written as ``\\n``, as Python writes it in a string; so is a carriage
    return, also in an OSError's and argparse's lines."""
    monkeypatch.chdir(tmp_path)
    assert main(["run", "--scene", "no\nscene", "--out", "x"]) == 2
    _one_line(capsys, "unknown scene 'no\\nscene'")
    assert main(["reconstruct", "--ptu", "a.ptu", "--patterns", "p.npy", "--code", "c\r\n.npy",
                 "--bit-rate", "1e10", "--range-gate", "1", "2", "--out", "o"]) == 2
    _one_line(capsys, "c\\r\\n.npy")
    with pytest.raises(SystemExit) as info:
        main(["run", "--size", "x\ny"])
    assert info.value.code == 2
    _one_line(capsys, "x\\ny")
    assert not (tmp_path / "x").exists() and not (tmp_path / "o").exists()


def test_a_calibration_out_named_as_a_folder_is_refused(tmp_path):
    """``calibrate --out runs/newdir/`` wrote a plain file named ``newdir`` (Path drops the
    trailing separator: an outside audit of 2026-12-02); a name that ends in a separator,
    or is ``.`` or ``..``, names a folder and is refused before any work."""
    from spslidar.pipeline.calibration_file import check_calibration_out

    for out in (f"{tmp_path}/newdir/", f"{tmp_path}{os.sep}", f"{tmp_path}/.", "..", "."):
        with pytest.raises(SpslidarError, match="is a folder; name the calibration file"):
            check_calibration_out(out)
    assert not (tmp_path / "newdir").exists()
    assert check_calibration_out(tmp_path / "newdir" / "cal.json").name == "cal.json"
