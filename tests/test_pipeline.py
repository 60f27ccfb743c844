"""End to end: noiseless recovery, PSST vs conventional, range aliasing, reproducibility."""

import json

import numpy as np
import pytest

from spslidar import pipeline
from spslidar.config import Config
from spslidar.constants import SPEED_OF_LIGHT
from spslidar.errors import ConfigError

BIN = SPEED_OF_LIGHT * 1e-10 / 2  # 1.5 cm


@pytest.mark.parametrize("qcr", [False, True])
def test_noiseless_full_sampling_recovers_every_pixel_within_one_bin(qcr):
    r = pipeline.run(scene="steps", size=16, compression=1.0, code_length=1023, noiseless=True,
                     qcr=qcr, iterations=300)
    err = np.abs(r.depth - r.truth)
    assert np.all(np.isfinite(r.depth))
    assert err.max() <= BIN, f"max error {err.max():.4f} m"


def test_noiseless_subbin_beats_bin_quantisation():
    """On a noiseless, fully sampled ramp the sub-bin estimate beats the bins' quantisation
    (measured: 0.0043 -> 0.0034-0.0035 m with either TV). The default path (QCR): without
    QCR the noiseless ramp's TV optimum erodes its thin slices with either TV (0.024 m at 1500
    iterations), so that path's error depends on where the iterations stop."""
    kw = dict(scene="ramp", size=16, compression=1.0, code_length=1023, noiseless=True,
              iterations=300)
    plain = pipeline.run(**kw)
    sub = pipeline.run(**kw, subbin=True)
    assert sub.depth_rmse < 0.9 * plain.depth_rmse


def test_psst_with_qcr_beats_conventional_at_mn10():
    kw = dict(size=32, code_length=4095, noise=10.0, seed=1)
    psst = pipeline.run(**kw, lidar="psst", qcr=True)
    conv = pipeline.run(**kw, lidar="conventional", qcr=True)
    assert psst.depth_rmse < 0.5 * conv.depth_rmse
    # same acquisition time per pattern
    assert conv.metrics["acquisition_time_per_pattern_s"] <= \
        psst.metrics["acquisition_time_per_pattern_s"]


def test_conventional_10mhz_aliases_a_20m_scene_psst_does_not():
    kw = dict(scene="camera", size=16, range_gate=(1.0, 30.0), noise=1.0, seed=2)
    conv = pipeline.run(**kw, lidar="conventional", rep_rate=10e6)
    assert conv.metrics["unambiguous_range_m"] == pytest.approx(14.99, abs=0.01)
    assert any("unambiguous range" in w for w in conv.warnings)
    shift = np.nanmedian(conv.depth - conv.truth)
    assert shift == pytest.approx(-conv.metrics["unambiguous_range_m"], abs=0.05)
    psst = pipeline.run(**kw, lidar="psst", code_length=16383)
    assert abs(np.nanmedian(psst.depth - psst.truth)) < 0.05
    assert not any("unambiguous range" in w for w in psst.warnings)


def test_a_code_the_conventional_lidar_ignores_cannot_refuse_it():
    """--lidar conventional --code gold --code-length 4095 was refused (no Gold code of 4095
    bits) although the run fires single pulses and warns that the code is ignored; with
    --fairness power its ones count sets the pulses, and the refusal stands."""
    kw = dict(size=8, code_length=4095, lidar="conventional", code="gold", noise=1.0)
    conv = pipeline.run(**kw)
    assert any("ignored" in w and "--code gold" in w for w in conv.warnings)
    same = pipeline.run(**{**kw, "code": "mseq"})
    np.testing.assert_array_equal(conv.depth, same.depth)  # the code made no difference
    with pytest.raises(ConfigError, match="not valid for a Gold code"):
        pipeline.run(**kw, fairness="power")


def test_seeded_runs_are_reproducible():
    kw = dict(size=16, code_length=1023)
    a, b = pipeline.run(**kw, seed=5), pipeline.run(**kw, seed=5)
    c = pipeline.run(**kw, seed=6)
    np.testing.assert_array_equal(a.depth, b.depth)
    assert not np.array_equal(a.corr, c.corr)


def test_all_solvers_run_through_the_pipeline():
    rmse = {}
    for solver in ("fista", "twist", "tval3", "gpsr"):
        r = pipeline.run(size=32, code_length=4095, solver=solver)
        assert r.metrics["solver_info"]["solver"] == solver
        rmse[solver] = r.depth_rmse
    best = min(rmse.values())
    assert max(rmse.values()) < 4 * best + 0.01, rmse


