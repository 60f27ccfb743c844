"""The Python API as a researcher scripts it, as an outside audit of 2026-11-29 did (about 600
probes): what gave a silently wrong number, changed the caller's arrays, or ended deep in
NumPy."""

from __future__ import annotations

import numpy as np
import pytest

from spslidar.errors import ConfigError


@pytest.mark.parametrize("dtype", [np.uint8, bool, np.int64, np.float16])
def test_integer_and_half_matrices_give_float_products(dtype):
    """A 0/1 uint8 (or bool) pattern matrix computed its products in uint8: [0.9, 1.2] read
    [0, 0] (or [True, True]), and its adjoint likewise."""
    from spslidar.operators import MatrixOperator, dottest
    from spslidar.patterns import as_patterns

    b = np.array([[1, 0, 1, 1], [0, 1, 1, 0]]).astype(dtype)
    x = np.array([0.4, 0.9, 0.3, 0.2])
    exact = b.astype(np.float64) @ x
    tol = 1e-3 if dtype == np.float16 else 1e-12  # (float16 is read as float32)
    for op in (as_patterns(b), MatrixOperator(b)):
        assert np.allclose(op @ x, exact, rtol=tol, atol=tol)
        assert np.issubdtype(op.dtype, np.floating) and op.dtype != np.float16
        assert dottest(op, rng=0) < 1e-4


def test_integer_dtype_patterns_are_refused():
    from spslidar.patterns.dense import make_patterns

    with pytest.raises(ConfigError, match="use float32 or float64"):
        make_patterns("gaussian", 2, 4, np.random.default_rng(1), dtype=int)


def test_the_linear_detector_leaves_the_callers_means():
    from spslidar.detectors import build_detector

    lam = np.full((1, 4), 0.5)
    counts, _ = build_detector("linear").detect(lam, np.random.default_rng(0))
    assert np.array_equal(lam, np.full((1, 4), 0.5)) and counts is not lam
    frozen = np.full((2, 3), 2.0)
    frozen.flags.writeable = False  # (a read-only lam was "assignment destination ...")
    assert build_detector("linear").detect(frozen, np.random.default_rng(0))[0].shape == (2, 3)


def test_a_scene_keeps_its_own_copy():
    from spslidar.scenes.base import Scene

    d = np.full((8, 8), 20.0)
    s = Scene("m", d, np.ones((8, 8)), np.ones((8, 8), bool))
    d[:] = 5.0
    assert s.depth[0, 0] == 20.0 and not s.depth.flags.writeable and d.flags.writeable


def test_a_sweep_result_named_as_a_parameter_is_an_error_row(tmp_path):
    """``{"noise": 0, ...}`` replaced each point's noise in its row, so results.csv credited
    each RMSE to another noise; a function that changed its params changed the row's."""
    from spslidar.experiments.sweep import ERROR_KEY, run_sweep

    rows = run_sweep(lambda p: {"noise": 0, "rmse": p["noise"] * 0.1},
                     [{"noise": 1}, {"noise": 5}], tmp_path / "a", progress=False)
    assert [r["noise"] for r in rows] == [1, 5]
    assert all("a parameter of the point (there " in r[ERROR_KEY] for r in rows)
    same = run_sweep(lambda p: {"noise": p["noise"], "r": 2}, [{"noise": 1}], tmp_path / "c",
                     progress=False)
    assert same[0]["noise"] == 1 and same[0]["r"] == 2  # (the same value: a row, as snr's)

    def meddler(p):
        p["noise"] = 99
        return {"r": 1}

    rows = run_sweep(meddler, [{"noise": 1}], tmp_path / "b", progress=False)
    assert rows[0]["noise"] == 1 and rows[0]["r"] == 1


def test_ml_depth_reads_no_nan_and_checks_its_arguments():
    from spslidar.depth.argmax import ml_depth

    s = np.random.default_rng(0).random((3, 6))
    s[:, 2] += 5
    s[1, 4] = np.nan  # not the tallest
    s[2] = np.nan  # nothing at all: no return
    depth, _ = ml_depth(s, np.arange(6), 1e-10)
    assert depth[0] == depth[1] and np.isnan(depth[2])
    for lags, bw, why in ((np.arange(10), 1e-10, "one delay per slice"),
                          (np.arange(6), -1e-10, "positive number of seconds"),
                          (np.arange(6), 0.0, "positive number of seconds")):
        with pytest.raises(ValueError, match=why):
            ml_depth(s, lags, bw)
    with pytest.raises(ValueError, match=r"\(Q, K\) array"):
        ml_depth(np.ones(6), np.arange(6), 1e-10)


