"""``reflectivity.npy`` through a simulated instrument's IRF and jitter
(:func:`spslidar.instrument.window_share`): the share of a return within the window the
reflectivity is read over, against a Monte-Carlo of the photons' arrival times, and a run
whose IRF has a tail read at the scene's reflectivity (an outside audit of 2026-12-03 found
0.74-0.79 of it)."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from spslidar.cli import main
from spslidar.instrument import window_share
from spslidar.scenes import load_scene

BIN = 1e-10  # seconds per TDC bin (10 GHz)
PERIOD = 1023


def _monte_carlo(draw_jitter, pulse: float = 0.5, offsets: int = 32, n: int = 200_000,
                 seed: int = 0, then=None) -> float:
    """The window's share by drawing photons: a return at ``100 + u`` bins (``u`` the
    offsets' midpoints), each photon ``U pulse`` later (the RZ pulse) plus its jitter, binned
    (``then``: a detector's jitter after that, the photon uniform within its bin, as the GMAPD
    model convolves its histogram); the tallest bin's and its two neighbours' share, averaged
    over the offsets."""
    rng = np.random.default_rng(seed)
    shares = []
    for u in (np.arange(offsets) + 0.5) / offsets:
        t = 100 + u + rng.random(n) * pulse + draw_jitter(rng, n)
        if then is not None:
            t = np.floor(t) + rng.random(n) + then(rng, n)
        counts = np.bincount(np.floor(t).astype(np.int64) - 50, minlength=200)
        top = int(np.argmax(counts))
        shares.append(counts[top - 1: top + 2].sum() / n)
    return float(np.mean(shares))


def test_an_ideal_instrument_holds_the_whole_return():
    """A half-bit pulse covers at most two bins, both within a bin of the tallest."""
    assert window_share(SimpleNamespace(irf=None, pulse_width=0.5), BIN, PERIOD) == 1.0
    assert window_share(SimpleNamespace(irf=None, pulse_width=0.5), BIN, PERIOD,
                        {"jitter": 0.0, "jitter_tail": 0.0, "jitter_tail_weight": 0.0}) == 1.0


@pytest.mark.parametrize("fwhm, tail, weight", [(150e-12, 0.0, 0.0), (150e-12, 400e-12, 0.3),
                                                (300e-12, 200e-12, 0.6)])
def test_an_irfs_share_equals_the_photons_drawn(fwhm, tail, weight):
    """A parametric IRF (Gaussian, with an exponential tail) against 6.4 M photons drawn
    with NumPy: the binomial error of each offset's share is under 1e-3, its mean's under
    2e-4, so 3e-3 holds whatever the draw."""
    spec = f"gaussian:{fwhm}" + (f",tail:{tail},weight:{weight}" if tail else "")
    sigma = fwhm / 2.3548200450309493 / BIN

    def jitter(rng, n):
        late = np.where(rng.random(n) < weight, rng.exponential(tail / BIN or 1.0, n), 0.0)
        return rng.normal(0.0, sigma, n) + late

    got = window_share(SimpleNamespace(irf=spec, pulse_width=0.5), BIN, PERIOD)
    assert got == pytest.approx(_monte_carlo(jitter), abs=3e-3)
    assert got < (0.99 if not tail else 0.9)  # (the window truly loses a share)


def test_a_detectors_jitter_composes_with_the_irf():
    """The GMAPD's own Gaussian jitter (a standard deviation, as ``--jitter`` takes it) after
    the IRF, on the IRF's histogram as the detector model applies it (a photon uniform within
    its bin): as photons drawn through both."""
    cfg = SimpleNamespace(irf="gaussian:150e-12", pulse_width=0.5)
    det = {"jitter": 80e-12, "jitter_tail": 0.0, "jitter_tail_weight": 0.0}
    sigma = 150e-12 / 2.3548200450309493 / BIN

    def irf(rng, n):
        return rng.normal(0.0, sigma, n)

    def detector(rng, n):
        return rng.normal(0.0, 0.8, n)

    got = window_share(cfg, BIN, PERIOD, det)
    assert got == pytest.approx(_monte_carlo(irf, then=detector), abs=3e-3)
    assert got < window_share(cfg, BIN, PERIOD) - 0.02


def test_a_sampled_irf_file(tmp_path):
    """A response sampled per bin (``--irf FILE.npy``, its peak the time origin): a photon
    uniform within its bin lands at the kernel's offsets with its weights."""
    h = np.array([0.0, 1.0, 0.5, 0.3, 0.2, 0.1])
    np.save(tmp_path / "irf.npy", h)
    got = window_share(SimpleNamespace(irf=str(tmp_path / "irf.npy"), pulse_width=0.5), BIN,
                       PERIOD)
    offs, w = np.arange(h.size) - 1, h / h.sum()

    def kernel(rng, n):  # (the kernel moves a photon by whole bins)
        return offs[rng.choice(h.size, n, p=w)].astype(np.float64)

    assert got == pytest.approx(_monte_carlo(kernel), abs=3e-3)


def test_a_tailed_irfs_run_reads_the_scenes_reflectivity(tmp_path):
    """A noiseless 16x16 run through the README's IRF (150 ps FWHM, a 400 ps tail): the
    reflectivity's median over the scene's is within 3 % of 1 (0.778 before the window's
    share was taken out; the ideal instrument's noiseless refit reads within 1 %), and
    ``metrics.json`` says the share."""
    out = tmp_path / "r"
    assert main(["run", "--scene", "steps", "--size", "16", "--code-length", "1023",
                 "--irf", "gaussian:150e-12,tail:400e-12", "--noiseless", "--compression",
                 "0.5", "--no-figure", "--out", str(out)]) == 0
    got = np.load(out / "reflectivity.npy")
    ratio = (got / load_scene("steps", 16).reflectivity)[np.isfinite(got)]
    assert np.median(ratio) == pytest.approx(1.0, abs=0.03)
    method = json.loads((out / "metrics.json").read_text())["reflectivity_method"]
    assert method["instrument_window_share"] == pytest.approx(0.768, abs=0.005)
