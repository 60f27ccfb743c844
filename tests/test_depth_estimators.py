"""Spatial depth estimators (``censor``, ``mrf``): exact on noiseless cubes, thin and slanted
structures kept in noisy ones, a consistent confidence, and no access to the truth."""

from __future__ import annotations

import ast
import inspect
import pathlib
from dataclasses import fields

import numpy as np
import pytest

from spslidar.constants import SPEED_OF_LIGHT
from spslidar.depth import ESTIMATORS, DepthContext, DepthEstimate, profile
from spslidar.depth.censor import CensorDepth, road_linear
from spslidar.depth.guarded import GuardedDepth
from spslidar.depth.mrf import MRFDepth, min_sum_bp, truncated_linear_envelope
from spslidar.forward import depth_to_delay, pulse_overlaps
from spslidar.scenes import load_scene

BW = 1e-10  # 100 ps bins
BIN_M = SPEED_OF_LIGHT * BW / 2  # 1.5 cm
PW = 0.5
SPATIAL = ("censor", "mrf", "guarded", "evidence")
ALL = ("argmax",) + SPATIAL


def cube(depth: np.ndarray, amplitude: np.ndarray | float, margin: int = 6):
    """Noiseless slices of a depth map: each pixel's return split over the bins it overlaps
    (the simulator's pulse model), and the context the pipeline would pass."""
    delay = depth_to_delay(depth.ravel(), BW)
    lo = int(np.floor(delay.min())) - margin
    hi = int(np.floor(delay.max())) + margin
    lags = np.arange(lo, hi + 1)
    bins, w = pulse_overlaps(delay, PW)
    q = depth.size
    x = np.zeros((q, lags.size))
    amp = np.broadcast_to(np.asarray(amplitude, dtype=np.float64), depth.shape).ravel()
    for j in range(bins.shape[1]):
        np.add.at(x, (np.arange(q), bins[:, j] - lo), amp * w[:, j])
    return x, DepthContext(lags, BW, PW, depth.shape, False)