def test_save_is_atomic(tmp_path, monkeypatch):
    r = pipeline.run(size=16, code_length=1023)
    out = r.save(tmp_path / "res")
    # (hidden files: the result's own marker)
    assert sorted(p.name for p in out.iterdir() if not p.name.startswith(".")) == [
        "confidence.npy", "depth.npy", "depth.png", "metrics.json", "points.ply",
        "reflectivity.npy", "truth.npy", "valid.npy"]
    m = json.loads((out / "metrics.json").read_text())
    assert m["depth_rmse_m"] == pytest.approx(r.depth_rmse)
    assert {"total", "simulate", "solve"} <= set(m["timing_s"])
    assert m["config"]["code_length"] == 1023 and m["seed"] == 0 and m["version"]

    import spslidar.figures

    def boom(*a, **k):
        raise RuntimeError("disk full")

    monkeypatch.setattr(spslidar.figures, "depth_figure", boom)
    with pytest.raises(RuntimeError):
        r.save(tmp_path / "half")
    assert not (tmp_path / "half").exists()
    assert [p.name for p in tmp_path.iterdir()] == ["res"]


def test_run_accepts_config_objects_and_dicts():
    cfg = Config(size=16, code_length=1023)
    a = pipeline.run(cfg)
    b = pipeline.run({"size": 16, "code-length": 1023})
    np.testing.assert_array_equal(a.depth, b.depth)
    m = pipeline.run_metrics({"size": 16, "code_length": 1023})
    assert m["depth_rmse_m"] == pytest.approx(a.depth_rmse)


# -- the simulation: fast path vs brute force -------------------------------------------------


def _small_measurement(**kw):
    cfg = dict(scene="steps", size=8, code_length=127, compression=1.0, seed=3)
    cfg.update(kw)
    return pipeline.measure(**cfg)


def _simulate(meas, seed, **kw):
    from spslidar.detectors.counting import NoiseModel
    from spslidar.detectors.linear import LinearDetector

    cfg = meas.config
    noise = NoiseModel(cfg.noise, tuple(cfg.noise_split), cfg.ambient, cfg.background_rate,
                       cfg.dark_count_rate)
    det = LinearDetector(dead_time=cfg.dead_time, efficiency=kw.pop("efficiency", 1.0))
    return pipeline.simulate_correlations(meas.patterns, meas.scene, meas.acq, meas.ulags, noise,
                                          det, cfg.pulse_width, np.random.default_rng(seed),
                                          **kw)


def _exact_moments(meas):
    """Exact mean and covariance of (C(tau_1..tau_K), N) per pattern, from eq. (4) written out
    pixel by pixel (independently of spslidar.forward's grouping by delay)."""
    from spslidar.correlate import correlation_gain, make_replica
    from spslidar.detectors.counting import NoiseModel
    from spslidar.forward import depth_to_delay, pulse_overlaps

    cfg, acq = meas.config, meas.acq
    period = acq.period
    code = acq.code.astype(float)
    phi = meas.patterns.todense().astype(float)
    alpha = meas.scene.reflectivity.ravel()
    bins, w = pulse_overlaps(depth_to_delay(meas.scene.depth.ravel(), acq.bin_width),
                             cfg.pulse_width)
    per_pixel = np.zeros((alpha.size, period))
    for j in range(alpha.size):
        for p in range(bins.shape[1]):
            per_pixel[j] += alpha[j] * w[j, p] * np.roll(code, bins[j, p] % period)
    noise = NoiseModel(cfg.noise).per_bin(meas.patterns, alpha, acq.bin_width)
    lam = acq.n_periods * (acq.signal_per_pulse * phi @ per_pixel + noise[:, None])
    f = make_replica(acq.code, acq.replica)
    gain = correlation_gain(acq.code, f) * acq.n_periods * acq.signal_per_pulse
    # the K+1 linear functionals of the histogram: the replica at each gated lag, and the total
    weights = np.stack([np.roll(f, int(lag)) / gain for lag in meas.ulags] + [np.ones(period)])
    mean = lam @ weights.T  # (M, K+1)
    cov = np.einsum("it,at,bt->iab", lam, weights, weights)  # Poisson: Var h(t) = lam(t)
    return mean, cov


