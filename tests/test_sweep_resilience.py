"""A sweep that meets a killed worker, a point's SystemExit, a resumed or re-fingerprinted
cache, a cluster or a clamp of ``--jobs`` (an outside audit of 2026-11-29)."""

from __future__ import annotations

import csv
import functools
import os
import signal
import sys
from typing import Any

import pytest

import spslidar.plugins as plugins
from spslidar.cli import main
from spslidar.depth import ESTIMATORS
from spslidar.experiments.sweep import engine, run_sweep
from spslidar.experiments.sweep.engine import WorkerLost

SMALL = "seed = 1\n[base]\nsize = 8\ncode_length = 63\n"


def _value(params: dict[str, Any]) -> dict[str, Any]:
    return {"value": params["x"] * 2}


def _killed_in_a_worker(params: dict[str, Any], *, parent: int,
                        cache: str | None = None) -> dict[str, Any]:
    """Killed (SIGKILL, as the OS kills for memory) at x == 2 in a pool worker; never in the
    test's own process. With ``cache``, only once a finished run is cached there (on a loaded
    machine the kill came before x == 1 had finished, and the line rightly said no run was
    cached: the test failed on CI's clean clone, 2026-11-30)."""
    if params["x"] == 2 and os.getpid() != parent:
        import time
        from pathlib import Path

        deadline = time.monotonic() + 60
        while cache and time.monotonic() < deadline and not any(
                p.is_file() for p in Path(cache).rglob("*")):
            time.sleep(0.05)
        os.kill(os.getpid(), signal.SIGKILL)
    return _value(params)


def _exits(params: dict[str, Any]) -> dict[str, Any]:
    if params["x"] == 2:
        raise SystemExit("bad boom")
    return _value(params)


@pytest.fixture
def stage_plugin(tmp_path, monkeypatch):
    """A plugin depth stage ``dies``: SIGKILLs its own process in a pool worker (never in this
    one), and raises SystemExit("bad boom") on its second call in this process."""
    monkeypatch.setenv(plugins.ENV, "")
    mod = tmp_path / "resilience_stages.py"
    mod.write_text(
        "import os, signal\n"
        "from spslidar.depth import ESTIMATORS\n"
        "from spslidar.depth.argmax import ArgmaxDepth\n\n"
        f"PARENT = {os.getpid()}\n"
        "CALLS = []\n\n\n"
        "class Dies(ArgmaxDepth):\n"
        "    name = 'dies'\n\n"
        "    def estimate(self, slices, ctx):\n"
        "        if os.getpid() != PARENT:\n"
        "            os.kill(os.getpid(), signal.SIGKILL)\n"
        "        CALLS.append(1)\n"
        "        if len(CALLS) == 2 and os.environ.get('RESILIENCE_EXIT'):\n"
        "            raise SystemExit('bad boom')\n"
        "        return super().estimate(slices, ctx)\n\n\n"
        "ESTIMATORS.add('dies', Dies, 'dies', 'argmax, or a killed worker')\n")
    try:
        yield mod
    finally:
        ESTIMATORS._entries.pop("dies", None)
        plugins._LOADED.clear()
        for name in [n for n in sys.modules if "resilience_stages" in n]:
            sys.modules.pop(name, None)


# --- 1. a killed worker -----------------------------------------------------------------------


def test_a_killed_worker_is_one_line_naming_the_cache(tmp_path):
    if engine.clamp_jobs(2, 3) < 2:
        pytest.skip("no room for a pool of 2 workers here")
    func = functools.partial(_killed_in_a_worker, parent=os.getpid(),
                             cache=str(tmp_path / "runs"))
    points = [{"x": 1}, {"x": 2}, {"x": 3}]
    with pytest.raises(WorkerLost) as info:
        run_sweep(func, points, tmp_path, jobs=2, progress=False)
    text = str(info.value)
    assert text.startswith("a worker process was killed (signal 9: out of memory?); ")
    assert f"cached in {tmp_path / 'runs'}: run the same command again to resume" in text
    assert "\n" not in text
    # the finished runs are cached: a rerun (here in-process) completes
    rows = run_sweep(func, points, tmp_path, progress=False)
    assert [r["value"] for r in rows] == [2, 4, 6]


