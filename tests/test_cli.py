"""The command-line tool, driven through ``main([...])``."""

import json
import re
import subprocess
import sys

import numpy as np
import pytest

from spslidar.cli import main

FAST = ["--size", "16", "--code-length", "1023"]


def test_run_writes_results(tmp_path, capsys):
    out = tmp_path / "r"
    assert main(["run", *FAST, "--out", str(out)]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert "depth RMSE" in lines[1]
    assert {p.name for p in out.iterdir() if not p.name.startswith(".")} == {
        "metrics.json", "depth.npy", "truth.npy", "valid.npy", "depth.png", "confidence.npy",
        "reflectivity.npy", "points.ply"}
    m = json.loads((out / "metrics.json").read_text())
    assert np.load(out / "depth.npy").shape == (16, 16)
    assert m["config"]["size"] == 16


def test_config_file_and_override(tmp_path):
    cfg = tmp_path / "c.toml"
    cfg.write_text('size = 16\ncode-length = 1023\nnoise = 2.0\nsolver = "twist"\n')
    out = tmp_path / "r"
    assert main(["run", "--config", str(cfg), "--noise", "3", "--out", str(out)]) == 0
    m = json.loads((out / "metrics.json").read_text())
    assert m["config"]["noise"] == 3.0 and m["config"]["solver"] == "twist"


@pytest.mark.parametrize("line,flag,says", [
    ("size = 16.5", ["--size", "8"], "--size must be an integer, got 16.5"),
    ("noise = -1", ["--noise", "2"], r"--noise must be in \[0, inf\), got -1"),
    ('solver = "nope"', ["--solver", "fista"], "unknown solver 'nope'"),
    ('detector = "gmapd"\ndead_time = "abc"', ["--dead-time", "5e-8"],
     "--dead-time must be a number, got 'abc'")])
def test_config_file_value_overridden_is_still_checked(tmp_path, capsys, line, flag, says):
    """A file's invalid value is refused though the command line overrides it (``size =
    16.5`` with ``--size 8`` ran: an audit of 2026-11-29), naming the file; a value that only
    conflicts with another the command line changes is not (next test)."""
    cfg = tmp_path / "c.toml"
    cfg.write_text(f"{line}\n")
    out = tmp_path / "r"
    assert main(["run", "--config", str(cfg), *FAST, *flag, "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"config file {cfg}: " in err and "overrides it" in err
    assert re.search(says, err), err
    assert not out.exists()


def test_config_file_value_valid_alone_with_an_override(tmp_path):
    """``compression = 0.02`` gives one pattern at the file's 8x8 (refused there) but is valid
    on its own and at the command line's 16x16 (5 patterns)."""
    cfg = tmp_path / "c.toml"
    cfg.write_text("size = 8\ncompression = 0.02\ncode-length = 1023\n")
    out = tmp_path / "r"
    assert main(["run", "--config", str(cfg), "--size", "16", "--out", str(out)]) == 0
    assert json.loads((out / "metrics.json").read_text())["config"]["size"] == 16


@pytest.mark.parametrize("lines,flags", [
    # valid with the file's own size (one pattern only at the default 64x64)
    ("size = 128\ncompression = 0.0002", ["--compression", "0.25", "--size", "16"]),
    # a GPU config run here with the command line's backend (this machine may lack PyTorch)
    ('backend = "torch"\ndevice = "cuda"\nsize = 16', ["--backend", "numpy", "--device",
                                                       "cpu"]),
])
def test_config_file_values_valid_in_their_own_context_are_not_refused(tmp_path, lines, flags):
    """A review of 2026-11-30: the overridden values were checked beside the defaults alone
    (and against this machine's backends), refusing files that are valid."""
    cfg = tmp_path / "c.toml"
    cfg.write_text(lines + "\n")
    out = tmp_path / "r"
    assert main(["run", "--config", str(cfg), "--code-length", "1023", "--no-figure", *flags,
                 "--out", str(out)]) == 0


def _bad(tmp_path):
    nan = tmp_path / "nan.npy"
    np.save(nan, np.full((8, 8), np.nan))
    neg = tmp_path / "neg.npy"
    np.save(neg, -np.ones((8, 8)))
    toml = tmp_path / "bad.toml"
    toml.write_text("sise = 3\n")
    return {
        "missing scene": ["--scene", str(tmp_path / "nope.npy")],
        "nan depth": ["--scene", str(nan)],
        "negative depth": ["--scene", str(neg)],
        "unknown scene": ["--scene", "airplane"],
        "compression 0": ["--compression", "0"],
        "compression > 1": ["--compression", "1.5"],
        "mseq length": ["--code-length", "1000"],
        "gold length": ["--code", "gold", "--code-length", "4095"],
        "ones ratio": ["--code", "random", "--ones-ratio", "1.5"],
        "negative signal": ["--signal", "-1"],
        "negative noise": ["--noise", "-2"],
        "unknown solver": ["--solver", "newton"],
        "bad gate": ["--range-gate", "5", "1"],
        "bad config key": ["--config", str(toml)],
        "missing config": ["--config", str(tmp_path / "none.toml")],
        "bad number": ["--size", "big"],
        "depth window": ["--depth-min", "5", "--depth-max", "4"],
    }


def test_every_bad_input_is_one_line_exit_2_and_no_output(tmp_path, capsys):
    for name, args in _bad(tmp_path).items():
        out = tmp_path / f"out-{name.replace(' ', '_')}"
        try:
            code = main(["run", "--size", "16", "--code-length", "1023", *args,
                         "--out", str(out)])
        except SystemExit as exc:  # argparse errors
            code = exc.code
        err = capsys.readouterr().err.strip()
        assert code == 2, name
        assert len(err.splitlines()) == 1, (name, err)
        assert "error" in err and "Traceback" not in err, name
        assert not out.exists(), name
    # and no temporary folders were left behind
    assert not [p for p in tmp_path.iterdir() if ".tmp-" in p.name]


def test_warns_about_range_ambiguity(tmp_path, capsys):
    out = tmp_path / "r"
    code = main(["run", "--size", "16", "--code-length", "511", "--range-gate", "1", "30",
                 "--out", str(out), "--no-figure"])
    assert code == 0
    err = capsys.readouterr().err
    assert "unambiguous range" in err and "7.66 m" in err


def test_help_is_light():
    code = ("import sys, spslidar.cli as c; c.build_parser().format_help(); "
            "print(sorted(m for m in ('numpy', 'scipy', 'matplotlib', 'skimage') "
            "if m in sys.modules))")
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True)
    assert res.stdout.strip() == "[]"


def test_no_command_prints_help(capsys):
    assert main([]) == 2
    assert "run" in capsys.readouterr().out


# -- spslidar sweep / reproduce through main([...]) ------------------------------------------


SWEEP_TOML = """\
seed = 1
trials = 2
[base]
size = 16
code_length = 1023
[grid]
noise = [1, 10]
"""


def test_sweep_runs_grid_and_resumes(tmp_path, capsys):
    cfg = tmp_path / "s.toml"
    cfg.write_text(SWEEP_TOML)
    out = tmp_path / "sw"
    assert main(["sweep", str(cfg), "--out", str(out), "--no-progress"]) == 0
    import csv

    rows = list(csv.DictReader(open(out / "results.csv", newline="")))
    assert len(rows) == 4
    assert {(r["noise"], r["trial"]) for r in rows} == {(n, t) for n in ("1", "10")
                                                         for t in ("0", "1")}
    assert len({r["seed"] for r in rows}) == 4  # seeds derived from (seed, parameters)
    assert all(float(r["depth_rmse_m"]) > 0 for r in rows)
    cached = sorted(p.name for p in (out / "runs").glob("*.json"))
    assert len(cached) == 4
    # a second call finds every run in the cache and computes nothing
    stamps = {p.name: p.stat().st_mtime_ns for p in (out / "runs").glob("*.json")}
    assert main(["sweep", str(cfg), "--out", str(out), "--no-progress"]) == 0
    assert stamps == {p.name: p.stat().st_mtime_ns for p in (out / "runs").glob("*.json")}


@pytest.mark.parametrize("grid", ["noize = [1]", "noise = [-1]", "solver = ['newton']"])
def test_sweep_bad_grid_is_one_line_exit_2_no_output(tmp_path, capsys, grid):
    cfg = tmp_path / "bad.toml"
    cfg.write_text(f"[grid]\n{grid}\n")
    out = tmp_path / "sw"
    assert main(["sweep", str(cfg), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "error" in err and str(cfg) in err
    assert not out.exists()


def test_sweep_missing_config(tmp_path, capsys):
    assert main(["sweep", str(tmp_path / "none.toml"), "--out", str(tmp_path / "o")]) == 2
    assert len(capsys.readouterr().err.strip().splitlines()) == 1


@pytest.mark.parametrize("args", [["fig9"], ["fig2", "--trials", "0"], ["fig2", "--jobs", "0"],
                                  ["fig2", "--trials", "x"]])
def test_reproduce_bad_input_one_line_exit_2(tmp_path, capsys, args):
    out = tmp_path / "rep"
    try:
        code = main(["reproduce", *args, "--out", str(out)])
    except SystemExit as exc:  # argparse errors
        code = exc.code
    assert code == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "error" in err
    assert not out.exists()


def test_reproduce_all_quick(tmp_path, capsys):
    """`spslidar reproduce all --quick`: every experiment's figure, CSV and report section."""
    from spslidar.experiments.names import EXPERIMENT_NAMES

    out = tmp_path / "rep"
    assert main(["reproduce", "all", "--quick", "--out", str(out), "--no-progress"]) == 0
    text = (out / "report.md").read_text()
    for name in EXPERIMENT_NAMES:
        assert (out / name / "section.md").is_file(), name
        assert list((out / name).glob("*.csv")), name
        if name != "table1":
            assert list((out / name).glob("*.png")), name
    assert (out / "report.html").is_file()
    assert "0.201" in text and "0.176" in text and "0.033" in text  # the paper's numbers
    assert "aliased by 1 x 15.0 m" in text  # the conventional lidar wraps, the PSST does not
    assert (out / "table1" / "table1.md").is_file()


def test_spslidars_own_warnings_do_not_name_a_source_line(monkeypatch, capsys, tmp_path):
    """spslidar's own warnings say what they are; their source line read as a fault of the
    code ("... (RuntimeWarning in calibration.py:378)" after a calibration's advice, an
    audit). A library's warning keeps where it came from, and a repeat of one of ours is
    counted by its first words."""
    import warnings
    from pathlib import Path

    import spslidar
    from spslidar import cli

    own = str(Path(spslidar.__file__).parent / "pipeline" / "calibration.py")

    def noisy(args):
        for n in (1, 2):
            warnings.warn_explicit(f"the target spreads over {n} bins", RuntimeWarning, own, 7)
        warnings.warn_explicit("overflow encountered", RuntimeWarning, "/lib/numpy/x.py", 9)
        return 0

    monkeypatch.setitem(cli.COMMANDS, "run", noisy)
    assert cli.main(["run", "--out", str(tmp_path / "r")]) == 0
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "spslidar run: warning: the target spreads over 1 bins"
    assert err[1].endswith("overflow encountered (RuntimeWarning in x.py:9)")
    assert '("the target spreads over 1 bins ...") came 1 more time' in err[2]


def test_a_warning_repeated_with_other_numbers_is_one_line_and_a_count(monkeypatch, capsys,
                                                                        tmp_path):
    """The GMAPD's fixed point warns once per block of patterns, each time with another
    relative change: one line per 64 patterns, all but the numbers the same. The command line prints
    it once, then how many more came; a different warning from the same place still shows."""
    import warnings

    from spslidar import cli

    def noisy(args):
        for change in (1.5e-3, 2.7e-4, 9.1e-5):
            warnings.warn(f"fixed point not converged (relative change {change:.2e})",
                          RuntimeWarning, stacklevel=1)
        warnings.warn("something else", RuntimeWarning, stacklevel=1)
        return 0

    monkeypatch.setitem(cli.COMMANDS, "run", noisy)
    assert cli.main(["run", "--out", str(tmp_path / "r")]) == 0
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 3, err
    assert "relative change 1.50e-03" in err[0] and "something else" in err[1]
    assert "came 2 more times" in err[2]