def _stack_runs(meas, seeds, method):
    out = []
    for s in seeds:
        sim = _simulate(meas, s, method=method)
        out.append(np.column_stack([sim["corr"], sim["counts"]]))
    return np.asarray(out, dtype=np.float64)  # (R, M, K+1)


@pytest.mark.parametrize("lidar,code_length", [("psst", 127), ("conventional", 2047)])
def test_fast_simulation_equals_brute_force_without_noise(lidar, code_length):
    meas = _small_measurement(lidar=lidar, code_length=code_length, noise=3.0)
    a = _simulate(meas, 0, noiseless=True, method="fast", efficiency=0.7)
    b = _simulate(meas, 0, noiseless=True, method="reference", efficiency=0.7)
    scale = np.abs(b["corr"]).max()
    np.testing.assert_allclose(a["corr"], b["corr"], rtol=0, atol=2e-6 * scale)
    np.testing.assert_allclose(a["counts"], b["counts"], rtol=1e-6)
    np.testing.assert_allclose(a["sigma"], b["sigma"], rtol=1e-6)
    mean, _ = _exact_moments(meas)
    np.testing.assert_allclose(b["corr"], 0.7 * mean[:, :-1], rtol=0, atol=2e-6 * scale)


def test_fast_simulation_has_the_distribution_of_the_brute_force_one():
    """Mean, variance and the covariance between lags (and with the total count) of the gated
    matched-filter outputs: fast path, brute force, and the exact moments agree."""
    meas = _small_measurement(noise=2.0, signal=1.0)
    reps = 300
    fast = _stack_runs(meas, range(1000, 1000 + reps), "fast")
    ref = _stack_runs(meas, range(5000, 5000 + reps), "reference")
    mean, cov = _exact_moments(meas)
    var = np.einsum("iaa->ia", cov)
    for sample in (fast, ref):
        z = (sample.mean(axis=0) - mean) / np.sqrt(var / reps)
        assert abs(z.mean()) < 0.1 and np.abs(z).max() < 5.5, (z.mean(), np.abs(z).max())
        ratio = sample.var(axis=0, ddof=1) / var
        # each ratio ~ chi2(R-1)/(R-1): sd sqrt(2/R) = 0.08; averaged over ~1000 outputs
        assert abs(ratio.mean() - 1) < 0.02 and ratio.min() > 0.6 and ratio.max() < 1.45
    # two-sample: the fast and brute-force means and variances agree with each other
    z2 = (fast.mean(axis=0) - ref.mean(axis=0)) / np.sqrt(2 * var / reps)
    assert abs(z2.mean()) < 0.1 and np.abs(z2).max() < 5.5
    assert abs(np.mean(fast.var(axis=0, ddof=1) / ref.var(axis=0, ddof=1)) - 1) < 0.03
    # joint structure: correlation matrix of (C(tau_1), ..., C(tau_K), N), pooled over patterns
    # (off the diagonal, which the variance test covers)
    sd = np.sqrt(var)
    exact_corr = cov / sd[:, :, None] / sd[:, None, :]
    off = ~np.eye(exact_corr.shape[1], dtype=bool)
    for sample in (fast, ref):
        c = sample - sample.mean(axis=0)
        emp = np.einsum("ria,rib->iab", c, c) / (reps - 1) / sd[:, :, None] / sd[:, None, :]
        err = (emp - exact_corr).mean(axis=0)  # mean over 64 patterns: sd <= 1/sqrt(64 R)
        assert np.abs(err[off]).max() < 5 / np.sqrt(64 * reps)
        assert abs(err[off].mean()) < 0.1 * abs(exact_corr[:, off].mean())
    # the lags are weakly but really correlated (the m-sequence's -1 sidelobes, the signal, the
    # shared total): drawing each lag's output on its own would set this to zero
    assert abs(exact_corr[:, off].mean()) > 0.005


def test_simulation_does_not_depend_on_threads(monkeypatch):
    meas = _small_measurement(size=16, code_length=255)  # 256 patterns: 4 blocks
    a = _simulate(meas, 7, threads=1)
    b = _simulate(meas, 7, threads=3)
    import spslidar.pipeline.simulate as simulate

    monkeypatch.setattr(simulate, "single_threaded_blas", lambda: None)  # no threadpoolctl
    c = _simulate(meas, 7, threads=2)
    for k in ("corr", "counts", "sigma"):
        np.testing.assert_array_equal(a[k], b[k])
        np.testing.assert_array_equal(a[k], c[k])
    assert not np.array_equal(a["corr"], _simulate(meas, 8)["corr"])


