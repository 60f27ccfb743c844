"""Tests of the Monte-Carlo sweep engine (spslidar.experiments.sweep)."""

from __future__ import annotations

import csv
import functools
import json
import os
import subprocess
import sys
import uuid
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from spslidar.errors import ConfigError
from spslidar.experiments import sweep
from spslidar.experiments.sweep import (
    SweepSpec,
    derive_seed,
    expand_grid,
    load_sweep_config,
    point_key,
    run_point,
    run_sweep,
    sweep_main,
    write_csv,
)

# Computed once with derive_seed and frozen here: a change means every cached sweep and every
# published result would silently change, so it must be deliberate.
FROZEN_PARAMS = {"noise": 5, "code_length": 1023, "size": 32, "rate": 0.25, "trial": 1}
FROZEN_SEED = 1662874469


# ---------------------------------------------------------------------------------------------
# Toy point functions (module level, so that joblib and Dask can pickle them)
# ---------------------------------------------------------------------------------------------


def toy(params: dict[str, Any]) -> dict[str, Any]:
    """A pure function of the params whose result depends on the seed."""
    rng = np.random.default_rng(params["seed"])
    return {
        "value": params["x"] * 10.0 + float(rng.normal()),
        "stats": {"mean": np.float64(params["x"]), "n": np.int64(3)},
        "curve": np.arange(3) * params["x"],
    }


def counting(params: dict[str, Any], *, calls_dir: str, fail_x: Any = None) -> dict[str, Any]:
    """Like :func:`toy`, leaving one file per call in ``calls_dir``; raises on ``x == fail_x``."""
    Path(calls_dir).mkdir(exist_ok=True)
    (Path(calls_dir) / f"{uuid.uuid4().hex}.json").write_text(json.dumps(params))
    if params["x"] == fail_x:
        raise ValueError(f"bad x\n{params['x']}")
    return toy(params)


def interrupting(params: dict[str, Any], *, calls_dir: str, stop_x: Any) -> dict[str, Any]:
    """Like :func:`counting`, but a Ctrl-C arrives while running the point ``x == stop_x``."""
    if params["x"] == stop_x:
        raise KeyboardInterrupt
    return counting(params, calls_dir=calls_dir)


def calls(calls_dir: Path) -> list[dict[str, Any]]:
    """Params of the calls recorded by :func:`counting`."""
    if not calls_dir.exists():
        return []
    return [json.loads(p.read_text()) for p in calls_dir.glob("*.json")]


def not_a_dict(params: dict[str, Any]) -> list[int]:
    return [1, 2]


def unserializable(params: dict[str, Any]) -> dict[str, Any]:
    return {"obj": object()}


POINTS = expand_grid({"size": 8}, {"x": [1, 2, 3]}, trials=2)


# ---------------------------------------------------------------------------------------------
# expand_grid
# ---------------------------------------------------------------------------------------------


def test_expand_grid_order_size_and_trials():
    points = expand_grid({"size": 32, "noise": 0}, {"noise": [1, 5], "code": [7, 15, 31]}, 2)
    assert len(points) == 2 * 3 * 2
    combos = [(p["noise"], p["code"], p["trial"]) for p in points]
    # First grid key slowest, trial fastest.
    assert combos[:4] == [(1, 7, 0), (1, 7, 1), (1, 15, 0), (1, 15, 1)]
    assert combos[-1] == (5, 31, 1)
    assert len(set(combos)) == len(combos)
    assert all(p["size"] == 32 for p in points)
    assert list(points[0]) == ["size", "noise", "code", "trial"]
    # Grid values override base; the order follows the grid's key order.
    swapped = expand_grid({}, {"code": [7, 15, 31], "noise": [1, 5]})
    assert [(p["noise"], p["code"]) for p in swapped][:3] == [(1, 7), (5, 7), (1, 15)]


def test_expand_grid_empty_grid_and_deep_copies():
    base = {"scene": {"depth": 1.0}}
    points = expand_grid(base, {}, trials=3)
    assert [p["trial"] for p in points] == [0, 1, 2]
    points[0]["scene"]["depth"] = 99.0
    assert points[1]["scene"]["depth"] == 1.0 and base["scene"]["depth"] == 1.0
    assert expand_grid({}, {"a": (1, 2)}) == [{"a": 1, "trial": 0}, {"a": 2, "trial": 0}]


@pytest.mark.parametrize(
    ("base", "grid", "trials", "match"),
    [
        ({}, {"a": []}, 1, "non-empty list"),
        ({}, {"a": 3}, 1, "non-empty list"),
        ({}, {"a": "abc"}, 1, "non-empty list"),
        ({}, {"a": [1]}, 0, "trials must be >= 1"),
        ({}, {"a": [1]}, 1.5, "trials must be an integer"),
        ({}, {"trial": [1]}, 1, "reserved"),
        ({"trial": 0}, {}, 1, "reserved"),
        ([], {}, 1, "base must be a table"),
        ({}, [1, 2], 1, "grid must be a table"),
    ],
)
def test_expand_grid_rejects_bad_input(base, grid, trials, match):
    with pytest.raises(ConfigError, match=match):
        expand_grid(base, grid, trials)


