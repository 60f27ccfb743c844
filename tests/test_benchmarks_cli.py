"""The benchmark scripts as a user runs them: a bad value is one line on stderr and exit 2,
before any work (an audit of 2026-11-28 found tracebacks, empty tables with exit 0, and a
missing --out folder found only after 17 s of work)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

BENCH = Path(__file__).resolve().parent.parent / "benchmarks"


@pytest.mark.parametrize("script,args,said", [
    ("depth_quality.py", ["--size", "-64"], "--size"),
    ("depth_quality.py", ["--scenes", "nosuch"], "unknown scene 'nosuch'"),
    ("depth_quality.py", ["--out", "/nonexistent-folder/x.md"], "does not exist"),
    ("instrument.py", ["--seeds", "-1"], "--seeds"),
    ("lambda_sweep.py", ["--solver", "foo"], "--solver"),
    ("depth_bounds.py", ["--scenes", "foo"], "unknown scene 'foo'"),
    ("solvers.py", ["--size", "-8"], "--size"),
    ("fused_tv_prox.py", ["--inner", "-1"], "--inner"),
    ("run_standard.py", ["--seed", "-1"], "--seed"),
    ("backends.py", ["--backends", "numpy"], "BACKEND:DEVICE"),
    ("backends.py", ["--repeat", "0"], "--repeat"),
    ("scale.py", ["--sizes", "100", "--kinds", "hadamard"], "power of two"),
    ("scale.py", ["--compressions", "2"], "--compressions"),
    # (each was ignored, or found after the whole benchmark: an audit of 2026-11-29)
    ("depth_quality.py", ["--draw", "1"], "--draw"),
    ("depth_quality.py", ["--procedural", "3", "--seed", "5"], "--seed"),
    ("solvers.py", ["--quick", "--table1-size", "3"], "size 3"),
    ("ptu_read.py", ["--records", "0"], "--records"),
    ("ptu_read.py", ["--record-type", "PicoHarpT3", "--bins", "5000"], "below 4096"),
    ("gmapd_model.py", ["--bins", "1000"], "2^n - 1"),
    ("gmapd_model.py", ["--dead-times", "5e-8,1.5e-10"], "whole 100 ps bins"),
    ("gmapd_model.py", ["--dead-times", "fast"], "--dead-times"),
    ("depth_quality.py", ["--plugin", "nosuch_plugin_module"], "nosuch_plugin_module"),
    # (a cache folder that cannot be made: a traceback after the work, as root; an audit)
    ("depth_quality.py", ["--size", "8", "--scenes", "steps", "--noise", "1", "--compression",
                          "0.5", "--estimators", "argmax", "--cache", "/proc/x"], "/proc"),
])
def test_a_bad_value_is_one_line_and_exit_2(script, args, said, tmp_path):
    if not BENCH.is_dir():
        pytest.skip("the benchmarks are not in this checkout")
    done = subprocess.run([sys.executable, str(BENCH / script), *args], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    err = done.stderr.strip().splitlines()
    assert done.returncode == 2, done.stderr
    assert len(err) == 1 and err[0].startswith(f"{script}: error: ") and said in err[0], err
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_depth_quality_caches_inside_its_folder_by_the_scenes_content(tmp_path):
    """An absolute scene path wrote its cache beside the scene, and a scene file rewritten
    gave its old slices (an audit of 2026-11-29)."""
    if not BENCH.is_dir():
        pytest.skip("the benchmarks are not in this checkout")
    import numpy as np

    scene, cache = tmp_path / "scene" / "plane.npy", tmp_path / "cache"
    scene.parent.mkdir()
    import re

    def argmax_rmse(*extra):
        done = subprocess.run(
            [sys.executable, str(BENCH / "depth_quality.py"), "--size", "8", "--scenes",
             str(scene), "--noise", "1", "--compression", "0.5", "--estimators", "argmax",
             *extra], cwd=tmp_path, capture_output=True, text=True, timeout=300)
        assert done.returncode == 0, done.stderr
        return re.search(r"argmax (\d+\.\d+)", done.stderr).group(1)

    np.save(scene, np.linspace(10, 11, 64).reshape(8, 8))
    argmax_rmse("--cache", str(cache))
    np.save(scene, np.full((8, 8), 10.0))
    assert argmax_rmse("--cache", str(cache)) == argmax_rmse()  # the new content's, not cached
    assert sorted(p.name for p in scene.parent.iterdir()) == ["plane.npy"]
    assert len(list(cache.iterdir())) == 2  # one case per content


def test_depth_quality_takes_a_users_estimator_by_plugin(tmp_path):
    """A user's own estimator had no way into the benchmark but SPSLIDAR_PLUGINS, which
    nothing said (an outside audit): --plugin makes it a choice, ranked against argmax."""
    if not BENCH.is_dir():
        pytest.skip("the benchmarks are not in this checkout")
    (tmp_path / "mine.py").write_text(
        "from spslidar.depth import ESTIMATORS\n"
        "from spslidar.depth.argmax import ArgmaxDepth\n\n\n"
        "class Mine(ArgmaxDepth):\n    name = 'mine'\n\n\n"
        "ESTIMATORS.add('mine', Mine, 'mine', 'argmax under another name')\n")
    done = subprocess.run(
        [sys.executable, str(BENCH / "depth_quality.py"), "--plugin", str(tmp_path / "mine.py"),
         "--size", "8", "--scenes", "steps", "--noise", "1", "--compression", "0.5",
         "--estimators", "mine"], cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    row = next(ln for ln in done.stdout.splitlines() if "| mine |" in ln)
    assert "| 1.000 | 1.000 (steps) |" in row  # (argmax under another name: ratio 1)


def test_ptu_read_benchmark_reads_what_the_peer_reads(tmp_path):
    """The reader benchmark on a small file: both readers' histograms equal (the script
    exits 1 with a line otherwise), and its table has both rows."""
    if not BENCH.is_dir():
        pytest.skip("the benchmarks are not in this checkout")
    done = subprocess.run([sys.executable, str(BENCH / "ptu_read.py"), "--records", "20000",
                           "--patterns", "8", "--bins", "127", "--repeat", "1"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "the histograms equal" in done.stdout
    assert "| spslidar `read_ptu_histograms` |" in done.stdout
    assert "| ptufile `decode_records` + NumPy |" in done.stdout


def test_gmapd_model_benchmark_agrees_with_its_peer(tmp_path):
    """The renewal model's benchmark on a short code: the model and the dense chain agree (the
    script exits 1 with a line otherwise), one table row per dead time."""
    if not BENCH.is_dir():
        pytest.skip("the benchmarks are not in this checkout")
    done = subprocess.run([sys.executable, str(BENCH / "gmapd_model.py"), "--bins", "127",
                           "--rows", "2", "--dead-times", "5e-9,2e-7"],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert "the two agree" in done.stdout
    assert "| 5 ns | 0.39 |" in done.stdout and "| 200 ns | 16 |" in done.stdout
