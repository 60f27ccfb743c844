"""The memory guard: a run that cannot fit is refused from its configuration, before work."""

import tracemalloc

import pytest

from spslidar import pipeline
from spslidar.cli import main
from spslidar.config import Config
from spslidar.errors import SpslidarError
from spslidar.pipeline import budget as budget_mod
from spslidar.pipeline.budget import Budget, available_memory, check_budget, estimate_budget


def _estimate(size=64, compression=0.25, period=2047, n_ulags=300, dense=True, **cfg):
    c = Config(size=size, compression=compression, **cfg)
    m = max(1, round(compression * size * size))
    return estimate_budget(c, n_patterns=m, period=period, n_lags=n_ulags, n_ulags=n_ulags,
                           window_bins=200, pattern_bytes_per_entry=4 if dense else None)


def _no_patterns(monkeypatch):
    """Make drawing the patterns an error: a refusal must come before any real work."""

    def boom(*a, **k):
        raise AssertionError("the patterns were drawn before the memory check")

    monkeypatch.setattr("spslidar.pipeline.chain.build_patterns", boom)


@pytest.mark.parametrize("args", [
    ["--size", "2048"],                                   # 4M pixels: hundreds of GB dense
    ["--size", "16", "--max-memory", "0.01"],              # an explicit limit below the run
    ["--size", "256", "--compression", "0.5"],             # dense 32768 x 65536 patterns
])
def test_refused_runs_are_one_line_exit_2_and_write_nothing(tmp_path, capsys, monkeypatch,
                                                            args):
    _no_patterns(monkeypatch)
    out = tmp_path / "out"
    assert main(["run", *args, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
    assert "memory" in err and ("GB" in err or "MB" in err)
    assert "--max-memory" in err
    assert not out.exists()


def test_estimate_grows_with_the_problem():
    small, big = _estimate(size=32), _estimate(size=64)
    assert big.bytes > small.bytes and big.seconds > small.seconds
    assert _estimate(compression=0.5).bytes > _estimate(compression=0.1).bytes
    # dense patterns are a large part; an implicit operator needs far less for them
    assert _estimate(size=128, dense=False).parts["patterns"] < \
        0.1 * _estimate(size=128).parts["patterns"]
    assert _estimate(dtype="float64").parts["solver"] == 2 * _estimate().parts["solver"]


def test_check_budget_limits():
    b = Budget(2e9, 10.0, {"patterns": 1.5e9, "solver": 0.5e9})
    check_budget(b, 3.0)  # fits
    with pytest.raises(SpslidarError, match=r"~2\.00 GB .*patterns, 1\.50 GB.*1\.00 GB "
                                            r"--max-memory"):
        check_budget(b, 1.0)
    # (1.22 against 1.2 read "needs ~1.2 GB ... more than the 1.2 GB"; 0.25 read "0.2 GB")
    with pytest.raises(SpslidarError, match=r"~1\.22 GB .* more than the 1\.20 GB"):
        check_budget(Budget(1.22e9, 1.0, {"patterns": 1e9}), 1.2)
    with pytest.raises(SpslidarError, match=r"more than the 0\.25 GB"):
        check_budget(b, 0.25)
    assert "patterns" in b.describe() and "10 s" in b.describe()


def test_available_memory_respects_rlimit(monkeypatch):
    import resource

    monkeypatch.setattr(resource, "getrlimit", lambda which: (123_000_000, -1))
    assert available_memory() == pytest.approx(123e6)
    assert available_memory.__module__ == "spslidar.machine"


def test_available_memory_without_proc_reads_psutil(monkeypatch):
    """Where there is no ``/proc/meminfo`` (macOS, Windows) the available memory is
    psutil's; Windows has no ``os.sysconf`` either, and every run was let through to fail in
    its allocation (a portability audit)."""
    import builtins
    import os
    import resource

    psutil = pytest.importorskip("psutil")
    real_open = builtins.open

    def no_proc(path, *args, **kwargs):
        if str(path).startswith("/proc"):
            raise FileNotFoundError(path)
        return real_open(path, *args, **kwargs)

    monkeypatch.setattr(builtins, "open", no_proc)
    monkeypatch.delattr(os, "sysconf")
    monkeypatch.setattr(resource, "getrlimit", lambda which: (-1, -1))
    monkeypatch.setattr(psutil, "virtual_memory", lambda: type("V", (), {"available": 5e9}))
    assert available_memory() == pytest.approx(5e9)


def test_estimate_covers_what_numpy_allocates():
    """The traced peak of a real run (NumPy's arrays, without the interpreter) stays below the
    estimate without its interpreter share: the model does not under-count the big arrays."""
    cfg = dict(size=48, compression=0.25, code_length=1023, seed=0)
    pipeline.run(cfg)  # imports and caches first: trace only what the run itself allocates
    tracemalloc.start()
    try:
        res = pipeline.run(cfg)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    est = res.metrics["estimate"]["memory_gb"] * 1e9
    assert peak < est - budget_mod.BASE_BYTES
    # and it is not absurdly loose either (within a factor of 20 of the arrays)
    assert est - budget_mod.BASE_BYTES < 20 * peak


def test_a_dense_matrix_that_cannot_fit_is_refused_before_the_scene_loads(monkeypatch, capsys,
                                                                          tmp_path):
    """--size 2048 with dense patterns: refused from the pattern matrix alone, before the
    scene (whose loading and resizing take a while at that size) is touched."""

    def no_scene(*a, **k):
        raise AssertionError("the scene was loaded before the memory check")

    monkeypatch.setattr("spslidar.pipeline.chain.load_scene", no_scene)
    out = tmp_path / "out"
    assert main(["run", "--size", "2048", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "patterns" in err and "GB" in err and not out.exists()


def test_the_time_estimate_counts_each_solvers_cap_and_the_dtypes_rate():
    """Every solver was priced at 100 iterations and every dtype at one rate: a 128x128
    Gaussian run priced at 152 s took 27 s. The solve's share follows the solver's own cap
    (FISTA 60, GPSR 120) and halves in float32 against float64."""
    from spslidar.pipeline.plan import preflight
    from spslidar.pipeline.weights import solver_default

    base = dict(scene="camera", size=32, compression=0.5, code_length=1023, auto_gate=False)
    overhead = preflight(**base, iterations=1).seconds  # one iteration: the rest of the run
    solve = {s: preflight(**base, solver=s).seconds - overhead for s in ("fista", "gpsr")}
    caps = {s: solver_default(s, "iterations") for s in solve}
    per_iteration = (preflight(**base, iterations=2).seconds - overhead)
    assert caps == {"fista": 60, "gpsr": 120}
    for s in solve:  # (cap - 1) iterations more than the one-iteration run
        assert solve[s] == pytest.approx((caps[s] - 1) * per_iteration, rel=1e-9)
    assert budget_mod.flop_rate("float32") == pytest.approx(2 * budget_mod.flop_rate("float64"))
    f32 = preflight(**base, iterations=1000).seconds
    f64 = preflight(**base, iterations=1000, dtype="float64").seconds
    assert f64 > 1.8 * f32  # the dense products dominate a long solve


def test_the_memory_estimate_counts_the_depth_estimators_working_set():
    """With 20 bytes per slice entry for every estimator, a 512x512 Hadamard run (10 %, the
    default mrf) was estimated at 1.69 GB and peaked at 1.95 GB (maximum RSS, 2026-11-28):
    the MRF's messages and data costs. Each estimator's registry entry gives its own."""
    from spslidar.depth import ESTIMATORS
    from spslidar.pipeline.plan import preflight

    bytes_of = {name: ESTIMATORS.get(name).defaults["slice_bytes"] for name in
                ("argmax", "censor", "mrf", "guarded", "evidence")}
    assert bytes_of["argmax"] < bytes_of["censor"] < bytes_of["mrf"] == bytes_of["guarded"]
    big = preflight(size=512, patterns="hadamard", compression=0.1)
    assert big.bytes > 1.95e9
    lean = preflight(size=512, patterns="hadamard", compression=0.1, depth="argmax")
    entries = big.parts["range slices"] / bytes_of["mrf"]  # Q x n_lags
    assert lean.parts["range slices"] == pytest.approx(bytes_of["argmax"] * entries, rel=1e-12)
    assert big.bytes - lean.bytes == pytest.approx(
        (bytes_of["mrf"] - bytes_of["argmax"]) * entries, rel=1e-9)


def test_a_floored_weights_longer_solve_is_priced_again_and_said(capsys, monkeypatch):
    """Where the weight meets its floor the solver runs five times its cap; the run had been
    announced at its configuration's price (a 512x512 Hadamard run announced at 47 s took
    145 s; a 256x256 one ran 106 s unannounced): the floored solve is priced again, said on
    stderr when long, and kept in metrics.json's estimate."""
    from spslidar.pipeline.weights import FLOORED_ITERATIONS

    monkeypatch.setattr(budget_mod, "ANNOUNCE_SECONDS", 0.0)
    r = pipeline.run(size=16, code_length=1023, noiseless=True, depth="argmax", seed=0)
    assert r.metrics["lam_floored"]
    assert r.metrics["solver_info"]["iterations"] <= 60 * FLOORED_ITERATIONS
    err = capsys.readouterr().err
    assert f"so the solve runs up to {60 * FLOORED_ITERATIONS} iterations" in err
    est = r.metrics["estimate"]
    assert est["time_s_at_floor"] > 0 and "time_s" in est
    r = pipeline.run(size=16, code_length=1023, noiseless=True, depth="argmax", seed=0,
                     iterations=60)
    assert "time_s_at_floor" not in r.metrics["estimate"]
    assert "the weight met its floor" not in capsys.readouterr().err


def test_the_time_estimate_counts_the_depth_stage_and_the_noise_verdict():
    """A 0-150 m gate at 64x64 took 17.3 s, 12 s of it the MRF and 3.5 s the noise verdict,
    where the estimate, which counted neither, said 2.5 s (an audit): each estimator's
    registry entry prices its time per pixel and gated slice, and a wide gate's estimate
    grows by that share."""
    from spslidar.depth import ESTIMATORS
    from spslidar.pipeline import preflight

    assert all("slice_seconds" in e.defaults for e in ESTIMATORS)
    mrf, argmax = (budget_mod.depth_seconds(d, 4096, 10_000) for d in ("mrf", "argmax"))
    assert mrf > 2 * argmax > 0  # (the noise verdict's share is the same for both)
    narrow = preflight({"range_gate": [19.0, 22.0]}).seconds
    wide = preflight({"range_gate": [0.0, 150.0]}).seconds
    n_extra = round(147.0 / 0.015)  # the wide gate's extra slices (1.5 cm bins)
    assert wide - narrow >= 0.9 * budget_mod.depth_seconds("mrf", 4096, n_extra)


def test_a_one_block_detector_model_is_priced_before_it_runs(tmp_path, monkeypatch, capsys):
    """A GMAPD run of one block of patterns (16x16: 64 patterns) was never priced: estimated
    at 0.13 s, it took 36 s (noiseless 275 s) without a word and past any --max-time (an
    audit of 2026-11-29). One pattern's model, on a stream of its own, now prices it."""
    import time

    import spslidar.pipeline.simulate as simulate
    from spslidar.cli import main

    calls = []

    def slow(*a, **k):
        calls.append(1)
        time.sleep(0.05)  # 16 patterns at 8x8: priced ~0.8 s
        return True

    monkeypatch.setattr(simulate, "_probe_row", slow)
    out = tmp_path / "o"
    assert main(["run", "--size", "8", "--detector", "gmapd", "--signal", "0.01", "--noise",
                 "0.001", "--max-time", "0.5", "--no-figure", "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "estimated from one pattern's model" in err and calls == [1]
    assert not out.exists()


def test_the_pricing_probe_takes_a_pattern_of_median_light():
    """The first pattern was probed: under a Hadamard order the all-on row, 1.9 times the mean
    light, and a 2.3 s run was priced at 6.6 s (a review). The probe takes the median row and
    says nothing itself where the model refuses (the block refuses with its own numbers)."""
    from types import SimpleNamespace

    import numpy as np

    import spslidar.pipeline.simulate as simulate
    from spslidar.errors import ConfigError
    from spslidar.patterns import as_patterns

    rows = np.array([[1.0, 1.0, 1.0, 1.0], [0.0, 0.0, 0.0, 1.0], [1.0, 1.0, 0.0, 0.0],
                     [1.0, 0.0, 0.0, 0.0], [0.0, 1.0, 1.0, 1.0]])
    seen = []

    from spslidar.detectors.base import DetectorModel

    class Model(DetectorModel):
        def detect(self, lam, rng, n, out=None):
            seen.append(float(lam.sum()))
            return lam, lam.sum(axis=1)

        def correct(self, counts, n, expected=False):
            return counts

    acq = SimpleNamespace(code=np.array([1, 0, 1]), signal_per_pulse=1.0, n_periods=1)
    shifts, weights = np.array([0]), np.ones((4, 1))
    code_matrix = simulate.shifted_codes(acq.code, shifts)
    args = (as_patterns(rows), weights, shifts, np.zeros(5), acq)
    assert simulate._probe_row(*args, Model(), False, code_matrix)
    assert seen == [2.0 * 2]  # the median row's light (2 mirrors) over the code's 2 pulses

    class Refusing(Model):
        def detect(self, lam, rng, n, out=None):
            raise ConfigError("saturated")

    assert simulate._probe_row(*args, Refusing(), False, code_matrix) is False