# ---------------------------------------------------------------------------------------------
# derive_seed
# ---------------------------------------------------------------------------------------------


def test_derive_seed_frozen_value_and_key_order():
    assert derive_seed(7, FROZEN_PARAMS) == FROZEN_SEED
    assert derive_seed(7, dict(reversed(list(FROZEN_PARAMS.items())))) == FROZEN_SEED
    numpy_params = {**FROZEN_PARAMS, "noise": np.int64(5), "rate": np.float64(0.25)}
    assert derive_seed(np.int64(7), numpy_params) == FROZEN_SEED
    assert 0 <= FROZEN_SEED < 2**32


def test_derive_seed_same_in_another_process():
    code = (
        "import json, sys; from spslidar.experiments.sweep import derive_seed; "
        "print(derive_seed(7, json.loads(sys.argv[1])))"
    )
    out = subprocess.run(
        [sys.executable, "-c", code, json.dumps(FROZEN_PARAMS)],
        capture_output=True,
        text=True,
        check=True,
        env={**os.environ, "PYTHONHASHSEED": "123"},
    )
    assert int(out.stdout) == FROZEN_SEED


def test_derive_seed_changes_with_params_and_seed():
    seeds = {
        derive_seed(7, FROZEN_PARAMS),
        derive_seed(8, FROZEN_PARAMS),
        derive_seed(7, {**FROZEN_PARAMS, "trial": 2}),
        derive_seed(7, {**FROZEN_PARAMS, "rate": 0.25000000000000006}),
        derive_seed(7, {**FROZEN_PARAMS, "noise": 5.0}),
        derive_seed(7, {**FROZEN_PARAMS, "extra": None}),
    }
    assert len(seeds) == 6
    trial_seeds = {p["trial"]: derive_seed(0, p) for p in expand_grid({}, {}, trials=50)}
    assert len(set(trial_seeds.values())) == 50


@pytest.mark.parametrize(
    ("seed", "params", "match"),
    [
        ("1", {}, "seed must be an integer"),
        (True, {}, "seed must be an integer"),
        (1, [("a", 1)], "params must be a dict"),
        (1, {"a": object()}, "unsupported type object"),
        (1, {"a": {1: 2}}, "is not a string"),
    ],
)
def test_derive_seed_rejects_bad_input(seed, params, match):
    with pytest.raises(ConfigError, match=match):
        derive_seed(seed, params)


# ---------------------------------------------------------------------------------------------
# run_sweep: local
# ---------------------------------------------------------------------------------------------


def test_run_sweep_rows_seeds_and_cache_files(tmp_path):
    rows = run_sweep(toy, POINTS, tmp_path / "out", seed=3, progress=False)
    assert len(rows) == len(POINTS)
    for point, row in zip(POINTS, rows, strict=True):
        assert row["x"] == point["x"] and row["trial"] == point["trial"]
        assert row["seed"] == derive_seed(3, point)
        # Results are JSON-normalized: numpy values become plain Python ones.
        assert type(row["stats"]["n"]) is int and row["curve"] == [0, point["x"], 2 * point["x"]]
    assert len({row["value"] for row in rows}) == len(rows)  # trials differ
    assert "seed" not in POINTS[0]  # caller's points are not modified
    files = sorted((tmp_path / "out" / "runs").glob("*.json"))
    params = [{k: r[k] for k in ("size", "x", "trial", "seed")} for r in rows]
    assert [f.stem for f in files] == sorted(point_key(p) for p in params)
    record = json.loads(files[0].read_text())
    assert set(record) >= {"key", "params", "result"} and record["key"] == files[0].stem
    assert not list((tmp_path / "out" / "runs").glob(".*"))  # no temporary files left


def test_cached_rows_keep_the_columns_and_their_order(tmp_path):
    # toy's result keys are not in alphabetical order ("value", "stats", "curve"): a rerun
    # served from the cache must give the same rows with the same key order, and the same CSV
    fresh = run_sweep(toy, POINTS, tmp_path / "out", seed=3, progress=False)
    cached = run_sweep(toy, POINTS, tmp_path / "out", seed=3, progress=False)
    assert cached == fresh
    assert [list(r) for r in cached] == [list(r) for r in fresh]
    assert list(fresh[0]).index("value") < list(fresh[0]).index("curve")
    a = sweep.write_csv(fresh, tmp_path / "fresh.csv").read_text()
    assert sweep.write_csv(cached, tmp_path / "cached.csv").read_text() == a


def test_run_sweep_jobs_1_and_2_give_identical_rows(tmp_path):
    serial = run_sweep(toy, POINTS, tmp_path / "a", seed=11, jobs=1, progress=False)
    parallel = run_sweep(toy, POINTS, tmp_path / "b", seed=11, jobs=2, progress=False)
    assert serial == parallel
    # Same rows when the points are given in another order: seeds don't depend on order.
    shuffled = run_sweep(toy, POINTS[::-1], tmp_path / "c", seed=11, progress=False)
    assert shuffled[::-1] == serial


