"""Walsh-Hadamard patterns: the fast transform, the operators' adjoints, the orderings, the two
DMD realisations against ideal +-1 patterns, and the refusal of sizes that are not 2^k."""

import dataclasses

import numpy as np
import pytest
from scipy.linalg import hadamard

from spslidar.errors import ConfigError
from spslidar.operators import dottest
from spslidar.operators.hadamard import WalshHadamard, fwht
from spslidar.patterns import HADAMARD_ORDERS, build_patterns
from spslidar.patterns.hadamard import (
    HadamardPatterns,
    hadamard_order,
    hadamard_patterns,
    walsh_sequency,
)


@pytest.mark.parametrize("q", [1, 2, 4, 8, 32, 128, 1024])
def test_fwht_matches_scipy_hadamard(q):
    x = np.random.default_rng(q).standard_normal((q, 3))
    np.testing.assert_allclose(fwht(x), hadamard(q) @ x, rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(fwht(x[:, 0]), hadamard(q) @ x[:, 0], rtol=1e-12, atol=1e-9)


def test_fwht_column_blocks_and_in_place():
    # Q * K large enough for the cache-blocked path (several column blocks)
    x = np.random.default_rng(0).standard_normal((4096, 300)).astype(np.float32)
    x0 = x.copy()
    ref = fwht(x[:, :7].astype(np.float64))
    y = fwht(x)
    np.testing.assert_array_equal(x, x0)  # no side effect
    np.testing.assert_allclose(y[:, :7], ref, rtol=1e-4, atol=1e-3)
    z = x.copy()
    assert fwht(z, out=z) is not None
    np.testing.assert_array_equal(z, y)
    # H H = Q I
    np.testing.assert_allclose(fwht(fwht(x0[:, :5].astype(np.float64))) / 4096, x0[:, :5],
                               atol=1e-9)


def test_fwht_refuses_other_lengths():
    with pytest.raises(ConfigError, match="power-of-two"):
        fwht(np.ones(12))
    with pytest.raises(ConfigError):
        WalshHadamard(48)


def _sets(n=8, m=20, dtype=np.float64):
    out = {}
    for kind in ("hadamard", "scrambled-hadamard"):
        for real in ("shifted", "differential", "complementary"):
            p = hadamard_patterns(kind, m, n, np.random.default_rng(3), dtype=dtype,
                                  realisation=real)
            out[f"{kind}-{real}"] = p
            out[f"{kind}-{real}-frames"] = p.exposures()[0]
    return out


@pytest.mark.parametrize("name", sorted(_sets()))
def test_adjoint_of_every_hadamard_operator(name):
    op = _sets()[name]
    dottest(op, n_cols=1, rng=0)
    dottest(op, n_cols=4, rng=1)
    dottest(op.as_dtype(np.float32), n_cols=2, rng=2)
    dottest(op.centred(2.0, np.float64), n_cols=2, rng=3)


def test_walsh_hadamard_operator_adjoint():
    dottest(WalshHadamard(64), n_cols=3, rng=0)


@pytest.mark.parametrize("name", sorted(_sets()))
def test_patterns_match_their_dense_rows(name):
    op = _sets()[name]
    dense = op.todense()
    n = op.n_side
    h = hadamard(n * n)
    rows = h[op.rows]
    if op.signs is not None:
        rows = (rows * op.signs[None, :])[:, np.argsort(op.perm)]
    if op.flips is not None:
        rows = rows * op.flips[:, None]
    expected = {"shifted": (1 + rows) / 2, "bipolar": rows}.get(op.mode)
    if op.mode == "pairs":
        expected = np.empty((2 * rows.shape[0], n * n))
        expected[0::2], expected[1::2] = (1 + rows) / 2, (1 - rows) / 2
    np.testing.assert_array_equal(dense, expected)
    np.testing.assert_allclose(op.mean_pattern(), dense.mean(axis=0), atol=1e-12)
    x = np.random.default_rng(0).standard_normal((n * n, 2))
    np.testing.assert_allclose(op.apply_rows(slice(3, 9), x), dense[3:9] @ x, atol=1e-10)
    if op.mode != "bipolar":  # what the DMD shows: 0/1 mirrors
        assert set(np.unique(dense)) <= {0.0, 1.0}


@pytest.mark.parametrize("order", HADAMARD_ORDERS)
@pytest.mark.parametrize("n", [2, 8, 32])
def test_orderings_are_permutations(order, n):
    perm = hadamard_order(order, n, np.random.default_rng(0))
    np.testing.assert_array_equal(np.sort(perm), np.arange(n * n))


def _sign_changes(img):
    return int(np.sum(img[:, 1:] != img[:, :-1]) + np.sum(img[1:] != img[:-1]))


def test_walsh_sequency_counts_sign_changes():
    for n in (2, 4, 16, 64):
        h = hadamard(n)
        counted = np.sum(h[:, 1:] != h[:, :-1], axis=1)
        np.testing.assert_array_equal(walsh_sequency(n), counted)


def test_sequency_order_is_ordered_by_sign_changes():
    n = 16
    h = hadamard(n * n)
    perm = hadamard_order("sequency", n)
    changes = [_sign_changes(h[r].reshape(n, n)) for r in perm]
    assert np.all(np.diff(changes) >= 0)
    assert perm[0] == 0 and changes[0] == 0  # the DC row first
    # and the natural order is not (the test could fail)
    nat = [_sign_changes(h[r].reshape(n, n)) for r in range(n * n)]
    assert np.any(np.diff(nat) < 0)


def test_cake_cutting_order_is_ordered_by_pieces():
    from scipy import ndimage

    n = 16
    h = hadamard(n * n)
    pieces = []
    for r in hadamard_order("cake-cutting", n)[:64]:
        img = h[r].reshape(n, n)
        pieces.append(ndimage.label(img > 0)[1] + ndimage.label(img < 0)[1])
    assert np.all(np.diff(pieces) >= 0)


@pytest.mark.parametrize("size", [6, 12, 100])
def test_bad_sizes_are_refused_in_one_line(size):
    from spslidar.config import Config

    with pytest.raises(ConfigError) as exc:
        Config(patterns="hadamard", size=size)
    assert "\n" not in str(exc.value) and "power of two" in str(exc.value)
    with pytest.raises(ConfigError, match="power of two"):
        build_patterns("scrambled-hadamard", 10, size, np.random.default_rng(0))


def test_bad_size_exits_2_on_the_cli(tmp_path, capsys):
    from spslidar.cli import main

    rc = main(["run", "--out", str(tmp_path / "x"), "--patterns", "hadamard", "--size", "48"])
    assert rc == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "power of two" in err[0]


def _noiseless(realisation):
    from spslidar.pipeline.chain import measure

    return measure(size=16, patterns="hadamard", hadamard_realisation=realisation,
                   noiseless=True, compression=0.5, code_length=1023, seed=4)


def _ideal_corr(meas):
    """The noiseless outputs of ideal +-1 patterns (negative transmittances), simulated
    directly through the bipolar operator."""
    from spslidar.detectors import build_detector
    from spslidar.detectors.counting import NoiseModel
    from spslidar.pipeline.simulate import simulate_correlations

    cfg = meas.config
    p = meas.patterns
    ideal = HadamardPatterns(p.n_side, p.rows, p.signs, p.perm, "bipolar", np.float64)
    noise = NoiseModel(cfg.noise, tuple(cfg.noise_split), cfg.ambient, cfg.background_rate,
                       cfg.dark_count_rate)
    sim = simulate_correlations(ideal, meas.scene, meas.acq, meas.ulags, noise,
                                build_detector("linear"), cfg.pulse_width,
                                np.random.default_rng(0), noiseless=True)
    return ideal, sim["corr"].astype(np.float64)


def _centre(a):
    return a - a.mean(axis=0)


def test_differential_pairs_equal_ideal_patterns_in_the_noiseless_limit():
    from spslidar.pipeline.chain import reconstruct

    meas = _noiseless("differential")
    ideal, corr = _ideal_corr(meas)
    assert meas.patterns.shape == ideal.shape
    np.testing.assert_array_equal(meas.patterns.todense(), ideal.todense())
    got = meas.sim["corr"].astype(np.float64)
    scale = np.abs(corr).max()
    # C+ - C- is h p itself (the background cancels); the ideal's outputs differ from it by a
    # per-lag constant only (the bipolar replica's response to a flat background)
    np.testing.assert_allclose(_centre(got), _centre(corr), atol=1e-5 * scale)
    twin = dataclasses.replace(meas, sim={**meas.sim, "corr": corr.astype(np.float32)})
    a, b = reconstruct(meas, lam=1e-3), reconstruct(twin, lam=1e-3)
    np.testing.assert_allclose(a.slices, b.slices, atol=1e-3 * np.abs(b.slices).max())
    np.testing.assert_array_equal(a.depth, b.depth)
    assert a.metrics["depth_rmse_m"] < 0.02


def test_shifted_patterns_with_qcr_centring_equal_ideal_in_the_noiseless_limit():
    from spslidar.qcr import qcr_problem

    meas = _noiseless("shifted")
    ideal, corr = _ideal_corr(meas)
    m = meas.patterns.shape[0]
    # the centred (1 + h)/2 patterns are the centred ideal ones, halved (eq. 11: the DC is gone)
    a_shift, y_shift = qcr_problem(meas.patterns, meas.sim["corr"], "centred", np.float64)
    a_ideal, y_ideal = qcr_problem(ideal, corr, "centred", np.float64)
    np.testing.assert_allclose(a_shift.todense(), 0.5 * a_ideal.todense(), atol=1e-12)
    np.testing.assert_allclose(y_shift, 0.5 * y_ideal, atol=1e-5 * np.abs(y_ideal).max())
    assert m == 128


def test_differential_halves_the_time_per_frame_honestly():
    diff, shifted = _noiseless("differential"), _noiseless("shifted")
    assert shifted.patterns.rows[0] == 0  # cake-cutting order: the all-on (DC) pattern first
    # the two frames (1 + h)/2 and (1 - h)/2 together are one all-on frame; each is shown for
    # half the time, so each pair collects half the signal of one full-time all-on exposure
    np.testing.assert_allclose(diff.sim["signal_counts"], 0.5 * shifted.sim["signal_counts"][0],
                               rtol=1e-9)


def test_hadamard_runs_are_reproducible_and_scrambling_uses_the_seed():
    a = build_patterns("scrambled-hadamard", 30, 8, np.random.default_rng(1))
    b = build_patterns("scrambled-hadamard", 30, 8, np.random.default_rng(1))
    c = build_patterns("scrambled-hadamard", 30, 8, np.random.default_rng(2))
    np.testing.assert_array_equal(a.todense(), b.todense())
    assert not np.array_equal(a.todense(), c.todense())
    assert a.nbytes < 8 * 64 * 3  # tables only, never the (M, Q) matrix


@pytest.mark.parametrize("name", ["hadamard-shifted", "scrambled-hadamard-differential",
                                  "hadamard-differential-frames", "hadamard-complementary",
                                  "scrambled-hadamard-complementary"])
def test_centred_operator_matches_the_dense_centred_patterns(name):
    op = _sets()[name]
    dense = op.todense()
    want = (dense - dense.mean(axis=0)) / 3.0
    np.testing.assert_allclose(op.centred(3.0, np.float64).todense(), want, atol=1e-12)
    np.testing.assert_allclose(op.centred(3.0, np.float32).todense(), want, atol=1e-6)


def _peak_bytes(**cfg):
    import tracemalloc

    from spslidar.pipeline.chain import measure, reconstruct

    tracemalloc.start()
    try:
        meas = measure(**cfg)
        reconstruct(meas)
        return tracemalloc.get_traced_memory()[1], meas.patterns.shape
    finally:
        tracemalloc.stop()


def test_hadamard_chain_memory_grows_with_the_cube_not_m_times_q():
    # the implicit chain's peak is a few (Q, K) blocks (K ~ 60 slices) plus O(M K) outputs; an
    # (M, Q) float32 matrix alone would grow by 4 x 4096 x (1638 -> 4096) B = 40 MB here (the
    # Gaussian chain's traced peak grows by ~125 MB, the Hadamard one's by ~5 MB)
    cfg = dict(size=64, patterns="hadamard", code_length=1023, iterations=3)
    _peak_bytes(compression=0.1, **cfg)  # one-time allocations (scene, code caches)
    low, _ = _peak_bytes(compression=0.4, **cfg)
    high, (m, q) = _peak_bytes(compression=1.0, **cfg)
    assert high - low < 0.25 * (m - round(0.4 * q)) * q * 4, (low / 1e6, high / 1e6)


@pytest.mark.parametrize("quick", [True, False])
def test_pattern_kind_experiment_points_are_valid_configs(quick, tmp_path):
    from spslidar.config import Config
    from spslidar.experiments.pattern_kinds import pattern_kind_points
    from spslidar.experiments.reproduce import Context

    points = pattern_kind_points(Context(tmp_path, quick=quick))
    sizes = {p["size"] for p in points}
    assert sizes == ({32, 64} if quick else {128, 256})
    for p in points:
        cfg = Config(**{k: v for k, v in p.items() if k != "trial"})
        assert cfg.patterns != "gaussian" or cfg.size == min(sizes)  # dense only where it fits
    assert {p["patterns"] for p in points if p["size"] == max(sizes)} == {
        "hadamard", "scrambled-hadamard"}


@pytest.mark.parametrize("kind", ["hadamard", "scrambled-hadamard"])
@pytest.mark.parametrize("order", HADAMARD_ORDERS)
@pytest.mark.parametrize("share", [1.0, 0.25])
def test_complementary_rows_leave_no_pixel_unseen(kind, order, share):
    """The constant column of the Sylvester matrix is +1 in every shown row of ``shifted``
    (and more columns are in some orders' subsets), so QCR's centring by the mean pattern
    zeroes it and that pixel is never measured; with a random half of the rows shown as
    complements no column of the centred patterns is zero. Everything but the signs is
    ``shifted``'s (the signs are drawn last), no frame is dark, and half the rows flip."""
    n = 16
    m = int(share * n * n)
    got = {r: hadamard_patterns(kind, m, n, np.random.default_rng(5), dtype=np.float64,
                                order=order, realisation=r)
           for r in ("shifted", "complementary")}
    unseen = {r: int(np.sum(np.abs(_centre(p.todense())).max(axis=0) < 1e-12))
              for r, p in got.items()}
    assert unseen["shifted"] >= 1 and unseen["complementary"] == 0, unseen
    a, b = got["shifted"], got["complementary"]
    np.testing.assert_array_equal(a.rows, b.rows)
    for key in ("signs", "perm"):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key))
    assert a.flips is None and int(np.sum(b.flips == -1)) == m // 2
    dense = b.todense()
    assert dense.max(axis=1).min() == 1.0  # no dark frame (the constant row is never flipped)
    np.testing.assert_array_equal(np.where(b.flips[:, None] < 0, 1 - dense, dense),
                                  a.todense())


