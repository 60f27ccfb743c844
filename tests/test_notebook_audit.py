"""The Python API as a notebook uses it (an outside audit of 2026-11-29): runs in a thread
pool keep their own warnings and leave BLAS as they found it; results and measurements sent
through pickle or deepcopy keep their arrays read-only; stages pickle."""

from __future__ import annotations

import copy
import pickle
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from threadpoolctl import threadpool_info

import spslidar

SMALL = dict(scene="camera", size=16, code_length=255, iterations=30)


def _blas_threads() -> list[int]:
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]


def test_runs_in_threads_keep_their_own_warnings_and_blas():
    """A GPSR run on an odd side (the wavelet warns) beside a TV run, both in a thread pool,
    five times: the warning is the GPSR run's only; BLAS's threads are as before."""
    before = _blas_threads()
    odd = spslidar.measure(**dict(SMALL, size=15, solver="gpsr"))
    for _ in range(5):
        with ThreadPoolExecutor(2) as pool:
            a = pool.submit(spslidar.reconstruct, odd)
            b = pool.submit(spslidar.run, **SMALL)
            a, b = a.result(), b.result()
        assert any("wavelet" in w for w in a.warnings)
        assert not any("wavelet" in w for w in b.warnings)
    # (a BLAS library loaded meanwhile, SciPy's, starts at the same default)
    assert set(_blas_threads()) == set(before)


def test_runs_in_threads_equal_runs_in_turn():
    with ThreadPoolExecutor(2) as pool:
        threaded = list(pool.map(lambda s: spslidar.run(**SMALL, seed=s).depth, (1, 2, 3, 4)))
    for seed, depth in zip((1, 2, 3, 4), threaded, strict=True):
        np.testing.assert_array_equal(depth, spslidar.run(**SMALL, seed=seed).depth)


def test_a_results_lags_cannot_change_the_measurement():
    """``r.lags -= r.lags[0]`` (delays made relative for a plot) had made the next
    reconstruction of the same measurement 19.9 m off for 0.26."""
    m = spslidar.measure(**SMALL, seed=1)
    r = spslidar.reconstruct(m)
    with pytest.raises(ValueError, match="read-only"):
        r.lags -= r.lags[0]
    assert spslidar.reconstruct(m).depth_rmse == r.depth_rmse


@pytest.mark.parametrize("through", ["pickle", "deepcopy"])
def test_read_only_survives_pickle_and_deepcopy(through):
    m = spslidar.measure(**SMALL, seed=1)
    m2 = pickle.loads(pickle.dumps(m)) if through == "pickle" else copy.deepcopy(m)
    for arr in (m2.scene.depth, m2.scene.reflectivity, m2.scene.valid, m2.lags, m2.ulags,
                m2.inverse):
        assert not arr.flags.writeable
    r = spslidar.reconstruct(m2)
    with pytest.raises(ValueError, match="read-only"):
        r.scene.depth[:] += 1
    assert spslidar.reconstruct(m2).depth_rmse == r.depth_rmse


def test_objects_compare_and_print_as_a_notebook_expects():
    m = spslidar.measure(**SMALL, seed=1)
    r = spslidar.reconstruct(m)
    assert m == m and r == r and m.scene == m.scene  # (raised "truth value ... ambiguous")
    assert m != copy.deepcopy(m)  # identity: arrays are not compared
    for obj in (m, r, m.scene):
        assert len(repr(obj)) < 200 and type(obj).__name__ in repr(obj)
    assert "depth RMSE" in repr(r) and "16x16" in repr(m)


def test_a_valid_mask_of_other_numbers_is_refused():
    from spslidar.errors import SceneError
    from spslidar.scenes import Scene

    with pytest.raises(SceneError, match="valid mask must hold booleans or 0/1"):
        Scene("s", np.full((4, 4), 5.0), np.ones((4, 4)), np.full((4, 4), 0.3))
    Scene("s", np.full((4, 4), 5.0), np.ones((4, 4)), np.eye(4))  # 0/1 is a mask