def noisy_scene(seed: int = 0, n: int = 32):
    """A slanted plane (2 bins per pixel) with a dark band of weak returns and a one-pixel
    pole in front; slices with sparse non-negative noise spikes like a TV reconstruction's."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:n, 0:n]
    depth = 3.0 + 2 * BIN_M * x + 0.5 * BIN_M * y  # slanted: 2 bins per column
    amp = np.full((n, n), 1.0)
    weak = (y >= 4) & (y < 14)
    amp[weak] = 0.1  # near the noise spikes' maximum: argmax fails on a third of them
    pole = (x == 20) & (y >= 2)
    depth[pole] = 2.6
    amp[pole] = 0.2  # a moderate return, one pixel wide, across the weak band too
    slices, ctx = cube(depth, amp, margin=12)
    noise = 0.035 * np.abs(rng.standard_normal(slices.shape)) * (rng.random(slices.shape) < 0.65)
    return slices + noise, ctx, depth, weak, pole


def off(est: DepthEstimate, depth: np.ndarray, tol: float = 3 * BIN_M) -> np.ndarray:
    d = est.depth.reshape(depth.shape)
    return ~(np.abs(d - depth) <= tol)


@pytest.mark.parametrize("name", ALL)
@pytest.mark.parametrize("scene", ["room", "street", "steps"])
def test_noiseless_depth_exact_within_the_bin(name, scene):
    sc = load_scene(scene, 32)
    slices, ctx = cube(sc.depth, sc.reflectivity)
    est = ESTIMATORS.load(name)().estimate(slices, ctx)
    err = np.abs(est.depth.reshape(sc.depth.shape) - sc.depth)
    assert np.all(err <= BIN_M / 2 + 1e-9)  # the leading-edge convention: half a bin at most
    # and exactly the argmax's bin: nothing to correct in a noiseless cube
    ref = ESTIMATORS.load("argmax")().estimate(slices, ctx)
    np.testing.assert_allclose(est.depth, ref.depth)


@pytest.mark.parametrize("name", SPATIAL)
def test_subbin_refinement_recovers_fractional_delays(name):
    n = 16
    depth = 4.0 + BIN_M * 0.37 * np.arange(n * n).reshape(n, n) / n  # fractions of a bin
    slices, ctx = cube(depth, 1.0)
    est = ESTIMATORS.load(name)(subbin=True).estimate(slices, ctx)
    coarse = ESTIMATORS.load(name)().estimate(slices, ctx)
    err = np.abs(est.depth.reshape(n, n) - depth)
    assert err.max() < 0.3 * BIN_M
    assert np.mean(err) < np.mean(np.abs(coarse.depth.reshape(n, n) - depth))
    # what the counts hold (the pulse's shape, profile.subbin_offset): a return straddling
    # two bins exactly, one inside its bin at the middle of where it could be (the centroid
    # missed both by up to a quarter bin)
    frac = depth_to_delay(depth, BW) % 1.0
    limit = np.where(frac <= 1 - PW, (1 - PW) / 2 - frac, 0.0) * BIN_M
    np.testing.assert_allclose(est.depth.reshape(n, n) - depth, limit, atol=0.01 * BIN_M)


def test_noisy_scene_is_meaningful():
    from scipy.ndimage import median_filter

    slices, ctx, depth, weak, pole = noisy_scene()
    am = ESTIMATORS.load("argmax")().estimate(slices, ctx)
    bad = off(am, depth)
    assert bad[weak & ~pole].mean() > 0.25  # the weak band defeats a per-pixel estimate ...
    assert bad[~weak].mean() < 0.02  # ... which gets the strong plane and the pole right
    # a naive spatial smoother erases the pole: a median filter, or an MRF whose depth edges
    # cost more than the pole's evidence
    smooth = median_filter(am.depth.reshape(depth.shape), 3)
    assert (np.abs(smooth - depth) > 3 * BIN_M)[pole].mean() > 0.9
    strict = MRFDepth(truncation=8.0, lines=False).estimate(slices, ctx)
    assert off(strict, depth)[pole].mean() > 0.9
    # ... unless the pole's argmax returns, which line up, are kept (spslidar.depth.lines)
    kept = MRFDepth(truncation=8.0).estimate(slices, ctx)
    assert off(kept, depth)[pole].mean() < 0.1 and kept.info["thin_structure_pixels"] >= 25


@pytest.mark.parametrize("name", SPATIAL)
@pytest.mark.parametrize("seed", [0, 1])
def test_slanted_plane_and_one_pixel_pole_survive_noise(name, seed):
    slices, ctx, depth, weak, pole = noisy_scene(seed)
    est = ESTIMATORS.load(name)().estimate(slices, ctx)
    am = ESTIMATORS.load("argmax")().estimate(slices, ctx)
    bad, bad_am = off(est, depth), off(am, depth)
    # censor and evidence keep a pixel's own return wherever it passes their tests, so a few
    # noise spikes of the weak band survive (evidence: 6-7 %, against 0-3 % for the MRFs)
    limit = 0.1 if name in ("censor", "evidence") else 0.05
    assert bad[weak].mean() < limit < bad_am[weak].mean()  # weak slanted band recovered
    assert bad[pole].mean() <= 0.1  # the one-pixel pole is not smoothed away
    plane = ~weak & ~pole
    assert bad[plane].mean() <= 0.01  # nor is the steep plane flattened
    rmse = np.sqrt(np.nanmean((est.depth.reshape(depth.shape) - depth) ** 2))
    rmse_am = np.sqrt(np.nanmean((am.depth.reshape(depth.shape) - depth) ** 2))
    assert rmse < 0.5 * rmse_am


@pytest.mark.parametrize("name", ALL)
def test_confidence_in_unit_interval_and_mask_consistent(name):
    slices, ctx, depth, weak, pole = noisy_scene(2)
    slices[5] = 0.0  # a pixel without any return
    est = ESTIMATORS.load(name)().estimate(slices, ctx)
    q = slices.shape[0]
    for arr in (est.depth, est.confidence, est.peak, est.low_confidence):
        assert arr.shape == (q,)
    assert np.all((est.confidence >= 0) & (est.confidence <= 1))
    assert np.isnan(est.depth[5]) and est.confidence[5] == 0 and not est.low_confidence[5]
    thr = ESTIMATORS.load(name)().low_confidence
    np.testing.assert_array_equal(est.low_confidence,
                                  np.isfinite(est.depth) & (est.confidence < thr))
    if name in SPATIAL:
        # meaningful: the pixels it gets wrong are far less confident than those it gets right
        bad = off(est, depth) & np.isfinite(est.depth.reshape(depth.shape))
        conf = est.confidence.reshape(depth.shape)
        if bad.any():
            assert conf[bad].mean() < 0.7 * conf[~bad].mean()
        assert est.low_confidence.reshape(depth.shape)[weak].mean() > \
            est.low_confidence.reshape(depth.shape)[~weak].mean()


@pytest.mark.parametrize("name", SPATIAL)
def test_estimators_see_only_slices_and_context(name):
    cls = ESTIMATORS.load(name)
    assert list(inspect.signature(cls.estimate).parameters) == ["self", "slices", "ctx"]
    assert {f.name for f in fields(DepthContext)} == {"lags", "bin_width", "pulse_width",
                                                      "shape", "subbin"}
    # no estimator module imports the scenes or the pipeline, or names a truth
    for module in (inspect.getmodule(cls), profile):
        tree = ast.parse(pathlib.Path(module.__file__).read_text())
        names = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}
        names |= {n.attr for n in ast.walk(tree) if isinstance(n, ast.Attribute)}
        assert not names & {"scene", "truth", "load_scene", "Scene", "reflectivity"}
        imported = {a.module or "" for a in ast.walk(tree) if isinstance(a, ast.ImportFrom)}
        imported |= {a.name for i in ast.walk(tree) if isinstance(i, ast.Import) for a in i.names}
        assert not any(m.split(".")[-1] in ("scenes", "pipeline", "metrics") for m in imported)
    # and inputs are not modified
    slices, ctx, *_ = noisy_scene(3, n=16)
    before = slices.copy()
    a = cls().estimate(slices, ctx)
    b = cls().estimate(slices, ctx)
    np.testing.assert_array_equal(slices, before)
    np.testing.assert_array_equal(a.depth, b.depth)


@pytest.mark.parametrize("name", SPATIAL)
def test_spatial_estimators_need_the_image_shape(name):
    slices, ctx, *_ = noisy_scene(n=8)
    bad = DepthContext(ctx.lags, BW, PW, (0, 0), False)
    with pytest.raises(ValueError, match="shape"):
        ESTIMATORS.load(name)().estimate(slices, bad)


def test_truncated_linear_envelope_matches_brute_force():
    rng = np.random.default_rng(4)
    h = rng.normal(size=(5, 23)).astype(np.float64)
    s, t = 0.3, 1.1
    k = np.arange(23)
    pair = np.minimum(s * np.abs(k[:, None] - k[None, :]), t)
    brute = np.min(h[:, None, :] + pair[None], axis=2)
    brute -= brute.min(axis=1, keepdims=True)
    np.testing.assert_allclose(truncated_linear_envelope(h, s, t), brute, atol=1e-12)


def test_bp_is_exact_on_a_chain():
    # on a tree (one image row) min-sum BP gives the exact MAP: compare with Viterbi
    rng = np.random.default_rng(5)
    n, k, s, t = 9, 6, 0.4, 1.0
    cost = rng.normal(size=(k, 1, n))
    belief, _ = min_sum_bp(cost, s, t, iterations=2 * n, patience=0)
    lab = np.arange(k)
    pair = np.minimum(s * np.abs(lab[:, None] - lab[None, :]), t)
    acc, back = cost[:, 0, 0].copy(), []
    for j in range(1, n):
        tot = acc[:, None] + pair  # previous label x current label
        back.append(np.argmin(tot, axis=0))
        acc = tot.min(axis=0) + cost[:, 0, j]
    best = [int(np.argmin(acc))]
    for b in reversed(back):
        best.append(int(b[best[-1]]))
    np.testing.assert_array_equal(np.argmin(belief[:, 0, :], axis=0), best[::-1])


def test_linear_road_is_zero_on_planes_edges_and_poles():
    y, x = np.mgrid[0:12, 0:12]
    plane = 7 * x + 3 * y  # steep slanted plane
    assert np.all(road_linear(plane) == 0)
    scene = plane.copy()
    scene[:, 6] = 200  # a one-pixel pole
    scene[:, 9:] += 50  # and a depth edge
    road = road_linear(scene)
    assert np.all(road[1:-1, 6] == 0) and np.all(road[1:-1, 8:10] == 0)
    spike = plane.copy()
    spike[5, 3] += 40
    assert road_linear(spike)[5, 3] == 40  # no direction of its neighbourhood predicts it


def test_mrf_options_validated():
    with pytest.raises(ValueError, match="smoothness must be a finite number >= 0"):
        MRFDepth(smoothness=-1)
    with pytest.raises(ValueError, match=r"low_confidence must be in \[0, 1\]"):
        MRFDepth(low_confidence=2.0)


@pytest.mark.slow
def test_mrf_beats_argmax_on_the_motorcycle_end_to_end():
    import spslidar

    meas = spslidar.measure(scene="motorcycle", noise=10)
    r = spslidar.reconstruct(meas)
    cfg = r.config
    ctx = DepthContext(np.asarray(r.lags), meas.acq.bin_width, cfg.pulse_width,
                       (cfg.size, cfg.size), cfg.subbin)
    truth, valid = r.scene.depth, r.scene.valid
    rmse = {}
    for name in ("argmax", "mrf"):
        d = ESTIMATORS.load(name)().estimate(r.slices, ctx).depth.reshape(truth.shape)
        have = valid & np.isfinite(d)
        rmse[name] = float(np.sqrt(np.mean((d[have] - truth[have]) ** 2)))
    assert rmse["mrf"] < 0.5 * rmse["argmax"]
    assert rmse["mrf"] < 0.1


def poles_and_fence(n: int = 24):
    """A wall at 4 m with one-pixel poles at 3 m (one bright, one dark: 0.05 against the
    wall's 0.6) and a mesh at 2.5 m over the middle rows in front of it (half a pixel's
    footprint each: returns of 0.45 from the mesh and 0.3 from the wall)."""
    depth = np.full((n, n), 4.0)
    amp = np.full((n, n), 0.6)
    depth[:, 5], amp[:, 5] = 3.0, 1.0
    depth[:, 9], amp[:, 9] = 3.0, 0.05
    mesh = np.zeros((n, n), bool)
    mesh[14:20, 12:22] = True
    depth[mesh], amp[mesh] = 2.5, 0.45
    front, ctx = cube(depth, amp, margin=12)
    behind = np.where(mesh, 4.0, depth)
    back, _ = cube(behind, np.where(mesh, 0.3, 0.0), margin=12)
    lag0 = int(np.floor(depth_to_delay(np.array([behind.min()]), BW)[0])) - 12
    lags0 = int(np.floor(depth_to_delay(np.array([depth.min()]), BW)[0])) - 12
    # both blocks on the front block's lags (the wall behind lies inside them)
    shift = lag0 - lags0
    slices = front.copy()
    slices[:, shift:shift + back.shape[1]] += back[:, : slices.shape[1] - shift]
    return slices, ctx, depth, mesh


def test_poles_and_fence_setup_is_meaningful():
    slices, ctx, depth, mesh = poles_and_fence()
    am = ESTIMATORS.load("argmax")().estimate(slices, ctx)
    assert not off(am, depth).any()  # noiseless: the mesh, stronger, is each pixel's tallest


@pytest.mark.parametrize("name", ALL)
def test_noiseless_one_pixel_poles_and_fence_recovered(name):
    slices, ctx, depth, mesh = poles_and_fence()
    est = ESTIMATORS.load(name)().estimate(slices, ctx)
    err = np.abs(est.depth.reshape(depth.shape) - depth)
    assert np.all(err <= BIN_M / 2 + 1e-9)  # the dark pole and the mesh's first surface too


def test_guarded_reports_the_second_surface_of_a_fence():
    slices, ctx, depth, mesh = poles_and_fence()
    est = ESTIMATORS.load("guarded")().estimate(slices, ctx)
    d2 = est.depth2.reshape(depth.shape)
    assert np.isfinite(d2[mesh]).all()
    assert np.all(np.abs(d2[mesh] - 4.0) <= BIN_M / 2 + 1e-9)  # the wall behind the mesh
    assert np.isnan(d2[~mesh]).all()  # one surface elsewhere, poles included
    assert est.info["two_surface_fraction"] == pytest.approx(mesh.mean())


def test_second_surface_needs_significance_not_just_a_second_maximum():
    from spslidar.depth.guarded import GuardedDepth

    slices, ctx, depth, weak, pole = noisy_scene(4)
    est = GuardedDepth().estimate(slices, ctx)
    # one surface per pixel, with noise spikes: every profile has a second maximum, but
    # few pass the test
    assert np.isfinite(est.depth2).mean() < 0.03
    assert all(ESTIMATORS.load(n)().estimate(slices, ctx).depth2 is None
               for n in ("argmax", "censor", "mrf"))
    assert np.isfinite(ESTIMATORS.load("evidence")().estimate(slices, ctx).depth2).mean() < 0.03


def test_neighbour_support_keeps_surfaces_and_drops_lone_peaks():
    from spslidar.depth.guarded import neighbour_support

    first = np.full((6, 6), 10)
    second = np.full((6, 6), -1)
    second[1:4, 1:4] = 20  # a surface seen through a 3x3 mesh
    second[5, 5] = 30  # a lone peak
    second[0, 5] = 9  # the wall beside it, behind a one-pixel occluder: its neighbours' first
    out = neighbour_support(first.ravel(), second.ravel(), (6, 6)).reshape(6, 6)
    assert np.all(out[1:4, 1:4] == 20)  # every mesh pixel has >= 3 mesh neighbours
    assert out[5, 5] == -1 and out[0, 5] == 9
    assert np.all(out[second < 0] == -1)  # nothing added
    assert np.array_equal(neighbour_support(first.ravel(), second.ravel(), (6, 6), need=0),
                          second.ravel())
    strict = neighbour_support(first.ravel(), second.ravel(), (6, 6), need=4).reshape(6, 6)
    assert strict[1, 1] == -1 and strict[2, 2] == 20  # a mesh corner has 3 such neighbours


def test_second_surfaces_of_lone_noise_peaks_are_dropped():
    from spslidar.depth.guarded import GuardedDepth

    slices, ctx, depth, weak, pole = noisy_scene(4)
    plain = np.isfinite(GuardedDepth(support=0).estimate(slices, ctx).depth2).sum()
    kept = np.isfinite(GuardedDepth().estimate(slices, ctx).depth2).sum()
    assert kept < plain  # one surface per pixel here: every second surface is a false one
    with pytest.raises(ValueError, match="support"):
        GuardedDepth(support=9)


def test_guard_keeps_a_strong_one_pixel_pole_that_the_mrf_smooths_away():
    from spslidar.depth.guarded import GuardedDepth

    slices, ctx, depth, weak, pole = noisy_scene(0)
    strict = MRFDepth(truncation=8.0, lines=False).estimate(slices, ctx)  # erases the pole
    guarded = GuardedDepth(truncation=8.0).estimate(slices, ctx)
    assert off(strict, depth)[pole].mean() > 0.9
    assert off(guarded, depth)[pole & ~weak].mean() < 0.1


@pytest.mark.slow
@pytest.mark.parametrize("seed", [3, 11, 5])
def test_default_within_five_percent_of_argmax_on_procedural_scenes(seed):
    # seed 3 at 32x32, 50 %: the MRF replaces thin objects that argmax keeps; on FISTA's 0.3
    # slices it lost (0.346 against 0.275 m), on its default 0.45 slices it is within 5 %
    # (0.361 against 0.354 m, measured 2026-11-27)
    from spslidar.config import Config

    rmse = _procedural_rmse(seed, ("argmax", Config().depth))
    assert rmse[Config().depth] <= 1.05 * rmse["argmax"]


def _procedural_rmse(seed: int, names) -> dict[str, float]:
    """Each estimator's depth RMSE on one measurement of ``procedural:seed`` (32x32, m_n 5,
    50 % patterns), all reading the same reconstructed slices."""
    import spslidar

    meas = spslidar.measure(scene=f"procedural:{seed}", size=32, noise=5, compression=0.5,
                            seed=seed)
    r = spslidar.reconstruct(meas)
    ctx = DepthContext(np.asarray(r.lags), meas.acq.bin_width, r.config.pulse_width,
                       (32, 32), False)
    truth, valid = r.scene.depth, r.scene.valid
    rmse = {}
    for name in names:
        d = ESTIMATORS.load(name)().estimate(r.slices, ctx).depth.reshape(truth.shape)
        have = valid & np.isfinite(d)
        rmse[name] = float(np.sqrt(np.mean((d[have] - truth[have]) ** 2)))
    return rmse


def test_line_evidence_supports_a_pole_not_a_spike():
    from spslidar.depth.evidence import line_evidence, neighbour_share

    n, k = 7, 12
    z = np.zeros((n, n, k))
    z[:, 3, 5] = 2.0  # a one-pixel pole at slice 5, whole column
    z[1, 1, 9] = 6.0  # an isolated spike at slice 9
    z[5, 5, 8] = 1.0  # slanted: a neighbour of the pole's line one slice off still counts
    lab = np.argmax(z, axis=2).ravel()
    ev = line_evidence(z.reshape(n * n, k), lab, (n, n)).reshape(n, n)
    assert ev[3, 3] == pytest.approx(6.0)  # itself and both pole neighbours
    assert ev[0, 3] == pytest.approx(4.0)  # the pole's end: one neighbour inside the image
    assert ev[1, 1] == pytest.approx(6.0)  # the spike: its own evidence only
    share = neighbour_share(np.eye(n, dtype=bool), (n, n)).reshape(n, n)
    assert share[3, 3] == pytest.approx(3 / 9) and share[0, 0] == pytest.approx(2 / 9)


def test_evidence_keeps_a_one_pixel_pole_the_mrf_erases_by_its_line_alone():
    from spslidar.depth.evidence import EvidenceDepth

    slices, ctx, depth, weak, pole = noisy_scene(0)
    strict = MRFDepth(truncation=8.0, lines=False).estimate(slices, ctx)
    assert off(strict, depth)[pole].mean() > 0.9
    # only the line test: no strong-return or occluder keeps
    line_only = EvidenceDepth(truncation=8.0, strong=1e9, occluder=1e9).estimate(slices, ctx)
    assert off(line_only, depth)[pole].mean() < 0.1
    assert line_only.info["kept_line"] > 0
    # and the weak band is still the MRF's: the line test does not keep noise spikes
    am = ESTIMATORS.load("argmax")().estimate(slices, ctx)
    assert off(line_only, depth)[weak & ~pole].mean() < 0.5 * off(am, depth)[weak & ~pole].mean()


def test_evidence_options_validated():
    from spslidar.depth.evidence import EvidenceDepth

    with pytest.raises(ValueError, match="strong must be a finite number >= 0"):
        EvidenceDepth(strong=-1)
    with pytest.raises(ValueError, match=r"share must be a finite number in \[0, 1\]"):
        EvidenceDepth(share=1.5)


@pytest.mark.parametrize("seed", [3, 11, 5])
def test_evidence_within_five_percent_of_argmax_on_procedural_scenes(seed):
    # the case the MRF loses most (seed 3, thin objects: 0.342 against argmax's 0.354 m at
    # 32x32, 50 %) and two it wins (0.135 / 0.191 against 0.258 / 0.311 m)
    rmse = _procedural_rmse(seed, ("argmax", "evidence"))
    assert rmse["evidence"] <= 1.05 * rmse["argmax"]
    if seed != 3:  # and better where noise, not thin objects, is what argmax gets wrong
        assert rmse["evidence"] < 0.95 * rmse["argmax"]


@pytest.mark.parametrize("name", ["guarded", "evidence"])
def test_a_featureless_profile_holds_no_second_surface(name):
    """Every slice equal: guarded and evidence gave a second surface on every pixel (an
    audit of 2026-11-28); there is no return beside the first, let alone a second."""
    from spslidar.depth import ESTIMATORS
    from spslidar.depth.base import DepthContext

    x = np.ones((64, 20))
    ctx = DepthContext(lags=np.arange(100, 120), bin_width=1e-10, shape=(8, 8))
    out = ESTIMATORS.load(name)().estimate(x, ctx)
    assert out.depth2 is not None and not np.isfinite(out.depth2).any()


@pytest.mark.parametrize("make", [
    lambda: GuardedDepth(scale=float("nan")), lambda: GuardedDepth(scale=float("inf")),
    lambda: GuardedDepth(gap=2.9), lambda: GuardedDepth(support=1.5),
    lambda: GuardedDepth(quantile="x"), lambda: MRFDepth(smoothness=float("nan")),
    lambda: MRFDepth(iterations=True), lambda: MRFDepth(truncation=float("nan")),
    lambda: CensorDepth(window=2.5), lambda: CensorDepth(gap=0),
])
def test_estimator_options_are_finite_whole_where_counted_and_one_line(make):
    """NaN passed every '<' test and gap=2.9 was taken as 2 (an audit of 2026-11-29): each is
    a ConfigError now, the CLI's one line."""
    from spslidar.errors import ConfigError

    with pytest.raises(ConfigError, match="must be"):
        make()