def test_the_cli_says_a_killed_worker_in_one_line_and_exits_1(stage_plugin, tmp_path, capsys):
    if engine.clamp_jobs(2, 2) < 2:
        pytest.skip("no room for a pool of 2 workers here")
    toml = tmp_path / "s.toml"
    toml.write_text(SMALL + 'depth = "dies"\n[grid]\nnoise = [1, 5]\n')
    out = tmp_path / "o"
    status = main(["--plugin", str(stage_plugin), "sweep", str(toml), "--out", str(out),
                   "--jobs", "2", "--no-progress"])
    err = capsys.readouterr().err
    assert status == 1
    assert "Traceback" not in err and "TerminatedWorkerError" not in err
    lines = [line for line in err.splitlines() if "worker process was killed" in line]
    assert len(lines) == 1 and lines[0].startswith("spslidar sweep: a worker process was killed")
    # no run had finished (the stage dies at every point): no folder of a marker alone
    assert lines[0].endswith("before any run finished: run the same command again (with "
                             "fewer --jobs where memory ran out)")
    assert not out.exists()
    # in this process the stage does not die: the same command (one job) completes
    assert main(["--plugin", str(stage_plugin), "sweep", str(toml), "--out", str(out),
                 "--no-progress"]) == 0


# --- 2. --max-time prices the runs not cached ------------------------------------------------


def test_max_time_leaves_out_the_cached_runs(tmp_path, capsys):
    toml = tmp_path / "s.toml"
    toml.write_text(SMALL + "[grid]\nnoise = [1, 2]\n")
    args = ["sweep", str(toml), "--out", str(tmp_path / "o"), "--no-progress"]
    assert main(args) == 0
    capsys.readouterr()
    assert main([*args, "--max-time", "0.001"]) == 0  # every run cached: nothing to price
    assert "sweep: 2 runs (2 read from the cache, 0 run), 2 ok" in capsys.readouterr().err
    toml.write_text(SMALL + "[grid]\nnoise = [1, 2, 3]\n")
    assert main([*args, "--overwrite", "--max-time", "0.001"]) == 2  # one run to price
    assert "(2 cached, not counted; 1 to run) would take" in capsys.readouterr().err


def test_max_time_says_the_runs_cached_by_other_code(tmp_path, capsys, monkeypatch):
    # (an audit of 2026-12-01: every run cached by older code was priced, and the refusal
    # said only "2 runs would take", as if the cache had not been read)
    import spslidar.plugins

    toml = tmp_path / "s.toml"
    toml.write_text(SMALL + "[grid]\nnoise = [1, 2]\n")
    args = ["sweep", str(toml), "--out", str(tmp_path / "o"), "--no-progress"]
    assert main(args) == 0
    capsys.readouterr()
    monkeypatch.setattr(spslidar.plugins, "code_fingerprint", lambda: "0" * 16)
    assert main([*args, "--max-time", "0.001"]) == 2
    assert ("(0 cached, not counted; 2 to run, 2 of them cached by other code (spslidar or "
            "its plugins changed)) would take") in capsys.readouterr().err


# --- 3. a cluster's threads, not --jobs ------------------------------------------------------


def test_a_clusters_threads_share_the_estimate_and_jobs_is_ignored(tmp_path, capsys,
                                                                    monkeypatch):
    import distributed

    from spslidar.errors import SpslidarError
    from spslidar.pipeline import budget

    said: list[float] = []
    real = budget.check_time

    def stop(seconds, max_time, what="this run", *args, **kwargs):
        if not what.startswith("this sweep"):  # a run's own check (the preflight)
            return real(seconds, max_time, what, *args, **kwargs)
        said.append(seconds)
        raise SpslidarError("priced")

    monkeypatch.setattr(budget, "check_time", stop)
    toml = tmp_path / "s.toml"
    toml.write_text(SMALL + "[grid]\nnoise = [1, 2, 3, 4]\n")
    args = ["sweep", str(toml), "--out", str(tmp_path / "o"), "--no-progress"]
    assert main(args) == 2  # one local process: the whole estimate
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as cluster:
        assert main([*args, "--scheduler", cluster.scheduler_address, "--jobs", "64"]) == 2
    assert said[1] == pytest.approx(said[0] / 2)  # its 2 threads, not 64 (nor 4) workers
    assert "--jobs 64 is ignored with --scheduler: the cluster's 2 threads" in (
        capsys.readouterr().err)