def test_a_matrix_edited_after_it_is_wrapped_leaves_the_operator_as_it_was():
    """The transpose was a snapshot and the matrix a live reference: after the owner's edit
    the products and the adjoint were of two matrices (dottest failed)."""
    from spslidar.operators import MatrixOperator, dottest
    from spslidar.patterns import as_patterns

    a = np.random.default_rng(0).random((3, 4))
    a0 = a.copy()
    op, pats = MatrixOperator(a), as_patterns(a)
    a[0, 0] += 100
    dottest(op)
    np.testing.assert_array_equal(op.todense(), a0)
    np.testing.assert_array_equal(pats.todense(), a0)
    np.testing.assert_allclose(pats.rmatvec(np.ones((3, 1)))[:, 0], a0.T @ np.ones(3))


@pytest.mark.parametrize("bad, match", [
    (dict(A=np.eye(3) + 1j), "must be real"),
    (dict(A=np.eye(3), dtype=int), "real floating type"),
])
def test_a_matrix_operator_is_real(bad, match):
    from spslidar.operators import MatrixOperator

    with pytest.raises(ValueError, match=match):
        MatrixOperator(**bad)


@pytest.mark.parametrize("value", [np.nan, np.inf])
def test_patterns_with_a_nan_or_an_infinity_are_refused(value):
    from spslidar.patterns import as_patterns

    p = np.ones((4, 9))
    p[1, 2] = value
    with pytest.raises(ValueError, match="finite real transmittances"):
        as_patterns(p)


def test_a_plugin_cell_can_be_run_again_and_taken_back(tmp_path):
    """Registering a plugin again with another default replaces it (it was refused, with no
    way back but a new kernel); ``remove`` takes it back, leaving nothing of a cell run
    twice, and gives back a built-in it replaced; a built-in itself stays; a plugin loaded
    from a file is not taken for a built-in (a review of 2026-11-29)."""
    from spslidar.depth import ESTIMATORS
    from spslidar.depth.argmax import ArgmaxDepth
    from spslidar.errors import ConfigError
    from spslidar.plugins import load_plugins
    from spslidar.registry import Option

    class Mine(ArgmaxDepth):
        name = "mine"

    argmax = ESTIMATORS.get("argmax")
    try:
        ESTIMATORS.add("mine", Mine, "Mine", "t", options=(Option("mine_hw", 1, "hw", kind=int),))
        with pytest.warns(RuntimeWarning, match="replaced"):
            ESTIMATORS.add("mine", ArgmaxDepth, "Mine", "t",
                           options=(Option("mine_hw", 2, "hw", kind=int),))
        assert ESTIMATORS.get("mine").options[0].default == 2
        with pytest.warns(RuntimeWarning, match="replaced"):
            ESTIMATORS.add("argmax", Mine, "mine as argmax")
    finally:
        removed = [ESTIMATORS.remove(n) for n in ("mine", "argmax")]
    assert "mine" not in ESTIMATORS and removed[1].target is Mine
    assert ESTIMATORS.get("argmax") is argmax
    with pytest.raises(ConfigError, match="built in"):
        ESTIMATORS.remove("argmax")
    plug = tmp_path / "mystages.py"
    plug.write_text("from spslidar.depth import ESTIMATORS\n"
                    "from spslidar.depth.argmax import ArgmaxDepth\n"
                    "ESTIMATORS.add('fromfile', ArgmaxDepth, 'From a file')\n")
    try:
        load_plugins([str(plug)])
    finally:
        ESTIMATORS.remove("fromfile")
    assert "fromfile" not in ESTIMATORS


def test_the_wavelet_regulariser_pickles():
    from spslidar.solvers.regularisers import make_wavelet_l1

    reg = make_wavelet_l1((16, 16))
    x = np.random.default_rng(0).random((256, 2))
    for other in (pickle.loads(pickle.dumps(reg)), copy.deepcopy(reg)):
        np.testing.assert_array_equal(other.prox(x, 0.1), reg.prox(x, 0.1))


@pytest.mark.parametrize("key, near", [("pattern_sigma", "sigma"), ("hadamard_order", "order"),
                                       ("sigmaa", "sigma")])