def test_evidence_options_refuse_nan():
    from spslidar.depth.evidence import EvidenceDepth
    from spslidar.errors import ConfigError

    for kw in ({"strong": float("nan")}, {"line": float("nan"), "strong": 1.0}):
        with pytest.raises(ConfigError, match="finite"):
            EvidenceDepth(**kw)
    assert GuardedDepth(gap=3.0).gap == 3 and isinstance(GuardedDepth(gap=3.0).gap, int)


def test_estimator_options_refuse_a_numpy_bool():
    from spslidar.errors import ConfigError

    with pytest.raises(ConfigError, match="iterations"):
        MRFDepth(iterations=np.bool_(True))
    assert MRFDepth(iterations=np.int64(5)).iterations == 5


@pytest.mark.parametrize("width", [0.5, 1.0])
def test_refine_subbin_leaves_out_a_column_that_is_not_the_adjacent_delay(width):
    """The centroid (a pulse of a bin or more) read a neighbour column three delays away as a
    share of the return (0.44 of a slice across the jump: a review)."""
    x = np.zeros((1, 6))
    x[0, 2], x[0, 3] = 1.0, 0.8
    lags = np.array([10, 11, 12, 15, 16, 17])
    got = profile.refine_subbin(x, np.array([2]), pulse_width=width, lags=lags)
    assert got[0] == pytest.approx(2.0, abs=1e-12)