def test_simulation_counts_are_poisson_totals():
    meas = _small_measurement()
    sim = _simulate(meas, 1)
    assert np.all(sim["counts"] == np.round(sim["counts"]))
    mean, cov = _exact_moments(meas)
    z = (sim["counts"] - mean[:, -1]) / np.sqrt(cov[:, -1, -1])
    assert abs(z.mean()) < 4 / np.sqrt(z.size) and np.abs(z).max() < 5
    from spslidar.correlate import correlation_gain, make_replica

    acq = meas.acq
    gain = correlation_gain(acq.code, make_replica(acq.code, acq.replica)) * acq.signal_per_pulse
    np.testing.assert_allclose(sim["sigma"] * gain, np.sqrt(sim["counts"]), rtol=1e-12)


def test_simulation_rejects_unknown_method():
    from spslidar.errors import ConfigError

    with pytest.raises(ConfigError, match="unknown simulation method 'gaussian'"):
        _simulate(_small_measurement(), 0, method="gaussian")


@pytest.mark.parametrize("method", ["fast", "reference"])
def test_simulation_rejects_means_beyond_float32_counts(method):
    meas = _small_measurement()
    meas.acq.signal_per_pulse = 1e7  # ~1e8 photons per bin: not exact in float32
    with pytest.raises(ValueError, match="a count holds exactly"):
        _simulate(meas, 0, method=method)
    with pytest.raises(ValueError, match="a count holds exactly"):
        pipeline.measure(scene="steps", size=8, code_length=127, signal=1e7)
    meas = _small_measurement()
    meas.patterns = meas.patterns.todense() - 50.0  # negative transmittances: refused as such
    with pytest.raises(ValueError, match=r"transmittances in \[0, 1\], got values from -50"):
        _simulate(meas, 0, method=method)
    from spslidar.patterns import DensePatterns

    neg = DensePatterns(meas.patterns + 50.0)
    neg.matrix = neg.matrix - 50.0  # past the patterns' own check: the means' check remains
    meas.patterns = neg
    with pytest.raises(ValueError, match="must be finite and non-negative"):
        _simulate(meas, 0, method=method)


def test_run_shared_reuses_the_measurement_and_equals_run(monkeypatch):
    pipeline.clear_shared()
    calls = []
    real = pipeline.measure

    def counting(cfg=None, **kw):
        calls.append(1)
        return real(cfg, **kw)

    import spslidar.pipeline.chain as chain
    import spslidar.pipeline.shared as shared

    monkeypatch.setattr(chain, "measure", counting)
    a = pipeline.run_shared(size=16, solver="fista", seed=4)
    b = pipeline.run_shared(size=16, solver="tval3", lam_scale=0.5, seed=4)
    assert len(calls) == 1  # the second run only changed processing keys
    assert not a.metrics["measurement_reused"] and b.metrics["measurement_reused"]
    assert b.config.solver == "tval3" and b.config.lam_scale == 0.5
    ref = pipeline.run(size=16, solver="tval3", lam_scale=0.5, seed=4)
    np.testing.assert_array_equal(b.depth, ref.depth)
    assert b.timing["simulate"] == a.timing["simulate"]  # the time it took to simulate
    # another seed is another measurement; the oldest is dropped beyond SHARED_MEASUREMENTS
    monkeypatch.setattr(shared, "SHARED_MEASUREMENTS", 1)
    pipeline.run_shared(size=16, seed=5)
    pipeline.run_shared(size=16, seed=4)
    assert len(calls) == 4  # run() above, then both of these
    pipeline.clear_shared()