def test_build_patterns_refuses_an_option_no_kind_takes(key, near):
    from spslidar.errors import ConfigError
    from spslidar.patterns import build_patterns

    with pytest.raises(ConfigError, match=f"no option '{key}': did you mean '{near}'"):
        build_patterns("gaussian", 8, 4, 0, **{key: 0.05})
    a = build_patterns("gaussian", 8, 4, 0, sigma=0.05).todense()  # its own: taken
    assert not np.array_equal(a, build_patterns("gaussian", 8, 4, 0).todense())


@pytest.mark.parametrize("call, match", [
    (lambda: __import__("spslidar.operators", fromlist=["x"]).MatrixOperator(np.eye(3))
     .matvec(np.ma.masked_array(np.ones(3), mask=[1, 0, 0])), "masked array"),
    (lambda: __import__("spslidar.operators", fromlist=["x"]).MatrixOperator(np.eye(3))
     .rmatvec(np.ones(3) + 1j), "complex"),
])
def test_operators_refuse_masks_and_complex_inputs(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_the_matched_filter_refuses_fractional_lags_and_a_bank_of_other_lags():
    from spslidar.correlate import matched_filter, replica_matrix

    rng = np.random.default_rng(0)
    hist, rep = rng.random((2, 16)), rng.random(16)
    lags = np.arange(10)
    with pytest.raises(ValueError, match="whole bins"):
        matched_filter(hist, rep, lags + 0.7)
    with pytest.raises(ValueError, match="whole bins"):
        matched_filter(hist, rep, np.array([1.0, np.nan]))
    with pytest.raises(ValueError, match="bank of shape"):
        matched_filter(hist, rep, lags, bank=replica_matrix(rep, lags[:3]))
    np.testing.assert_allclose(matched_filter(hist, rep, lags.astype(float)),
                               matched_filter(hist, rep, lags))  # whole floats: taken


@pytest.mark.parametrize("width", [0, -1e-10, "1e-10", None])
def test_a_bin_width_that_is_no_width_is_one_line(width):
    from spslidar.correlate import gate_lags
    from spslidar.depth import DepthContext
    from spslidar.errors import ConfigError

    with pytest.raises(ConfigError, match="bin_width must be a positive number"):
        gate_lags((1.0, 2.0), width)
    with pytest.raises(ConfigError, match="bin_width must be a positive number"):
        DepthContext((4, 4), np.arange(3), width, 0.5)


def test_every_random_stream_takes_a_seed_and_refuses_what_is_none():
    from spslidar.codes.sequences import make_code
    from spslidar.detectors import build_detector
    from spslidar.errors import ConfigError

    lam = np.full((2, 8), 0.001)  # (a flux a GMAPD works at)
    for name in ("linear", "gmapd"):
        det = build_detector(name)
        a, _ = det.detect(lam, 0)
        np.testing.assert_array_equal(a, det.detect(lam, np.random.default_rng(0))[0])
        det.detect(lam, None)
        with pytest.raises(ConfigError, match="rng must be"):
            det.detect(lam, 1.5)
    with pytest.raises(ValueError, match="lam must be"):
        build_detector("linear").detect(lam[0], 0)
    with pytest.raises(ValueError, match="n_periods"):
        build_detector("gmapd").detect(lam, 0, n_periods=0)
    for bad in (1.5, -1):
        with pytest.raises(ConfigError, match="rng must be"):
            make_code("random", 31, 0.5, rng=bad)


def test_return_amplitudes_take_a_pattern_operator_and_refuse_bad_delays():
    from spslidar.forward import return_amplitudes
    from spslidar.patterns import build_patterns

    pats = build_patterns("bernoulli", 6, 4, 0)
    refl, delay = np.ones(16), np.linspace(3.0, 9.0, 16)
    shifts, amp = return_amplitudes(pats, refl, delay, 0.5, 64)
    np.testing.assert_allclose(amp, return_amplitudes(pats.todense(), refl, delay, 0.5, 64)[1])
    for period in (0, 1.5):
        with pytest.raises(ValueError, match="period must be a whole number"):
            return_amplitudes(pats.todense(), refl, delay, 0.5, period)
    with pytest.raises(ValueError, match="NaN"):
        return_amplitudes(pats.todense(), refl, np.where(delay > 5, np.nan, delay), 0.5, 64)


def test_qcr_takes_lists_and_refuses_a_measurement_of_other_rows():
    from spslidar.qcr import plain_problem, qcr_delta, qcr_problem

    rng = np.random.default_rng(0)
    p, c = rng.random((6, 9)), rng.random((6, 2))
    np.testing.assert_allclose(qcr_delta(p.tolist(), c), qcr_delta(p, c))
    for fn in (qcr_delta, qcr_problem, plain_problem):
        with pytest.raises(ValueError, match="corr has 5 rows for 6 patterns"):
            fn(p, c[:5])


def test_a_matrix_with_a_nan_is_refused():
    from spslidar.operators import MatrixOperator

    with pytest.raises(ValueError, match="NaN or an infinity"):
        MatrixOperator(np.array([[1.0, np.nan]]))


def test_a_callers_catch_warnings_around_a_threaded_run_leaves_warnings_working():
    """A notebook's own ``catch_warnings`` entered while a run was active in a thread and
    left after it had made every later warning a RecursionError (a review of 2026-11-29)."""
    import time
    import warnings

    with ThreadPoolExecutor(1) as pool:
        fut = pool.submit(spslidar.run, **SMALL)
        time.sleep(0.2)
        with warnings.catch_warnings():
            fut.result()
        fut = pool.submit(spslidar.run, **SMALL)
        time.sleep(0.2)
        warnings.warn("main thread", UserWarning, stacklevel=1)  # (it raised before)
        assert fut.result().depth is not None
    warnings.warn("no run", UserWarning, stacklevel=1)


def test_a_warning_in_a_runs_worker_thread_reaches_its_result(monkeypatch):
    """The simulation's pool raised warnings where no run was known: they left
    ``metrics.json`` (a review of 2026-11-29)."""
    import threading
    import warnings

    from spslidar.pipeline import simulate

    real = simulate.matched_filter
    seen = []

    def filtered(*args, **kwargs):
        if threading.current_thread() is not threading.main_thread():
            seen.append(1)
            warnings.warn("raised in a simulation worker", RuntimeWarning, stacklevel=1)
        return real(*args, **kwargs)

    monkeypatch.setattr(simulate, "matched_filter", filtered)
    r = spslidar.run(scene="camera", size=32, code_length=255, iterations=5)
    assert seen, "the simulation ran no worker thread: the test tests nothing"
    assert any("simulation worker" in w for w in r.warnings)


def test_a_plugin_pattern_kinds_own_option_reaches_it():
    """A pattern kind's declared ``Option(param=...)`` was refused by ``build_patterns``'s
    check of the option names (a review of 2026-11-29)."""
    from spslidar.patterns import PATTERNS, DensePatterns
    from spslidar.registry import Option

    def sparse(kind, m, n, rng, dtype=np.float32, density=0.5, **_):
        return DensePatterns((rng.random((m, n * n)) < density).astype(dtype), kind)

    PATTERNS.add("sparse", sparse, options=(Option("sparse_density", 0.5, lo=0, hi=1,
                                                   param="density"),))
    try:
        r = spslidar.run(**dict(SMALL, iterations=5), patterns="sparse", sparse_density=0.3)
        assert r.metrics["config"]["sparse_density"] == 0.3
    finally:
        PATTERNS.remove("sparse")


def test_a_complex_matrix_is_refused_whatever_its_dtype():
    from spslidar.operators import MatrixOperator

    with pytest.raises(ValueError, match="must be real"):
        MatrixOperator(np.eye(3) + 1j, dtype=np.float32)


def test_two_runs_logs_are_told_apart_while_both_are_empty():
    """Run B leaving while run A's log and its own were both empty took A's out of the
    active list (``list.remove`` compares by ==), and A then failed to find its own: a
    ValueError in 2 of 12 threaded runs, found on reading the change again."""
    import threading
    import warnings

    from spslidar.capture import captured_warnings

    a_in, b_out = threading.Event(), threading.Event()
    got: dict = {}

    def run_a():
        with captured_warnings() as log:
            a_in.set()
            b_out.wait(5)
            warnings.warn("a's own", UserWarning, stacklevel=1)
        got["a"] = [str(w.message) for w in log]

    thread = threading.Thread(target=run_a)
    thread.start()
    a_in.wait(5)
    with captured_warnings() as log_b:
        pass
    b_out.set()
    thread.join(5)
    assert got["a"] == ["a's own"] and log_b == []


#: a stand-in for spslidar's BLAS hold that records BLAS's threads inside it (``seen``)
_SPY = r"""
seen = []
real = parallel._blas_held

def spy():
    ctx = real()
    class Spy:
        def __enter__(self):
            held = ctx.__enter__()
            seen.append(blas())
            return held
        def __exit__(self, *exc):
            return ctx.__exit__(*exc)
    return Spy()
"""

_THREAD_AFTER_MAIN = r"""
import json, sys
from concurrent.futures import ThreadPoolExecutor
import numpy as np
from threadpoolctl import threadpool_info
import spslidar
from spslidar.operators import parallel

def blas():
    return sorted(i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas")
""" + _SPY + r"""
A = dict(scene="procedural:4", size=16, code_length=1023, seed=5, solver="gpsr")
main = spslidar.run(**A)
before = blas()
parallel._blas_held = spy
with ThreadPoolExecutor(1) as ex:
    thread = ex.submit(spslidar.run, **A).result()
parallel._blas_held = real
with ThreadPoolExecutor(4) as ex:
    list(ex.map(lambda s: spslidar.run(scene="camera", size=16, code_length=1023, seed=s),
                range(8)))
print(json.dumps({"equal": bool(np.array_equal(main.slices, thread.slices)),
                  "held": seen, "before": before, "after": blas()}))
"""


def test_a_run_in_a_worker_thread_after_one_in_the_main_thread_holds_blas_too():
    """OpenBLAS ignores a thread limit set from another thread once the main thread has set
    one: a run in a worker thread after a main-thread run had BLAS on every core, and its
    slices differed from the same run's (24 of 24 configurations; depth maps 9 of 24), and
    concurrent runs left BLAS on one thread for good in 3 of 5 processes (an audit of
    2026-11-30). The limit is set from a thread of spslidar's own: the worker's run holds
    BLAS on one thread and equals the main thread's bit for bit, and the pool leaves BLAS as
    it found it. (A fresh process: the order of the calls is the point.)"""
    import json
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", _THREAD_AFTER_MAIN], capture_output=True,
                         text=True, timeout=300, check=True).stdout
    got = json.loads(out.strip().splitlines()[-1])
    assert got["held"] and all(set(h) == {1} for h in got["held"]), got
    assert got["equal"], got
    assert got["after"] == got["before"], got