def test_metrics_need_one_pixel_grid():
    from spslidar.metrics import edge_agreement, rmse, sobel_edges

    with pytest.raises(ValueError, match="differ"):
        rmse(np.ones((2, 8)), np.ones((8, 2)))
    assert rmse(np.ones((4, 4)), np.ones(16)) == 0.0  # a map and its flat pixels
    with pytest.raises(ValueError, match="valid"):
        rmse(np.ones((4, 4)), np.ones((4, 4)), np.ones((2, 8), bool))
    with pytest.raises(ValueError, match="2-D map"):
        sobel_edges(np.ones((2, 3, 3)))
    with pytest.raises(ValueError, match="differ"):
        edge_agreement(np.ones((4, 4)), np.ones((3, 3)))


def test_non_finite_or_fractional_codes_and_operators_are_refused():
    from spslidar.codes import periodic_xcorr
    from spslidar.operators import MatrixOperator, dottest

    with pytest.raises(ConfigError, match="non-finite or fractional"):
        periodic_xcorr([np.nan, 1, 0], [1, 0, 1], bipolar=False)
    with pytest.raises(ConfigError, match="non-finite or fractional"):
        periodic_xcorr([0.4, 0.4, 0.4], [1, 1, 1], bipolar=False)
    with pytest.raises(ValueError, match="NaN or an infinity"):  # (refused where wrapped)
        MatrixOperator([[np.nan, 1.0], [1.0, 1.0]])
    from spslidar.operators.base import LinearOperator

    class Nan(LinearOperator):  # an operator of one's own that gives NaN
        def __init__(self):
            super().__init__((2, 2), np.float64)

        def _matvec(self, x):
            return np.full_like(x, np.nan)

        _rmatvec = _matvec

    with pytest.raises(AssertionError, match="dot test failed"):
        dottest(Nan(), rng=0)


def test_solvers_refuse_non_finite_data_and_take_a_matrix():
    from spslidar.solvers import StopRule
    from spslidar.solvers.fista import FISTA
    from spslidar.solvers.regularisers import L1

    a = np.random.default_rng(0).standard_normal((6, 4))
    y = a @ np.array([1.0, 0, 0, 2.0])
    x, _ = FISTA(stop=StopRule(50)).solve(a, y, L1(), 0.01)  # (an AttributeError before)
    assert np.isfinite(x).all()
    bad = y.copy()
    bad[0] = np.nan
    with pytest.raises(ValueError, match="NaN or an infinity"):
        FISTA(stop=StopRule(5)).solve(a, bad, L1(), 0.01)
    with pytest.raises(ValueError, match="x0 holds"):
        FISTA(stop=StopRule(5)).solve(a, y, L1(), 0.01, x0=np.full(4, np.inf))
    with pytest.raises(ValueError, match="whole number"):
        StopRule(5.5)


def test_operator_shapes_are_checked():
    from spslidar.operators import Identity, MatrixOperator
    from spslidar.operators.image import Gradient2D

    for make, why in ((lambda: Identity(-1), ">= 0"), (lambda: Gradient2D(4), "a pair"),
                      (lambda: Gradient2D((2, 3, 4)), "a pair"),
                      (lambda: MatrixOperator(np.ones(5)), r"\(M, N\) matrix")):
        with pytest.raises(ValueError, match=why):
            make()


def test_a_numpy_dtype_is_a_config_dtype():
    from spslidar.config import Config

    assert Config(dtype=np.float32).dtype == "float32"
    assert Config(dtype=np.dtype("float64")).dtype == "float64"
    with pytest.raises(ConfigError, match="unknown dtype 'int32'"):
        Config(dtype=np.int32)


def test_an_l1_basis_of_other_images_is_refused():
    from spslidar.operators import Wavelet2D
    from spslidar.solvers.regularisers import L1

    reg = L1(Wavelet2D((4, 16)))
    with pytest.raises(ValueError, match="takes 64 pixels, the problem has 32 rows"):
        reg.prox(np.ones((32, 2)), 0.1)
    assert reg.prox(np.ones((64, 2)), 0.1).shape == (64, 2)


@pytest.mark.parametrize("name", ["linear", "gmapd"])
@pytest.mark.parametrize("bad", [-1.0, np.nan, np.inf])
def test_a_detector_refuses_impossible_means(name, bad):
    from spslidar.detectors import build_detector

    with pytest.raises(ValueError, match="finite and non-negative"):
        build_detector(name).detect(np.array([[0.5, bad]]), np.random.default_rng(0))