def test_run_sweep_explicit_seed_is_kept(tmp_path):
    points = expand_grid({}, {"x": [1], "seed": [5, 6]})
    rows = run_sweep(toy, points, tmp_path, seed=0, progress=False)
    assert [row["seed"] for row in rows] == [5, 6]
    rng = np.random.default_rng(5)
    assert rows[0]["value"] == 10.0 + rng.normal()


def test_run_sweep_seed_ignore_pairs_points(tmp_path):
    # points that differ only in an ignored key share their seed (paired comparisons), and
    # still are separate runs with their own cache entries
    points = expand_grid({"x": 1}, {"method": ["a", "b"], "y": [1, 2]})
    rows = run_sweep(toy, points, tmp_path, seed=3, progress=False, seed_ignore=["method"])
    seeds = {(r["method"], r["y"]): r["seed"] for r in rows}
    assert seeds["a", 1] == seeds["b", 1] == derive_seed(3, {"x": 1, "y": 1, "trial": 0})
    assert seeds["a", 2] == seeds["b", 2] != seeds["a", 1]
    assert len(list((tmp_path / "runs").glob("*.json"))) == 4
    plain = run_sweep(toy, points, tmp_path / "plain", seed=3, progress=False)
    assert plain[0]["seed"] != plain[2]["seed"]  # without seed_ignore: every point its own
    with pytest.raises(ConfigError, match="not a string"):
        run_sweep(toy, points, tmp_path, seed_ignore="method", progress=False)


def test_run_sweep_resumes_after_interruption(tmp_path):
    calls_dir = tmp_path / "calls"
    out = tmp_path / "out"
    points = expand_grid({}, {"x": [1, 2, 3, 4]})
    func = functools.partial(interrupting, calls_dir=str(calls_dir), stop_x=3)
    with pytest.raises(KeyboardInterrupt):
        run_sweep(func, points, out, progress=False)
    assert sorted(c["x"] for c in calls(calls_dir)) == [1, 2]
    assert len(list((out / "runs").glob("*.json"))) == 2  # finished runs were kept

    for f in calls_dir.iterdir():
        f.unlink()
    func = functools.partial(counting, calls_dir=str(calls_dir))
    rows = run_sweep(func, points, out, progress=False)
    assert sorted(c["x"] for c in calls(calls_dir)) == [3, 4]  # only the missing points
    assert [row["x"] for row in rows] == [1, 2, 3, 4] and all("error" not in r for r in rows)
    assert rows == run_sweep(toy, points, tmp_path / "fresh", progress=False)

    for f in calls_dir.iterdir():
        f.unlink()
    assert run_sweep(func, points, out, progress=False) == rows
    assert calls(calls_dir) == []  # fully cached: nothing recomputed


def test_run_sweep_failures_are_recorded_not_cached_and_retried(tmp_path):
    calls_dir = tmp_path / "calls"
    out = tmp_path / "out"
    points = expand_grid({}, {"x": [1, 2, 3]})
    func = functools.partial(counting, calls_dir=str(calls_dir), fail_x=2)
    rows = run_sweep(func, points, out, progress=False)
    assert rows[1]["error"] == "ValueError: bad x 2"
    assert rows[1]["x"] == 2 and "value" not in rows[1]
    assert "error" not in rows[0] and "error" not in rows[2]
    assert len(list((out / "runs").glob("*.json"))) == 2

    for f in calls_dir.iterdir():
        f.unlink()
    rows = run_sweep(functools.partial(counting, calls_dir=str(calls_dir)), points, out)
    assert [c["x"] for c in calls(calls_dir)] == [2]  # only the failed point is retried
    assert all("error" not in row for row in rows)


def test_run_sweep_bad_results_are_failures(tmp_path):
    rows = run_sweep(not_a_dict, [{"x": 1}], tmp_path / "a", progress=False)
    assert rows[0]["error"] == "TypeError: func returned list, expected a dict"
    rows = run_sweep(unserializable, [{"x": 1}], tmp_path / "b", progress=False)
    assert rows[0]["error"].startswith("TypeError: result.obj has unsupported type object")
    assert not list((tmp_path / "b" / "runs").glob("*.json"))


def test_run_sweep_failures_with_jobs_2(tmp_path):
    func = functools.partial(counting, calls_dir=str(tmp_path / "calls"), fail_x=2)
    rows = run_sweep(func, POINTS, tmp_path / "out", jobs=2, progress=False)
    assert [("error" in row) for row in rows] == [x == 2 for x in (1, 1, 2, 2, 3, 3)]
    assert len(list((tmp_path / "out" / "runs").glob("*.json"))) == 4