_MAIN_SET_ITSELF = r"""
import json, warnings
from threadpoolctl import threadpool_info, threadpool_limits
import spslidar
from spslidar.operators import parallel

def blas():
    return [i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"]
""" + _SPY + r"""
threadpool_limits(limits=2, user_api="blas")  # the main thread sets a limit itself
parallel._blas_held = spy
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    r = spslidar.run(scene="camera", size=16, code_length=1023, seed=0)
    r2 = spslidar.run(scene="camera", size=16, code_length=1023, seed=1)
said = [str(w.message) for w in caught] + list(r.warnings) + list(r2.warnings)
print(json.dumps({"seen": seen,
                  "warned": sum("could not be held to one thread" in s for s in said)}))
"""


def test_blas_that_cannot_be_held_to_one_thread_is_said_once():
    """Where the main thread set BLAS's limit itself (through threadpoolctl), OpenBLAS
    ignores spslidar's: one warning in the process says so and how to make the numbers
    equal; where the limit takes all the same (another BLAS), nothing is said."""
    import json
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", _MAIN_SET_ITSELF], capture_output=True,
                         text=True, timeout=300, check=True).stdout
    got = json.loads(out.strip().splitlines()[-1])
    held = all(set(h) == {1} for h in got["seen"])
    assert got["seen"] and got["warned"] == (0 if held else 1), got