def test_stage_names_are_read_in_any_case():
    """Scene names were read in any case, but ``solver="FISTA"`` (Config or ``--solver``) was
    an unknown stage: every registry now reads a name that differs only in case as the
    registered one, and metrics say the registered spelling."""
    from spslidar.cli import build_parser
    from spslidar.config import Config
    from spslidar.registry import Registry

    cfg = Config(solver="FISTA", detector="GMAPD", depth="Mrf", code="MSEQ",
                 patterns="Gaussian", dead_time=2e-8)
    assert (cfg.solver, cfg.detector, cfg.depth, cfg.code, cfg.patterns) == (
        "fista", "gmapd", "mrf", "mseq", "gaussian")
    assert cfg.extra["dead_time"] == 2e-8  # the stage's option reached the canonical stage
    args = build_parser().parse_args(["run", "--out", "o", "--solver", "TwIST", "--depth",
                                      "ARGMAX"])
    assert (args.solver, args.depth) == ("twist", "argmax")
    with pytest.raises(ConfigError, match="unknown solver 'fistaa'"):
        Config(solver="fistaa")
    snr = build_parser().parse_args(["snr", "--code", "MSEQ"])  # (snr's --code too: a review)
    assert snr.code == "mseq"
    from spslidar.pipeline.real import load_code

    assert load_code("MSEQ", 127).size == 127  # reconstruct's --code MSEQ was read as a file
    reg = Registry("thing", "thing")  # two entries differing only in case are refused
    reg.add("a", object)  # (since an outside audit registered "MRF" beside "mrf")
    with pytest.raises(ValueError, match="only in case"):
        reg.add("A", dict)
    assert reg.canonical("a") == "a" and reg.canonical("A") == "a"
    with pytest.raises(ConfigError, match="unknown thing"):
        reg.get(reg.canonical("b"))


def test_pattern_files_other_tools_write_are_said_plainly(tmp_path):
    """A 0/255 uint8 bitplane, a NaN and a TIFF stack were told "must hold mirror states in
    [0, 1]" (the NaN unnamed) and NumPy's "the magic string is not correct; expected
    b'\\x93NUMPY', got b'II*\\x00'" (an outside audit of lab formats)."""
    from spslidar.pipeline.real import check_patterns, load_patterns

    p = (np.random.default_rng(0).random((4, 4, 4)) < 0.5).astype(np.uint8)
    with pytest.raises(ConfigError, match="values from 0 to 255: 8-bit levels 0-255"):
        check_patterns(p * 255.0)  # (floats are states: 255 is no level of a float)
    # integers are stored levels, read as images are (as a .mat of imread's uint8 was,
    # while the same array as a .npy was refused: an audit): binary 0/1, grey over 255
    np.testing.assert_array_equal(check_patterns(p * 255), p.reshape(4, -1))
    np.testing.assert_array_equal(check_patterns((p * 255).astype(np.int64)), p.reshape(4, -1))
    grey = np.arange(64, dtype=np.uint8).reshape(4, 4, 4) * 4
    np.testing.assert_allclose(check_patterns(grey), grey.reshape(4, -1) / 255.0, rtol=1e-6)
    with pytest.raises(ConfigError, match="give the two complementary patterns"):
        check_patterns(2.0 * p - 1)
    nan = p.astype(np.float32)
    nan[1, 2, 3] = np.nan
    with pytest.raises(ConfigError, match="holds 1 NaN or infinite value"):
        check_patterns(nan)
    tif = tmp_path / "p.tif"
    tif.write_bytes(b"II*\x00" + bytes(200))
    # (a TIFF is read since stop 66, spslidar.io.lab_arrays: this one holds no image)
    with pytest.raises(ConfigError, match="pattern image p.tif holds no image") as info:
        load_patterns(tif)
    assert "magic" not in str(info.value)
    assert check_patterns(p).shape == (4, 16)  # 0/1 uint8 as before