@pytest.mark.parametrize("kw, said, fix", [
    ({"lidar": "conventional", "periods": 16, "replica": "bipolar"},
     "pedestal of -1.00 times its return, which the solve's non-negativity clips: depths can "
     "be lost or wrong; --replica auto takes the unipolar replica", {"replica": "auto"}),
    ({"code": "random", "ones_ratio": 0.1, "replica": "bipolar"}, "pedestal of -0.7",
     {"replica": "auto"}),
    ({"regulariser": "l1", "replica": "unipolar"}, "the l1 prior shrinks",
     {"regulariser": "tv"}),
])
def test_a_replica_whose_plateau_no_step_undoes_is_said(kw, said, fix):
    """A bipolar replica on an unbalanced code (or a single pulse) leaves a pedestal below
    zero that the non-negative solve clips, and a unipolar plateau under a sparsity prior is
    shrunk before it is taken out: noiseless 16x16 steps read 0.22-0.31 m with 28-34 % of
    their pixels lost, with no word (an outside audit, options paired). What the warning
    advises is exact on the same scene, and says nothing."""
    base = dict(scene="steps", size=16, code_length=1023, compression=0.5, noiseless=True)
    r = pipeline.run(**base, **kw)
    assert any(said in w for w in r.warnings), r.warnings
    assert r.depth_rmse > 0.1  # (what the warning is about)
    advised = pipeline.run(**base, **{**kw, **fix})
    assert advised.depth_rmse < 0.005
    assert not any("pedestal" in w or "prior shrinks" in w for w in advised.warnings)


def test_a_code_too_short_for_any_replica_is_told_to_be_longer():
    """A 3-bit code (one bit on) leaves a pedestal of -1.00 through the bipolar replica that
    --replica auto itself takes, and -0.50 through the zero-mean one: the advice named the
    replica in use; it names the code's length now (about 21 bits puts the zero-mean
    replica's pedestal under 0.05 of the return)."""
    r = pipeline.run(scene="steps", size=8, code="random", code_length=3, seed=0,
                     noiseless=True)
    said = [w for w in r.warnings if "pedestal" in w]
    assert len(said) == 1 and "--replica auto takes" not in said[0], said
    assert ("no replica avoids it for a code of 3 bits (the zero-mean one leaves -0.50): "
            "use a code of at least 21 bits (--code-length)") in said[0]
    from spslidar.correlate import PLATEAU_SHARE, replica_plateau

    bits = np.zeros(21)
    bits[:10] = 1  # 10 of 21: the zero-mean replica's pedestal is -1 / 20, at the line
    assert replica_plateau(bits, "zero-mean") == pytest.approx(-PLATEAU_SHARE)


def test_a_short_code_whose_auto_replica_leaves_a_pedestal_is_told_the_one_that_does_not():
    """A 7-bit code of 5 ones takes the zero-mean replica under --replica auto, a pedestal
    of -1 / 6; the bipolar one leaves a plateau of +2 / 6 that is taken out, not clipped:
    that one is named, not "use a longer code" (the review's first version said so)."""
    from types import SimpleNamespace

    from spslidar.correlate import auto_replica, replica_plateau
    from spslidar.pipeline.plan import plateau_notes

    code = np.zeros(7)
    code[:5] = 1
    assert auto_replica(code) == "zero-mean"
    acq = SimpleNamespace(code=code, lidar="psst", replica="zero-mean")
    said = plateau_notes(acq, replica_plateau(code, "zero-mean"), False, "tv")
    assert len(said) == 1 and said[0].endswith("; --replica bipolar leaves +0.33"), said


def test_auto_takes_the_more_level_replica_of_a_code_one_bit_short_of_balance():
    """A 31-bit code of 15 ones was taken as balanced (``|2k - T| <= 1``) and given the
    bipolar replica, whose pedestal (-2 / 30) is twice the zero-mean one's (-1 / 30): auto
    takes the zero-mean one now, and says nothing; one more one (an m-sequence's count) keeps
    the bipolar replica, level to the bit (a review of 2026-12-03)."""
    from types import SimpleNamespace

    from spslidar.correlate import auto_replica, replica_plateau
    from spslidar.pipeline.plan import plateau_notes

    for ones, kind, level in ((15, "zero-mean", -1 / 30), (16, "bipolar", 0.0)):
        code = np.zeros(31)
        code[:ones] = 1
        assert auto_replica(code) == kind
        assert replica_plateau(code, kind) == pytest.approx(level, abs=1e-12)
        acq = SimpleNamespace(code=code, lidar="psst", replica=kind)
        assert plateau_notes(acq, replica_plateau(code, kind), False, "tv") == []
    code = np.zeros(30)  # an even count: half the bits ones ties, bipolar kept
    code[:15] = 1
    assert auto_replica(code) == "bipolar"
    assert replica_plateau(code, "bipolar") == pytest.approx(
        replica_plateau(code, "zero-mean"), abs=1e-12)