def test_a_results_config_and_detector_report_are_its_own():
    """A result's config was the measurement's own object and its ``metrics["detector"]``
    the measurement's dict: ``r.config.solver = "twist"`` made the next ``reconstruct(m)``
    a TwIST solve, and an edited detector report was every later result's (an audit of
    2026-11-30)."""
    m = spslidar.measure(**SMALL, seed=1)
    r1 = spslidar.reconstruct(m)
    assert r1.config is not m.config
    r1.config.solver = "twist"
    r1.metrics["detector"]["model"] = "EDITED"
    r2 = spslidar.reconstruct(m)
    assert r2.metrics["config"]["solver"] == "fista" and m.config.solver == "fista"
    assert r2.metrics["detector"]["model"] == "linear"
    np.testing.assert_array_equal(r2.depth, r1.depth)


@pytest.mark.parametrize("kind", ["hadamard", "scrambled-hadamard", "gaussian"])
def test_a_row_block_handed_out_is_a_copy(kind):
    """``apply_rows`` handed out a view of the product it keeps for the next blocks: a caller
    that zeroed its block zeroed the next call's (Hadamard kinds; an audit of 2026-11-30)."""
    from spslidar.patterns import build_patterns

    pats = build_patterns(kind, 64, 16, np.random.default_rng(0))
    x = np.random.default_rng(1).random((256, 3))
    want = pats.todense()[:4].astype(np.float64) @ x
    block = pats.apply_rows(slice(0, 4), x)
    block[:] = 0
    np.testing.assert_allclose(pats.apply_rows(slice(0, 4), x), want, rtol=1e-6)