# --- 4. a cache of other code is said ---------------------------------------------------------


def test_cached_runs_of_other_code_are_said(tmp_path, capsys):
    points = [{"x": 1}, {"x": 2}]
    run_sweep(_value, points, tmp_path, progress=False, code="aaaa")
    assert "other code" not in capsys.readouterr().err
    counts: dict[str, int] = {}
    run_sweep(_value, points, tmp_path, progress=False, code="bbbb", counts=counts)
    assert ("2 cached runs were made by other code (spslidar or its plugins changed) and are "
            "run again") in capsys.readouterr().err
    assert counts == {"cached": 0, "run": 2, "stale": 2}


# --- 5. a point's SystemExit is that point's failure ------------------------------------------


def test_a_points_system_exit_is_a_failed_row(tmp_path):
    rows = run_sweep(_exits, [{"x": 1}, {"x": 2}, {"x": 3}], tmp_path, progress=False)
    assert [r.get("error") for r in rows] == [None, "SystemExit: bad boom", None]
    assert [r.get("value") for r in rows] == [2, None, 6]


def test_a_plugin_stages_system_exit_names_its_point(stage_plugin, tmp_path, capsys,
                                                     monkeypatch):
    monkeypatch.setenv("RESILIENCE_EXIT", "1")
    toml = tmp_path / "s.toml"
    toml.write_text(SMALL + 'depth = "dies"\n[grid]\nnoise = [1, 5, 9]\n')
    out = tmp_path / "o"
    assert main(["--plugin", str(stage_plugin), "sweep", str(toml), "--out", str(out),
                 "--no-progress"]) == 1
    err = capsys.readouterr().err
    assert "sweep: 3 runs, 2 ok, 1 failed" in err
    assert "sweep: failed (noise=5, trial=0): SystemExit: bad boom" in err
    rows = list(csv.DictReader((out / "results.csv").open()))
    assert [r["error"] for r in rows] == ["", "SystemExit: bad boom", ""]


# --- 7. and 8. the exit status in --help; a clamp of --jobs said -----------------------------


def test_sweep_help_gives_the_exit_statuses(capsys):
    with pytest.raises(SystemExit):
        main(["sweep", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "Exit status: 0 when every run succeeded; 1 when the work did not complete" in text
    assert "2 on bad input" in text


def test_a_clamp_of_jobs_is_said(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(engine, "_cores", lambda: 2)
    toml = tmp_path / "s.toml"
    toml.write_text(SMALL + "[grid]\nnoise = [1]\n")
    assert main(["sweep", str(toml), "--out", str(tmp_path / "o"), "--jobs", "8",
                 "--no-progress"]) == 0
    assert ("spslidar sweep: warning: --jobs 8 clamped to 1 (1 runs to do, 2 cores)"
            in capsys.readouterr().err)


def test_a_garbled_loky_cpu_count_is_one_line_and_leaves_no_folder(tmp_path, monkeypatch,
                                                                   capsys):
    """``LOKY_MAX_CPU_COUNT=garbage`` was joblib's int() traceback, and left a folder holding
    nothing but a marker (an audit of 2026-11-30)."""
    from spslidar.cli import main

    toml = tmp_path / "s.toml"
    toml.write_text("[base]\nsize = 16\ncode_length = 1023\n[grid]\nseed = [0, 1]\n")
    monkeypatch.setenv("LOKY_MAX_CPU_COUNT", "garbage")
    out = tmp_path / "sw"
    assert main(["sweep", str(toml), "--jobs", "2", "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert "LOKY_MAX_CPU_COUNT='garbage'" in err and "Traceback" not in err
    assert not out.exists()