def test_run_sweep_recomputes_mismatched_or_corrupt_cache(tmp_path):
    calls_dir = tmp_path / "calls"
    func = functools.partial(counting, calls_dir=str(calls_dir))
    points = expand_grid({}, {"x": [1, 2, 3]})
    first = run_sweep(func, points, tmp_path, progress=False)
    files = {json.loads(f.read_text())["params"]["x"]: f for f in (tmp_path / "runs").iterdir()}
    record = json.loads(files[1].read_text())
    record["params"]["x"] = 10  # edited (or a hash collision)
    record["result"]["value"] = -1.0
    files[1].write_text(json.dumps(record))
    files[2].write_text('{"params": ')  # truncated by hand
    for f in calls_dir.iterdir():
        f.unlink()
    second = run_sweep(func, points, tmp_path, progress=False)
    assert sorted(c["x"] for c in calls(calls_dir)) == [1, 2]
    assert second == first
    assert json.loads(files[1].read_text())["params"]["x"] == 1  # repaired


def test_run_sweep_runs_again_a_record_whose_result_was_edited(tmp_path):
    """A cached record's result edited by hand (``depth_rmse_m`` set to 123.0) was read back
    into ``results.csv`` on resume (an outside audit of 2026-12-02): each record keeps its
    result's checksum, and one that no longer matches is run again; a record of an earlier
    version, without the checksum, is read as before."""
    calls_dir = tmp_path / "calls"
    func = functools.partial(counting, calls_dir=str(calls_dir))
    points = expand_grid({}, {"x": [1, 2, 3]})
    first = run_sweep(func, points, tmp_path, progress=False)
    files = {json.loads(f.read_text())["params"]["x"]: f for f in (tmp_path / "runs").iterdir()}
    assert all("result_sha256" in json.loads(f.read_text()) for f in files.values())
    edited = json.loads(files[1].read_text())
    edited["result"]["value"] = 123.0
    files[1].write_text(json.dumps(edited))
    older = json.loads(files[3].read_text())
    del older["result_sha256"]
    files[3].write_text(json.dumps(older))
    for f in calls_dir.iterdir():
        f.unlink()
    second = run_sweep(func, points, tmp_path, progress=False)
    assert [c["x"] for c in calls(calls_dir)] == [1]
    assert second == first and 123.0 not in [r.get("value") for r in second]


def test_run_sweep_duplicate_points_computed_once(tmp_path):
    calls_dir = tmp_path / "calls"
    func = functools.partial(counting, calls_dir=str(calls_dir))
    rows = run_sweep(func, [{"x": 1}, {"x": 1}], tmp_path, progress=False)
    assert len(calls(calls_dir)) == 1 and rows[0] == rows[1] and rows[0] is not rows[1]


def test_run_sweep_progress_bar_when_not_a_tty(tmp_path, capsys):
    rows = run_sweep(toy, POINTS[:2], tmp_path, progress=True)
    assert len(rows) == 2 and "error" not in rows[0]
    # no bar without a terminal, but the plain progress line of the last run
    err = capsys.readouterr().err
    assert "sweep: 2/2 runs done" in err and "\r" not in err


@pytest.mark.parametrize(
    ("kwargs", "points", "match"),
    [
        ({"jobs": 0}, [{"x": 1}], "--jobs must be a positive number"),
        ({"jobs": "2"}, [{"x": 1}], "jobs must be an integer"),
        ({"seed": 1.5}, [{"x": 1}], "seed must be an integer"),
        ({}, [{"x": 1}, 3], "point 1 must be a dict"),
        ({}, [{"x": {1, 2}}], "point 0.x has unsupported type set"),
        ({"scheduler": 42}, [{"x": 1}], "scheduler must be an address"),
    ],
)
def test_run_sweep_rejects_bad_input(tmp_path, kwargs, points, match):
    with pytest.raises(ConfigError, match=match):
        run_sweep(toy, points, tmp_path, progress=False, **kwargs)


def test_run_sweep_out_dir_created_or_rejected(tmp_path):
    out = tmp_path / "deep" / "out"
    run_sweep(toy, [{"x": 1}], out, progress=False)
    assert len(list((out / "runs").glob("*.json"))) == 1
    a_file = tmp_path / "file"
    a_file.write_text("")
    with pytest.raises(ConfigError, match="not a folder"):
        run_sweep(toy, [{"x": 1}], a_file, progress=False)


# ---------------------------------------------------------------------------------------------
# run_sweep: Dask
# ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def dask_cluster():
    import distributed
    cluster = distributed.LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None
    )
    try:
        yield cluster
    finally:
        cluster.close()


def test_run_sweep_on_dask_matches_local(tmp_path, dask_cluster):
    import distributed

    local = run_sweep(toy, POINTS, tmp_path / "local", seed=4, progress=False)
    with distributed.Client(dask_cluster) as client:
        on_client = run_sweep(
            toy, POINTS, tmp_path / "client", seed=4, scheduler=client, progress=False
        )
        assert client.status == "running"  # a client we were given is not closed
    assert on_client == local
    on_cluster = run_sweep(
        toy, POINTS, tmp_path / "cluster", seed=4, scheduler=dask_cluster, progress=False
    )
    assert on_cluster == local
    address = dask_cluster.scheduler_address
    by_address = run_sweep(toy, POINTS, tmp_path / "addr", seed=4, scheduler=address)
    assert by_address == local
    assert len(list((tmp_path / "addr" / "runs").glob("*.json"))) == len(POINTS)