def test_a_registry_read_while_another_thread_adds_and_removes_a_plugin():
    """Reading the options while a plugin was added and removed in another thread raised
    "dictionary changed size during iteration" (3 of 2 000 ``Config(...)`` calls, an audit of
    2026-11-30): the reads take a snapshot."""
    import sys
    import threading

    from spslidar.depth import ESTIMATORS
    from spslidar.registry import Option

    stop = threading.Event()
    errors = []

    def churn():
        k = 0
        while not stop.is_set():
            name = f"churn{k % 7}"
            ESTIMATORS.add(name, "spslidar.depth.argmax:ArgmaxDepth",
                           options=(Option(f"churn_opt{k % 7}", 1, kind=int),))
            ESTIMATORS.remove(name)
            k += 1

    old = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)
    t = threading.Thread(target=churn)
    t.start()
    try:
        for _ in range(30000):
            try:
                ESTIMATORS.options()
                ESTIMATORS.owners("half_width")
                list(ESTIMATORS)
                ESTIMATORS.help_text()
            except RuntimeError as err:
                errors.append(str(err))
    finally:
        stop.set()
        t.join()
        sys.setswitchinterval(old)
    assert not errors, errors[:1]
    assert not any(n.startswith("churn") for n in ESTIMATORS.names())


def test_a_sweep_leaves_no_warning_filter_behind(tmp_path):
    """A sweep on two workers added an "ignore" filter for loky's restarted-worker warning to
    the process for good (an audit of 2026-11-30)."""
    import warnings

    from spslidar.experiments.sweep import engine

    before = list(warnings.filters)
    out = list(engine._run_local(_square, [(0, {"x": 2}), (1, {"x": 3})], 2))
    assert sorted(o[1][1] for o in out) == [4, 9]
    assert warnings.filters == before


def test_a_sweep_takes_out_only_its_own_warning_filter(tmp_path, monkeypatch):
    """Where the sweep's filter does not go to the front of the global list (Python 3.14's
    context-local filters), the filter that is there is someone else's: left in place (the
    first global filter was taken out for good). Emulated by a filterwarnings that keeps the
    filter elsewhere."""
    import warnings

    from spslidar.experiments.sweep import engine

    warnings.filterwarnings("ignore", message="a caller's own filter")
    before = list(warnings.filters)
    monkeypatch.setattr(warnings, "filterwarnings", lambda *a, **k: None)
    out = list(engine._run_local(_square, [(0, {"x": 2}), (1, {"x": 3})], 2))
    assert sorted(o[1][1] for o in out) == [4, 9]
    assert warnings.filters == before


