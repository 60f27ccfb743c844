"""A sweep's IRF files checked as ``run`` checks them, its estimate of a large grid in seconds,
a full disk at ``results.csv``, a ``grid`` key under ``[base]``, an unreadable marker and the
``--jobs`` clamp said as a sweep warning (an outside audit of 2026-12-03)."""

from __future__ import annotations

import errno
import json
import time

import numpy as np
import pytest

from spslidar.cli import main
from spslidar.experiments.sweep import command, engine

SMALL = "seed = 1\n[base]\nsize = 16\ncode_length = 63\n"


def _err_lines(capsys) -> list[str]:
    return capsys.readouterr().err.strip().splitlines()


@pytest.mark.parametrize("kind", ["nan", "not_npy", "too_wide"])
def test_a_bad_irf_in_the_grid_is_refused_before_any_run(tmp_path, capsys, kind):
    """An IRF file of NaN, or one that is no array, ran every point into a failure (exit 1,
    a folder of an error row); ``run --irf`` refuses it, and so does the sweep now, before
    the folder exists. A Gaussian wider than half the code period too (``run``'s check)."""
    if kind == "nan":
        irf = np.ones((64, 16, 16))
        irf[0, 0, 0] = np.nan
        np.save(tmp_path / "p.npy", irf)
        value, said = "../p.npy", "a 1-D array of non-negative numbers"
    elif kind == "not_npy":
        (tmp_path / "p.npy").write_text("not an array\n")
        value, said = "../p.npy", "not a .npy file"
    else:
        value, said = "gaussian:1e-7", "wider than half the code period"
    (tmp_path / "t").mkdir()
    toml = tmp_path / "t" / "s.toml"
    toml.write_text(f'[base]\nsize = 16\ncode_length = 63\n[grid]\nirf = ["{value}"]\n')
    out = tmp_path / "o"
    assert main(["sweep", str(toml), "--out", str(out), "--no-progress"]) == 2
    lines = _err_lines(capsys)
    assert len(lines) == 1, lines
    assert lines[0].startswith("spslidar sweep: error: ") and "--irf" in lines[0]
    assert said in lines[0]
    assert not out.exists()


def test_a_large_grid_is_priced_in_seconds(tmp_path, capsys):
    """A grid of 9 000 points (noise x signal) spent 6 min 44 s pricing each point from
    scratch before its --max-time refusal; points that differ in the flux alone share one
    plan now (3 000 points here: about 2 s)."""
    noise, signal = list(range(1, 31)), list(range(1, 101))
    toml = tmp_path / "big.toml"
    toml.write_text(f"[base]\nsize = 16\ncode_length = 1023\n[grid]\nnoise = {noise}\n"
                    f"signal = {signal}\n")
    out = tmp_path / "o"
    start = time.perf_counter()
    assert main(["sweep", str(toml), "--out", str(out), "--max-time", "60",
                 "--no-progress"]) == 2
    took = time.perf_counter() - start
    lines = _err_lines(capsys)
    assert len(lines) == 1 and "this sweep of 3000 runs would take" in lines[0], lines
    assert took < 30, took
    assert not out.exists()


def test_a_plan_is_made_once_per_configuration_but_its_flux(tmp_path, capsys, monkeypatch):
    """The scene is read once, and the plan made once per configuration but its flux and
    seed: two solvers are two plans (each priced and its memory checked as its own), however
    many noise and signal values."""
    import spslidar.pipeline.plan as plan
    import spslidar.scenes as scenes

    calls = {"plan": 0, "scene": 0}
    real_plan, real_load = plan._plan, scenes.load_scene

    def counted_plan(*args, **kwargs):
        calls["plan"] += 1
        return real_plan(*args, **kwargs)

    def counted_load(*args, **kwargs):
        calls["scene"] += 1
        return real_load(*args, **kwargs)

    monkeypatch.setattr(plan, "_plan", counted_plan)
    monkeypatch.setattr(scenes, "load_scene", counted_load)
    toml = tmp_path / "s.toml"
    toml.write_text("seed = 1\ntrials = 2\n[base]\nsize = 16\ncode_length = 63\n[grid]\n"
                    "noise = [1, 2, 3, 4]\nsignal = [1, 2, 3]\nsolver = ['fista', 'twist']\n")
    out = tmp_path / "o"
    assert main(["sweep", str(toml), "--out", str(out), "--max-time", "0.001",
                 "--no-progress"]) == 2
    assert "this sweep of 48 runs would take" in capsys.readouterr().err
    assert calls == {"plan": 2, "scene": 1}
    assert not out.exists()