def test_a_regulariser_declaring_an_option_is_refused_at_registration():
    """A regulariser is built as ``make(shape, nonneg=..., max_inner=...)``, with nothing of
    the config's: a plugin's declared option was a key no config could set ("unknown config
    key", its default used always; an architecture audit). Refused where it is registered;
    without options it registers as before, and other registries still take options."""
    from spslidar.registry import Option, Registry
    from spslidar.solvers import REGULARISERS
    from spslidar.solvers.regularisers import make_l1

    with pytest.raises(ValueError, match="a regulariser declares no options or defaults.*"
                                         "weight of 'weighted'"):
        REGULARISERS.add("weighted", make_l1, options=(Option("weight", 1.0, "a weight"),))
    with pytest.raises(ValueError, match="eps of 'weighted'"):  # (a default: never used)
        REGULARISERS.add("weighted", make_l1, eps=5.0)
    assert "weighted" not in REGULARISERS
    REGULARISERS.add("weighted", make_l1, "weighted l1", "l1 by another name")
    try:
        assert REGULARISERS.load("weighted") is make_l1
    finally:
        REGULARISERS.remove("weighted")
    other = Registry("thing", "thing")
    other.add("a", make_l1, options=(Option("weight", 1.0),))
    assert list(other.options()) == ["weight"]


def test_the_solves_precision_does_not_change_the_patterns_shown():
    """Gaussian patterns were drawn in the solve's dtype, so --dtype float64 showed other
    patterns and detected other photons (RMSE 0.028 against 0.044 m on one scene: an outside
    audit, options paired): they are drawn once, and only rounded to the dtype; a run's
    acquisition is then the same within float32's rounding of a few grey levels."""
    from spslidar import measure
    from spslidar.patterns.dense import make_patterns

    p32 = make_patterns("gaussian", 16, 64, rng=3, dtype=np.float32)
    p64 = make_patterns("gaussian", 16, 64, rng=3, dtype=np.float64)
    assert p64.dtype == np.float64
    np.testing.assert_allclose(p64, p32, rtol=0, atol=1e-6)  # (float32's rounding)
    kw = dict(size=8, code_length=127, compression=0.5, seed=2)
    a, b = measure(**kw), measure(**kw, dtype="float64")
    ca, cb = (float(np.sum(m.sim["counts"])) for m in (a, b))
    assert abs(ca - cb) <= 1e-3 * ca, (ca, cb)


def test_patterns_a_rounding_outside_0_1_are_taken_and_beyond_it_said_exactly():
    """Grey levels computed in floating point (a pattern scaled by 1 + 1e-12, float32's
    1.0000001, less 1e-9) were refused as "got values from 0 to 1" and "+1/-1 differences?"
    (an outside audit of 2026-12-02): within ``PATTERN_ROUNDOFF`` they are clipped, beyond it
    the values are printed to nine digits and the +1/-1 hint is kept for +1/-1 patterns."""
    from spslidar.pipeline.inputs import PATTERN_ROUNDOFF
    from spslidar.pipeline.real import check_patterns

    p = (np.random.default_rng(2).random((4, 4, 4)) < 0.5).astype(np.float64)
    p[0, 0, 0], p[0, 0, 1] = 1.0, 0.0
    for near in (p * (1 + 1e-12), p - 1e-9, np.nextafter(p.astype(np.float32), np.float32(2)),
                 p * (1 + 0.9 * PATTERN_ROUNDOFF)):
        kept = near.copy()
        out = check_patterns(near)
        assert out.min() >= 0 and out.max() <= 1  # clipped, and within the rounding of 0/1:
        np.testing.assert_allclose(out, p.reshape(4, -1), rtol=0, atol=PATTERN_ROUNDOFF)
        np.testing.assert_array_equal(near, kept)  # the user's array untouched
    with pytest.raises(ConfigError, match=r"values from 0 to 1\.00001\b") as exc:
        check_patterns(p * 1.00001)
    assert "+1/-1" not in str(exc.value)
    with pytest.raises(ConfigError, match=r"values from -0\.001 to 0\.999\b") as exc:
        check_patterns(p - 1e-3)
    assert "+1/-1" not in str(exc.value)


def test_run_takes_a_runs_toml_file_as_its_configuration(tmp_path):
    """``spslidar.run("myrun.toml")`` reads the file as ``run --config`` does (it was taken
    for a scene's name, "unknown scene": an outside audit of 2026-12-03), keywords over it;
    a TOML file given as the scene says what it is."""
    import spslidar
    from spslidar.errors import SceneError

    path = tmp_path / "myrun.toml"
    path.write_text('scene = "steps"\nsize = 8\ncode_length = 255\nnoise = 1\n')
    got = spslidar.measure(path, seed=3)
    want = spslidar.measure(scene="steps", size=8, code_length=255, noise=1, seed=3)
    assert got.config == want.config
    assert spslidar.measure(str(path), noise=2).config.noise == 2  # (a str path too)
    with pytest.raises(SceneError, match=r"is a TOML file, a run's configuration, not a "
                                         r"scene: spslidar.run\('x.toml'\)"):
        spslidar.measure(scene="x.toml")