def test_complementary_rows_read_the_pixel_shifted_rows_never_see(tmp_path):
    """A 0.3 m step on pixel 0 alone, noiseless, every pattern: the shifted rows read it as
    its neighbours' 10 m (the TV's fill), the complementary rows read 10.3 m (within a bin)."""
    from spslidar.cli import main

    d = np.full((16, 16), 10.0)
    d[0, 0] = 10.3
    np.save(tmp_path / "step.npy", d)
    read = {}
    for real in ("shifted", "complementary"):
        out = tmp_path / real
        assert main(["run", "--scene", str(tmp_path / "step.npy"), "--size", "16",
                     "--patterns", "hadamard", "--hadamard-realisation", real,
                     "--compression", "1", "--noiseless", "--code-length", "1023",
                     "--out", str(out), "--no-figure"]) == 0
        read[real] = float(np.load(out / "depth.npy")[0, 0])
    bin_m = 299792458.0 / 2 / 10e9
    assert abs(read["shifted"] - 10.0) < bin_m
    assert abs(read["complementary"] - 10.3) < bin_m


@pytest.mark.parametrize("realisation,says", [("shifted", "(25%)"),
                                              ("complementary", "(25%, complementary)"),
                                              ("differential", "(25%, differential)")])
def test_the_summary_and_the_figure_title_say_how_the_rows_are_shown(realisation, says):
    """Both named the pattern kind alone, so a shifted and a complementary run of the same
    rows read alike (found looking at the figure, 2026-11-30)."""
    from spslidar import run
    from spslidar.figures import _title

    r = run(size=16, code_length=1023, patterns="hadamard", hadamard_realisation=realisation,
            periods=2)
    assert f"hadamard patterns {says}" in r.summary()
    assert f"hadamard patterns {says}" in _title(r)