def test_a_full_disk_at_results_csv_exits_1_and_names_the_cache(tmp_path, capsys,
                                                                  monkeypatch):
    """``results.csv`` refused by a full disk after every run ran exited 2, as bad input;
    the work did not complete (exit 1), and the line names the folder and the cached runs
    that the same command reuses."""
    toml = tmp_path / "s.toml"
    toml.write_text(SMALL + "[grid]\nnoise = [1, 2]\n")
    out = tmp_path / "o"

    def full(rows, path):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(command, "write_csv", full)
    assert main(["sweep", str(toml), "--out", str(out), "--no-progress"]) == 1
    lines = [line for line in _err_lines(capsys) if "could not be written" in line]
    assert len(lines) == 1, lines
    line = lines[0]
    assert line.startswith("spslidar sweep: results.csv could not be written into ")
    assert "No space left on device" in line and str(out) in line
    assert "2 finished runs cached in" in line and "run the same command" in line
    assert sorted(p.suffix for p in (out / "runs").iterdir()) == [".json", ".json"]
    assert not (out / "results.csv").exists()
    monkeypatch.undo()  # the disk has room again: the rerun reads the cache
    assert main(["sweep", str(toml), "--out", str(out), "--no-progress"]) == 0
    assert "(2 read from the cache, 0 run)" in capsys.readouterr().err
    assert (out / "results.csv").is_file()