def test_run_sweep_on_dask_records_failures_and_resumes(tmp_path, dask_cluster):
    calls_dir = tmp_path / "calls"
    func = functools.partial(counting, calls_dir=str(calls_dir), fail_x=3)
    rows = run_sweep(func, POINTS, tmp_path / "out", scheduler=dask_cluster, progress=False)
    assert [row.get("error") for row in rows][-2:] == ["ValueError: bad x 3"] * 2
    for f in calls_dir.iterdir():
        f.unlink()
    run_sweep(func, POINTS, tmp_path / "out", scheduler=dask_cluster, progress=False)
    assert sorted(c["x"] for c in calls(calls_dir)) == [3, 3]


def test_run_sweep_without_dask_installed(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(ConfigError, match=r"install spslidar\[dask\]"):
        run_sweep(toy, [{"x": 1}], tmp_path, scheduler="tcp://127.0.0.1:1", progress=False)
    # Fully cached sweeps and local runs never need dask.
    assert run_sweep(toy, [{"x": 1}], tmp_path, progress=False)[0]["x"] == 1


def test_run_sweep_empty_scheduler_address(tmp_path):
    import distributed  # noqa: F401 - a dependency of the tests (no skip)
    with pytest.raises(ConfigError, match="scheduler must be an address"):
        run_sweep(toy, [{"x": 1}], tmp_path, scheduler=" ", progress=False)


# ---------------------------------------------------------------------------------------------
# TOML sweep configs
# ---------------------------------------------------------------------------------------------

GOOD_TOML = """\
seed = 1
trials = 3
[base]          # any `spslidar run` config keys
size = 32
[base.scene]
depth = 2.5
[grid]          # each key a list of values
noise = [1, 5, 10]
code_length = [1023, 4095]
"""


def test_load_sweep_config(tmp_path):
    path = tmp_path / "sweep.toml"
    path.write_text(GOOD_TOML)
    spec = load_sweep_config(path)
    assert spec == SweepSpec(
        seed=1,
        trials=3,
        base={"size": 32, "scene": {"depth": 2.5}},
        grid={"noise": [1, 5, 10], "code_length": [1023, 4095]},
        path=path,
    )
    points = spec.points()
    assert len(points) == 3 * 2 * 3
    assert points[0] == {
        "size": 32,
        "scene": {"depth": 2.5},
        "noise": 1,
        "code_length": 1023,
        "trial": 0,
    }
    minimal = tmp_path / "minimal.toml"
    minimal.write_text("trials = 2\n[base]\nsize = 8\n")
    assert load_sweep_config(str(minimal)).points() == [{"size": 8, "trial": 0},
                                                         {"size": 8, "trial": 1}]


@pytest.mark.parametrize(
    ("text", "match"),
    [
        ("seed = 1\n[base\nsize = 3\n", r"sweep\.toml: invalid TOML: .*line 2"),
        ("[grid]\nnoise = 5\n", r"sweep\.toml: grid\.noise must be a non-empty list"),
        ("[grid]\nnoise = []\n", r"grid\.noise must be a non-empty list"),
        ("[grid]\nnoise = 'abc'\n", r"grid\.noise must be a non-empty list"),
        ("[grid]\ntrial = [1, 2]\n", "reserved"),
        ("[base]\ntrial = 1\n", "reserved"),
        ("[scene]\nsize = 3\n", r"unknown top-level table 'scene' \(allowed"),
        ("trails = 3\n", "unknown top-level key 'trails'"),
        ("seed = 'x'\n", "seed must be an integer"),
        ("seed = 1.5\n", "seed must be an integer"),
        ("trials = 0\n", "trials must be >= 1"),
        ("trials = true\n", "trials must be an integer"),
        ("base = 3\n", "base must be a table"),
        ("grid = [1, 2]\n", "grid must be a table"),
        ("trials = 2\n[base]\nseed = 4\n", "base.seed gives every trial the same noise"),
    ],
)
def test_load_sweep_config_rejects_bad_files(tmp_path, text, match):
    path = tmp_path / "sweep.toml"
    path.write_text(text)
    with pytest.raises(ConfigError, match=match) as info:
        load_sweep_config(path)
    assert "\n" not in str(info.value)


def test_load_sweep_config_missing_unreadable(tmp_path):
    with pytest.raises(ConfigError, match="sweep config not found: .*nope.toml"):
        load_sweep_config(tmp_path / "nope.toml")
    with pytest.raises(ConfigError, match="is a directory"):
        load_sweep_config(tmp_path)
    binary = tmp_path / "bin.toml"
    binary.write_bytes(b"\xff\xfe\x00")
    with pytest.raises(ConfigError, match="cannot read sweep config"):
        load_sweep_config(binary)


def test_base_seed_allowed_with_one_trial(tmp_path):
    path = tmp_path / "sweep.toml"
    path.write_text("[base]\nseed = 4\n[grid]\nx = [1, 2]\n")
    rows = run_sweep(toy, load_sweep_config(path).points(), tmp_path / "out", progress=False)
    assert [row["seed"] for row in rows] == [4, 4]


@pytest.mark.parametrize(("table", "said", "seeds"), [
    # (an outside audit of 2026-12-01: seed = 9 beside [base] seed = 4 ran seed 4 unsaid)
    ("[base]\nseed = 4\n[grid]\nx = [1, 2]\n", r"\[base\] seed = 4 sets", [4, 4]),
    # (one of 2026-12-03: beside [grid] seed = [0, 2], seeds 0 and 2 ran unsaid)
    ("[grid]\nseed = [0, 2]\nx = [1]\n", r"\[grid\] seed sets", [0, 2]),
])
def test_a_top_level_seed_that_a_table_overrides_is_said(tmp_path, table, said, seeds):
    """A top-level seed that [base] or [grid] overrides is said unused; without the
    top-level key, nothing is said."""
    import warnings

    path = tmp_path / "sweep.toml"
    path.write_text("seed = 9\n" + table)
    with pytest.warns(UserWarning, match=r"the top-level seed = 9 is not used: " + said
                      + r" every point's seed"):
        spec = load_sweep_config(path)
    assert sorted(p["seed"] for p in spec.points()) == seeds
    path.write_text(table)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_sweep_config(path)


# ---------------------------------------------------------------------------------------------
# write_csv and sweep_main
# ---------------------------------------------------------------------------------------------


def read_csv(path: Path) -> tuple[list[str], list[dict[str, str]]]:
    with open(path, newline="") as fh:
        reader = csv.DictReader(fh)
        return list(reader.fieldnames or []), list(reader)


def test_write_csv_columns_and_flattening(tmp_path):
    rows = [
        {"x": 1, "error": "ValueError: boom", "scene": {"depth": 2.5}},
        {"x": 2, "scene": {"depth": 3.0, "albedo": {"r": 0.5}}, "curve": [1, 2], "rmse": 0.1},
        {"x": np.int64(3), "rmse": np.float64(0.30000000000000004), "note": None, "flag": True},
    ]
    path = write_csv(rows, tmp_path / "r.csv")
    columns, data = read_csv(path)
    assert columns == [
        "x",
        "scene.depth",
        "scene.albedo.r",
        "curve",
        "rmse",
        "note",
        "flag",
        "error",
    ]
    assert len(data) == 3
    assert data[0]["error"] == "ValueError: boom" and data[0]["rmse"] == ""
    assert data[1]["scene.albedo.r"] == "0.5" and json.loads(data[1]["curve"]) == [1, 2]
    assert data[2]["x"] == "3" and float(data[2]["rmse"]) == 0.30000000000000004
    assert data[2]["note"] == "" and data[2]["flag"] == "True"
    assert [p.name for p in tmp_path.iterdir()] == ["r.csv"]  # no temporary file left


def test_write_csv_rejects_clashing_columns_and_keeps_old_file(tmp_path):
    path = tmp_path / "r.csv"
    path.write_text("old\n")
    with pytest.raises(ConfigError, match="appears twice"):
        write_csv([{"a.b": 1, "a": {"b": 2}}], path)
    with pytest.raises(ConfigError, match="row 0 must be a dict"):
        write_csv([[1, 2]], path)
    assert path.read_text() == "old\n"


def test_sweep_main_writes_results_and_counts_failures(tmp_path, capsys):
    config = tmp_path / "sweep.toml"
    config.write_text("seed = 2\ntrials = 2\n[base]\nsize = 8\n[grid]\nx = [1, 2, 3]\n")
    out = tmp_path / "out"
    func = functools.partial(counting, calls_dir=str(tmp_path / "calls"), fail_x=2)
    failures = sweep_main(config, out, progress=False, func=func)
    assert failures == 2
    err = capsys.readouterr().err
    assert "6 runs, 4 ok, 2 failed" in err and "x=2" in err and "ValueError: bad x 2" in err
    columns, data = read_csv(out / "results.csv")
    assert columns[:4] == ["size", "x", "trial", "seed"] and columns[-1] == "error"
    assert "stats.mean" in columns and "value" in columns
    assert [d["error"] != "" for d in data] == [False, False, True, True, False, False]
    expected = run_sweep(toy, load_sweep_config(config).points(), tmp_path / "o2", seed=2)
    assert [float(d["value"]) for d in data if not d["error"]] == [
        r["value"] for r in expected if r["x"] != 2
    ]
    assert sweep_main(config, out, progress=False, jobs=2, func=toy) == 0


def test_sweep_main_interrupted_writes_no_csv(tmp_path):
    config = tmp_path / "sweep.toml"
    config.write_text("[grid]\nx = [1, 2, 3]\n")
    func = functools.partial(interrupting, calls_dir=str(tmp_path / "calls"), stop_x=2)
    with pytest.raises(KeyboardInterrupt):
        sweep_main(config, tmp_path / "out", progress=False, func=func)
    assert not (tmp_path / "out" / "results.csv").exists()
    assert len(list((tmp_path / "out" / "runs").glob("*.json"))) == 1


# ---------------------------------------------------------------------------------------------
# run_point (spslidar.pipeline.run_metrics)
# ---------------------------------------------------------------------------------------------


def test_run_point_calls_pipeline_run_metrics(monkeypatch):
    import spslidar.pipeline as pipeline  # (a skip guarded it, which a deletion passed)

    assert callable(pipeline.run_metrics)
    seen = []

    def fake(config):
        seen.append(config)
        return {"depth_rmse_m": 0.5}

    monkeypatch.setattr(pipeline, "run_metrics", fake)
    assert run_point({"size": 8, "seed": 3, "trial": 1}) == {"depth_rmse_m": 0.5}
    assert seen == [{"size": 8, "seed": 3}]  # trial is folded into the seed, not passed on
    assert sweep.run_point is run_point


def test_run_point_runs_the_real_pipeline():
    import spslidar.pipeline as pipeline  # (a skip guarded it, which a deletion passed)

    assert callable(pipeline.run_metrics)
    metrics = run_point({"size": 16, "seed": derive_seed(0, {"size": 16}), "trial": 0})
    assert np.isfinite(metrics["depth_rmse_m"]) and metrics["depth_rmse_m"] >= 0
    json.dumps(metrics)  # cacheable as is


# ---------------------------------------------------------------------------------------------
# Files follow the umask (tempfile.mkstemp alone would make them 0600)
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("umask", [0o022, 0o077, 0o002])
def test_written_files_follow_the_umask(tmp_path, umask):
    import stat

    old = os.umask(umask)
    try:
        rows = run_sweep(toy, expand_grid({"x": 1}, {}, 1), tmp_path, progress=False)
        csv_path = write_csv(rows, tmp_path / "results.csv")
        text_path = tmp_path / "note.txt"
        sweep.atomic_write_text(text_path, "a\r\nb\n")
        bytes_path = tmp_path / "blob.bin"
        sweep.atomic_write_bytes(bytes_path, b"\x00\x01")
    finally:
        os.umask(old)
    expected = 0o666 & ~umask
    for path in [csv_path, text_path, bytes_path, *(tmp_path / "runs").iterdir()]:
        assert stat.S_IMODE(path.stat().st_mode) == expected, path.name
    assert text_path.read_bytes() == b"a\r\nb\n"  # written as given, no newline translation
    assert bytes_path.read_bytes() == b"\x00\x01"
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []


def test_atomic_write_leaves_nothing_on_failure(tmp_path, monkeypatch):
    target = tmp_path / "kept.txt"
    sweep.atomic_write_text(target, "old")

    def broken(src, dst):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", broken)
    with pytest.raises(OSError, match="disk full"):
        sweep.atomic_write_text(target, "new")
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["kept.txt"]


def test_progress_lines_without_a_terminal(tmp_path, capsys, monkeypatch):
    """Without a terminal (a log file, CI) tqdm is silent: a plain line every few seconds
    and one at the end (issue 24, item 7: reproduce fig4 ran 136 s silently)."""
    import spslidar.experiments.sweep.engine as engine

    monkeypatch.setattr(engine, "PLAIN_PROGRESS_S", 0.0)
    rows = engine.run_sweep(lambda p: {"y": p["x"]}, [{"x": i} for i in range(3)], tmp_path,
                            progress=True)
    assert len(rows) == 3
    lines = [x for x in capsys.readouterr().err.splitlines() if x.startswith("sweep: ")]
    assert lines[-1].startswith("sweep: 3/3 runs done") and len(lines) == 3


# ---------------------------------------------------------------------------------------------
# The pipeline's sweeps on grids a user writes (an audit of 2026-11-28)
# ---------------------------------------------------------------------------------------------


def _pipeline_sweep(tmp_path, grid: str, name: str = "s") -> tuple[int, list[dict]]:
    config = tmp_path / f"{name}.toml"
    config.write_text(f"seed = 1\n[base]\nsize = 8\ncode_length = 63\ndepth = 'argmax'\n"
                      f"[grid]\n{grid}\n")
    out = tmp_path / f"{name}_out"
    failed = sweep_main(config, out, progress=False)
    with open(out / "results.csv", newline="") as fh:
        return failed, list(csv.DictReader(fh))


def test_an_option_the_configuration_ignores_shares_the_seed(tmp_path, capsys):
    """rep_rate does nothing to a PSST lidar, but its two values got two seeds: RMSE 0.31
    against 0.25 m, an effect that was not there, and no word."""
    failed, rows = _pipeline_sweep(tmp_path, "rep_rate = [1e6, 2e6]")
    assert failed == 0 and len(rows) == 2
    assert rows[0]["seed"] == rows[1]["seed"]
    assert rows[0]["depth_rmse_m"] == rows[1]["depth_rmse_m"]
    assert "--rep-rate 1e+06 is ignored" in capsys.readouterr().err


def test_a_hyphenated_key_is_the_key_a_run_reads(tmp_path):
    """A grid over "lam-scale" drew another seed for each weight, where lam_scale pairs them,
    and named its column as spelled (an outside audit of 2026-12-01)."""
    path = tmp_path / "hyphens.toml"
    path.write_text('[base]\ncode-length = 1023\n[grid]\n"lam-scale" = [0.2, 0.6]\n')
    points = load_sweep_config(path).points()
    assert all(p["lam_scale"] in (0.2, 0.6) and p["code_length"] == 1023 for p in points)
    assert not any("lam-scale" in p or "code-length" in p for p in points)
    path.write_text('[grid]\nlam_scale = [0.2]\n"lam-scale" = [0.6]\n')
    with pytest.raises(ConfigError, match=r"grid: key 'lam_scale' given twice \('lam_scale' "
                                          r"and 'lam-scale'\)"):
        load_sweep_config(path)


def test_a_hyphenated_grid_key_pairs_its_points_as_the_underscored_one(tmp_path):
    runs = {}
    for spelling in ("lam_scale", "lam-scale"):
        failed, rows = _pipeline_sweep(tmp_path, f'"{spelling}" = [0.2, 0.6]',
                                       name=spelling.replace("-", "h"))
        assert failed == 0 and "lam-scale" not in rows[0]
        runs[spelling] = [(r["lam_scale"], r["seed"], r["depth_rmse_m"]) for r in rows]
    assert runs["lam_scale"] == runs["lam-scale"]
    assert runs["lam_scale"][0][1] == runs["lam_scale"][1][1]  # one seed: paired


def test_one_and_one_point_zero_are_one_point(tmp_path, capsys):
    """noise = 1 and noise = 1.0 got different seeds (a sweep written either way did not
    reproduce the other), and a value listed twice ran twice and counted twice."""
    _, a = _pipeline_sweep(tmp_path, "noise = [1, 3]", "a")
    _, b = _pipeline_sweep(tmp_path, "noise = [1.0, 3.0]", "b")
    assert [r["seed"] for r in a] == [r["seed"] for r in b]
    assert [r["depth_rmse_m"] for r in a] == [r["depth_rmse_m"] for r in b]
    with pytest.raises(ConfigError, match=r"grid.noise lists the same value twice \(1 and 1.0\)"):
        _pipeline_sweep(tmp_path, "noise = [1, 3, 1.0]", "c")


def test_a_whole_float_seeds_as_its_int_and_other_seeds_are_unchanged():
    """Only whole floats are rewritten: every other point keeps the seed it had (cached and
    published sweeps stay as they were)."""
    from spslidar.experiments.sweep.grid import same_value

    assert same_value(1.0) == 1 and same_value(np.float64(3.0)) == 3
    assert same_value(0.25) == 0.25 and same_value(True) is True and same_value("1.0") == "1.0"
    assert derive_seed(7, {k: same_value(v) for k, v in FROZEN_PARAMS.items()}) == FROZEN_SEED


def test_a_sweep_of_small_runs_counts_what_each_run_costs_anyway(tmp_path, capsys):
    """40 runs at 16x16 on 255 bits were estimated at 0.43 s (their solves) and took 13 s,
    so --max-time 0.5s did not stop them: each run's fixed cost (scene, depth, metrics) is
    now in the estimate."""
    config = tmp_path / "m.toml"
    config.write_text("trials = 20\n[base]\nsize = 16\ncode_length = 255\n[grid]\n"
                      "noise = [1, 2]\n")
    from spslidar.errors import SpslidarError

    with pytest.raises(SpslidarError, match="would take"):
        sweep_main(config, tmp_path / "o", progress=False, max_time=0.5)
    assert not (tmp_path / "o").exists()


def test_a_sweep_does_not_replace_another_sweeps_table_written_meanwhile(tmp_path):
    """Two sweeps into one folder at once: both said "results in" and the table held the
    second's points (an outside audit of 2026-11-29). The one that finishes second finds
    the other's table and says so; its runs stay cached."""
    from spslidar.errors import SpslidarError
    from spslidar.experiments.sweep.command import sweep_main

    out = tmp_path / "out"
    for name, values in (("a", "[1, 2]"), ("b", "[3, 4]")):
        (tmp_path / f"{name}.toml").write_text(f"seed = 1\n[grid]\nx = {values}\n")
    calls = []

    def point(params):
        if not calls:  # the other sweep runs and writes its table while this one works
            calls.append(1)
            assert sweep_main(tmp_path / "b.toml", out, progress=False,
                              func=lambda p: {"y": p["x"]}) == 0
        return {"y": params["x"]}

    with pytest.raises(SpslidarError, match="another sweep .* while this sweep ran"):
        sweep_main(tmp_path / "a.toml", out, progress=False, func=point)
    with open(out / "results.csv") as f:
        assert sorted(r["x"] for r in csv.DictReader(f)) == ["3", "4"]