def test_a_sweep_leaves_a_callers_own_identical_filter(monkeypatch):
    """A caller who had set the very filter the sweep sets lost it for good: the sweep's
    filterwarnings moved it to the front, and the sweep took it out as its own (a review)."""
    import warnings

    from spslidar.experiments.sweep import engine

    said = "A worker stopped while some jobs were given to the executor"
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=said, category=UserWarning)
        before = list(warnings.filters)
        out = list(engine._run_local(_square, [(0, {"x": 2}), (1, {"x": 3})], 2))
        assert sorted(o[1][1] for o in out) == [4, 9]
        assert warnings.filters == before


def _square(params):
    return params["x"] ** 2


_FORK_AFTER_A_RUN = r"""
import os, sys, time
import spslidar
spslidar.run(scene="camera", size=16, code_length=1023, seed=0)
pid = os.fork()
if pid == 0:
    r = spslidar.run(scene="camera", size=16, code_length=1023, seed=1)
    os._exit(0 if r.depth.shape == (16, 16) else 3)
deadline = time.time() + 120
while time.time() < deadline:
    done, status = os.waitpid(pid, os.WNOHANG)
    if done:
        print("child", os.waitstatus_to_exitcode(status))
        sys.exit(0)
    time.sleep(0.2)
os.kill(pid, 9)
print("child hung")
"""


@pytest.mark.skipif(not hasattr(__import__("os"), "fork"), reason="needs os.fork")
def test_a_forked_child_runs_after_its_parent_ran():
    """The setter thread of BLAS's limit does not survive a fork: a child forked after a run
    (multiprocessing's fork pools) waited for it forever (a review of 2026-11-30)."""
    import subprocess
    import sys

    out = subprocess.run([sys.executable, "-c", _FORK_AFTER_A_RUN], capture_output=True,
                         text=True, timeout=300).stdout
    assert out.strip().splitlines()[-1] == "child 0", out


def test_no_thread_of_spslidar_outlives_a_run():
    """The thread that holds BLAS to one thread stayed after every run, so the process was
    multi-threaded for good and Python 3.12+ warned at each ``os.fork()`` after a run (an
    audit of 2026-11-30): it ends with the last hold."""
    import threading

    from spslidar import run

    run(size=8, code_length=127, compression=0.5, seed=0)
    assert not [t.name for t in threading.enumerate() if t.name.startswith("spslidar-blas")]


def test_a_figure_that_fails_to_save_leaves_no_figure_open(tmp_path):
    """depth_figure's matplotlib engine left its figure in pyplot when savefig raised (a
    missing folder, a full disk, a Ctrl-C): 6.7 MB a call in a session (an audit of
    2026-11-30)."""
    import matplotlib.pyplot as plt

    from spslidar import run
    from spslidar.figures import depth_figure

    r = run(size=8, code_length=127, compression=0.5, seed=0)
    before = len(plt.get_fignums())
    for _ in range(3):
        with pytest.raises(OSError):
            depth_figure(r, tmp_path / "missing" / "d.png", engine="matplotlib")
    assert len(plt.get_fignums()) == before


def test_an_interrupted_command_in_a_session_leaves_no_warning_filter(monkeypatch, capsys,
                                                                      tmp_path):
    """main([...]) interrupted in a session added an 'ignore' filter for joblib's cancelled
    tasks that stayed, and hid the user's own joblib's warning (an audit of 2026-11-30); a
    process of its own (main() from the command line) still adds it, as it ends."""
    import warnings

    import spslidar.cli as cli

    def interrupted(args):
        raise KeyboardInterrupt

    from spslidar.interrupts import EXIT_INTERRUPTED

    monkeypatch.setitem(cli.COMMANDS, "run", interrupted)
    before = list(warnings.filters)
    assert cli.main(["run", "--size", "8", "--out", str(tmp_path / "o")]) == EXIT_INTERRUPTED
    assert warnings.filters == before