def test_a_full_disk_at_the_markers_record_exits_1(tmp_path, capsys, monkeypatch):
    """The marker's record of a written ``results.csv`` refused by a full disk: exit 1, said
    as such, and the same command again completes."""
    import spslidar.outdir as outdir

    toml = tmp_path / "s.toml"
    toml.write_text(SMALL + "[grid]\nnoise = [1]\n")
    out = tmp_path / "o"

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(outdir, "record_outputs", full)
    assert main(["sweep", str(toml), "--out", str(out), "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "results.csv was written into" in err and "marker could not record it" in err
    monkeypatch.undo()
    assert main(["sweep", str(toml), "--out", str(out), "--no-progress"]) == 0


@pytest.mark.parametrize("text, said", [
    ("[base]\nsize = 16\ngrid = 3\n", "grid must be a table ([grid]), got 3 (written after "
                                      "the [base] header, it is read as base.grid"),
    ("[base]\nsize = 16\ntrials = 2\n[grid]\nnoise = [1, 2]\n",
     "base.trials is not a run key (written after the [base] header"),
    ("[base]\nsize = 16\n[grid]\nnoise = [1, 2]\nbase = [1, 2]\n",
     "base must be a table ([base]), got [1, 2] (written after the [grid] header"),
    ("grid = 3\n", "grid must be a table ([grid]), got 3"),
])
def test_a_sweep_key_under_a_table_says_what_it_is(tmp_path, capsys, text, said):
    """``grid = 3`` under ``[base]`` said "[grid] is empty and trials = 1, so there is
    nothing to sweep", where ``base = [1, 2]`` said what was wrong."""
    toml = tmp_path / "s.toml"
    toml.write_text(text)
    out = tmp_path / "o"
    assert main(["sweep", str(toml), "--out", str(out), "--no-progress"]) == 2
    lines = _err_lines(capsys)
    assert len(lines) == 1 and said in lines[0], lines
    assert "nothing to sweep" not in lines[0]
    assert not out.exists()


def test_an_unreadable_marker_is_said_as_such_and_nothing_is_deleted(tmp_path, capsys):
    """A damaged marker was "holds no spslidar marker"; it is there, unreadable: refused in
    one line that says so, every file left as it was."""
    toml = tmp_path / "s.toml"
    toml.write_text(SMALL + "[grid]\nnoise = [1, 2]\n")
    out = tmp_path / "o"
    (out / "runs").mkdir(parents=True)
    (out / ".spslidar-output.json").write_text("{\n")
    record = out / "runs" / "0123456789abcdef.json"
    record.write_text(json.dumps({"result": {}}))
    before = {p: p.read_bytes() for p in out.rglob("*") if p.is_file()}
    assert main(["sweep", str(toml), "--out", str(out), "--no-progress"]) == 2
    lines = _err_lines(capsys)
    assert len(lines) == 1, lines
    assert "marker .spslidar-output.json is there but unreadable" in lines[0]
    assert "holds no spslidar marker" not in lines[0]
    assert {p: p.read_bytes() for p in out.rglob("*") if p.is_file()} == before


def test_a_clamp_of_jobs_is_a_sweep_warning(tmp_path, capsys, monkeypatch):
    """``--jobs 999`` was said as "spslidar: --jobs 999 clamped to 2", without the
    ``spslidar sweep: warning:`` of the sweep's other warnings."""
    monkeypatch.setattr(engine, "_cores", lambda: 2)
    monkeypatch.setattr(engine, "_process_headroom", lambda: None)
    toml = tmp_path / "s.toml"
    toml.write_text(SMALL + "[grid]\nnoise = [1, 2]\n")
    out = tmp_path / "o"
    assert main(["sweep", str(toml), "--out", str(out), "--jobs", "999",
                 "--max-time", "0.001", "--no-progress"]) == 2
    lines = _err_lines(capsys)
    assert lines[0] == "spslidar sweep: warning: --jobs 999 clamped to 2 (2 runs to do, 2 cores)"
    assert len(lines) == 2 and "more than --max-time" in lines[1], lines
    assert not out.exists()


def test_reproduce_says_an_unreadable_marker_too(tmp_path, capsys):
    """The same folder claim (:func:`spslidar.outdir.claim_folder`) serves ``reproduce``:
    its damaged marker is said as such, and nothing there is changed."""
    out = tmp_path / "o"
    out.mkdir()
    (out / ".spslidar-output.json").write_text("{\n")
    (out / "notes.txt").write_text("mine")
    assert main(["reproduce", "fig4", "--quick", "--out", str(out)]) == 2
    lines = _err_lines(capsys)
    assert len(lines) == 1 and "marker .spslidar-output.json is there but unreadable" in lines[0]
    assert (out / "notes.txt").read_text() == "mine"
    assert (out / ".spslidar-output.json").read_text() == "{\n"


def test_a_dead_time_grid_of_the_linear_counter_shares_its_seeds(tmp_path, capsys):
    """The linear counter's dead time sets only its pile-up report: a grid over it drew other
    noise at each point, an effect of a dead time it does not model (an outside audit of
    2026-12-03). Its points share their seed and depth now (only a run's pile-up report
    reads the value), and the sweep says so; the GMAPD's points, which it changes, keep
    their own seeds."""
    import csv

    def sweep(detector: str, flux: str = "") -> list[dict]:
        toml = tmp_path / f"{detector}.toml"
        toml.write_text(f'[base]\nsize = 8\ncode_length = 63\ndetector = "{detector}"\n{flux}'
                        f"[grid]\ndead_time = [5e-8, 2e-7]\n")
        out = tmp_path / detector
        assert main(["sweep", str(toml), "--out", str(out), "--no-progress"]) == 0
        with open(out / "results.csv", newline="") as fh:
            return list(csv.DictReader(fh))

    rows = sweep("linear")
    err = capsys.readouterr().err
    assert "--dead-time 2e-07 of --detector linear changes only its pile-up report" in err
    assert rows[0]["seed"] == rows[1]["seed"]
    assert rows[0]["depth_rmse_m"] == rows[1]["depth_rmse_m"]
    rows = sweep("gmapd", "signal = 1e-5\nnoise = 2e-5\n")  # a GMAPD's flux
    assert "changes only its pile-up report" not in capsys.readouterr().err
    assert rows[0]["seed"] != rows[1]["seed"]
