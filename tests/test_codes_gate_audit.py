"""An audit of codes, range gates and the conventional lidar's options: a default gate beyond
the unambiguous range ran without a word, ``snr --code gold`` took another member than
``run``, Gold members 0 and 1 were called Gold codes, the ones-ratio refusal misstated a Gold
code's ones, options without effect under ``--fairness power`` and a rounded ``--rep-rate``
were silent."""

from __future__ import annotations

import json

import numpy as np
import pytest

from spslidar.cli import main

SMALL = ["--size", "8", "--no-figure"]


def _metrics(out) -> dict:
    return json.loads((out / "metrics.json").read_text())


@pytest.mark.parametrize("args,ru", [
    (["--scene", "camera", "--code-length", "1023", "--signal", "50", "--noise", "1"],
     "15.33"),
    (["--scene", "camera", "--lidar", "conventional", "--rep-rate", "10e6",
      "--code-length", "16383"], "14.99"),
    (["--scene", "steps", "--code-length", "63", "--noiseless", "--compression", "1"],
     "0.9443"),
])
def test_a_default_gate_beyond_the_unambiguous_range_is_said(tmp_path, args, ru):
    """The camera at 20-20.8 m with a 1023-bit code (15.33 m unambiguous) read its true depths
    (RMSE 0.0048 m) through a gate placed from the scene's own depths, and said nothing."""
    out = tmp_path / "o"
    assert main(["run", *SMALL, *args, "--out", str(out)]) == 0
    said = [w for w in _metrics(out)["warnings"] if w.startswith("the default range gate")]
    assert len(said) == 1, _metrics(out)["warnings"]
    assert f"{ru} m unambiguous range" in said[0]
    assert "scene's own depths" in said[0] and f"modulo {ru} m" in said[0]


@pytest.mark.parametrize("args", [
    [],  # the default code: 245.6 m unambiguous
    ["--code-length", "1023", "--range-gate", "19.9", "20.9"],  # the operator's own gate
    ["--lidar", "conventional"],  # its default rate covers the gate
])
def test_a_default_gate_within_range_or_a_given_gate_is_not_said(tmp_path, args):
    out = tmp_path / "o"
    assert main(["run", *SMALL, *args, "--out", str(out)]) == 0
    assert not any(w.startswith("the default range gate") for w in _metrics(out)["warnings"])


def test_snr_takes_runs_default_gold_member(capsys):
    """``snr --code gold`` took member 0 (an m-sequence, 512 ones of 1023) where ``run``
    takes member 2 (a Gold code)."""
    from spslidar.codes import CODES, make_code

    assert main(["snr", "--code", "gold", "--code-length", "1023", "--size", "8",
                 "--trials", "20", "--json"]) == 0
    params = json.loads(capsys.readouterr().out)["params"]
    member = CODES.get("gold").defaults["index"]
    assert member == 2 and params["code_index"] == member
    assert params["ones"] == int(make_code("gold", 1023, index=member).sum())
    with pytest.raises(SystemExit):
        main(["snr", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "member 2 of a Gold family" in text and "two m-sequences" in text


def test_snr_library_default_member_is_runs():
    from spslidar.snr import snr_simulated, snr_theory

    kw = dict(signal=5.0, noise=10.0, size=8, on_fraction=0.5)
    assert snr_simulated("gold", 127, 0.5, **kw, trials=4, rng=0)["code_index"] == 2
    assert snr_theory(127, 0.5, **kw, code="gold") == snr_theory(127, 0.5, **kw, code="gold",
                                                                 code_index=2)
    assert snr_simulated("mseq", 127, 0.5, **kw, trials=4, rng=0)["code_index"] == 0


@pytest.mark.parametrize("index,what", [
    ("0", "m-sequence of 127 bits (Gold family member 0: the preferred pair's first"),
    ("1", "m-sequence of 127 bits (Gold family member 1: the preferred pair's second"),
    ("2", "Gold code of 127 bits"),
])
def test_gold_members_0_and_1_are_described_as_m_sequences(tmp_path, index, what):
    out = tmp_path / "o"
    assert main(["run", *SMALL, "--code", "gold", "--code-length", "127", "--code-index",
                 index, "--range-gate", "19.9", "20.9", "--out", str(out)]) == 0
    assert _metrics(out)["code_description"].startswith(what)


def test_run_help_names_the_default_gold_member(capsys):
    with pytest.raises(SystemExit):
        main(["run", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "member 2, the first Gold code, by default" in text
    assert "members 0 and 1 are the pair's two m-sequences" in text


def test_the_ones_ratio_refusal_counts_a_gold_codes_ones(tmp_path, capsys):
    """It said 'a Gold code has (length + 1) / 2 ones': member 2 at 2047 has 992."""
    out = tmp_path / "o"
    assert main(["run", *SMALL, "--code", "gold", "--code-length", "2047", "--ones-ratio",
                 "0.3", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "992 ones of 2047 bits for member 2" in err[0], err
    assert "(length + 1) / 2" not in err[0] and not out.exists()


@pytest.mark.parametrize("args,said", [
    (["--ones-ratio", "0.3"], "--ones-ratio 0.3 is ignored: an m-sequence's share"),
    (["--code-index", "5"], "--code-index 5 is ignored: a cyclic shift keeps"),
    (["--code", "gold", "--ones-ratio", "0.3"], "--ones-ratio 0.3 is ignored: a Gold code's"),
])
def test_code_options_without_effect_under_power_fairness_are_said(tmp_path, args, said):
    """Under --fairness power the conventional lidar takes only the code's count of ones:
    an m-sequence's ones ratio and shift changed nothing, silently."""
    out = tmp_path / "o"
    assert main(["run", *SMALL, "--lidar", "conventional", "--fairness", "power",
                 "--code-length", "2047", *args, "--out", str(out)]) == 0
    warns = _metrics(out)["warnings"]
    assert sum(said in w for w in warns) == 1, warns


def test_a_gold_member_under_power_fairness_has_an_effect_and_is_not_said(tmp_path):
    runs = {}
    for index in ("0", "2"):
        out = tmp_path / index
        assert main(["run", *SMALL, "--lidar", "conventional", "--fairness", "power",
                     "--code", "gold", "--code-length", "2047", "--code-index", index,
                     "--out", str(out)]) == 0
        runs[index] = _metrics(out)
    assert runs["0"]["signal_per_pulse"] != runs["2"]["signal_per_pulse"]  # 1024 / 992 ones
    assert not any("--code-index" in w for w in runs["0"]["warnings"])


@pytest.mark.parametrize("rate,said", [
    ("4e9", "runs at 5e+09 Hz (+25 %)"),
    ("3e9", "runs at 3.33333e+09 Hz (+11.1 %)"),
    ("10e6", None),  # 1000 bins exactly
    ("9.95e6", None),  # 1005 bins: 9.95025e6 Hz, within 1 %
])
def test_a_rep_rate_rounded_to_whole_bins_is_said(tmp_path, rate, said):
    """``--rep-rate 4e9`` ran at 5 GHz (two 100 ps bins) without a word."""
    out = tmp_path / "o"
    assert main(["run", *SMALL, "--lidar", "conventional", "--rep-rate", rate,
                 "--code-length", "2047", "--range-gate", "19.9", "20.9",
                 "--out", str(out)]) == 0
    metrics = _metrics(out)
    warns = [w for w in metrics["warnings"] if w.startswith(f"--rep-rate {float(rate):g}")]
    if said is None:
        assert not warns
    else:
        assert len(warns) == 1 and said in warns[0], warns
    # metrics.json's config gives the rate the lidar ran at (whole bins of 0.1 ns)
    period = round(10e9 / float(rate))
    assert metrics["config"]["rep_rate"] == pytest.approx(10e9 / period, rel=1e-12)


@pytest.mark.parametrize("light", [["--noiseless"], ["--signal", "50", "--noise", "0.01"]])
def test_an_aliased_gate_is_not_also_called_noise(tmp_path, light):
    """A run through a gate longer than the code's period repeats each peak every period: it
    was said to be "mostly noise" beside the gate-alias warning (ratio 1.00). Noiseless, no
    noise verdict is made at all; with noise, the verdict says why it has none."""
    out = tmp_path / "o"
    assert main(["run", "--scene", "steps", "--size", "8", "--code-length", "63",
                 "--range-gate", "0", "2", *light, "--compression", "1",
                 "--no-figure", "--out", str(out)]) == 0
    warns = _metrics(out)["warnings"]
    assert not any("mostly noise" in w for w in warns), warns
    assert any(w.startswith("no noise verdict") for w in warns) is (light[0] != "--noiseless")


def test_a_noiseless_spread_return_is_not_called_noise(tmp_path):
    """A noiseless run through a simulated IRF (its returns a few bins wide) was said to be
    "mostly noise" at RMSE 0.0015 m (an audit of the detectors, 2026-11-28); a noiseless
    gate without the scene is said to hold no return."""
    out = tmp_path / "o"
    assert main(["run", *SMALL, "--noiseless", "--irf", "gaussian:300e-12,tail:400e-12",
                 "--out", str(out)]) == 0
    assert not any("noise" in w for w in _metrics(out)["warnings"])
    miss = tmp_path / "miss"
    assert main(["run", *SMALL, "--noiseless", "--range-gate", "1", "3",
                 "--out", str(miss)]) == 0
    assert any("no pixel holds a return" in w for w in _metrics(miss)["warnings"])


def test_a_default_gate_reaches_a_second_layer_behind_every_pixel():
    """A scene whose every pixel also sees a wall behind it (a net before a wall, its first
    surface all at 3 m) was gated at 2.87-3.13 m from its first surface alone: the wall at
    4 m fell outside without a word, and two_surface_fraction read 0.001 (an audit of
    2026-11-29). The gate now reaches the farthest return, first or second."""
    from spslidar.constants import SPEED_OF_LIGHT
    from spslidar.pipeline.acquisition import default_gate
    from spslidar.scenes.procgen import LayeredScene

    n, bw = 8, 1e-10
    one = np.ones((n, n), bool)
    net = LayeredScene(name="net", depth=np.full((n, n), 3.0),
                       reflectivity=np.full((n, n), 0.5), valid=one,
                       behind_depth=np.full((n, n), 4.0),
                       behind_reflectivity=np.full((n, n), 0.3))
    lo, hi = default_gate(net, bw)
    bin_m = SPEED_OF_LIGHT * bw / 2
    assert lo == pytest.approx(3.0 - 3 * bin_m) and hi == pytest.approx(4.0 + 3 * bin_m)
    plain = LayeredScene(name="plain", depth=np.full((n, n), 3.0),
                         reflectivity=np.full((n, n), 0.5), valid=one)
    assert default_gate(plain, bw)[1] < 3.2  # one layer: the first surface's window


def test_a_second_layer_of_no_reflectivity_does_not_stretch_the_gate():
    """A behind layer whose reflectivity is 0 returns nothing; one such pixel at 20 m
    stretched an 8x8 wall's default gate from 3 m to 2.96-20.04 m (a review)."""
    from spslidar.pipeline.acquisition import default_gate
    from spslidar.scenes.procgen import LayeredScene

    n = 8
    behind = np.full((n, n), np.nan)
    behind[0, 0] = 20.0
    wall = LayeredScene(name="w", depth=np.full((n, n), 3.0), reflectivity=np.full((n, n), 0.5),
                        valid=np.ones((n, n), bool), behind_depth=behind,
                        behind_reflectivity=np.zeros((n, n)))
    assert default_gate(wall, 1e-10)[1] < 3.2


def test_code_sidelobes_are_none_for_an_m_sequence_and_a_gold_codes_sixteenth():
    """An m-sequence's correlation with its bipolar, zero-mean or unipolar replica is a peak
    on a constant (no sidelobes: the automatic gate keeps its plain threshold); a 1023-bit
    Gold code's off-peak values are 0 and +-1/16 of its peak (t(10) = 65 over 1024)."""
    from spslidar.codes import make_code
    from spslidar.correlate import make_replica
    from spslidar.pipeline.gate import code_sidelobes

    mseq = make_code("mseq", 1023)
    for kind in ("bipolar", "zero-mean", "unipolar"):
        assert code_sidelobes(mseq, make_replica(mseq, kind)) is None
    gold = make_code("gold", 1023, index=2)
    sl = code_sidelobes(gold, make_replica(gold, "bipolar"))
    assert sl[0] == pytest.approx(1.0)
    np.testing.assert_allclose(np.unique(np.round(sl[1:], 9)), [-0.0625, 0.0, 0.0625])


def _profile_of(kind, returns, seed=0, m=64):
    """64 patterns' matched-filter outputs over delays 300-899 of returns ``{delay: height}``
    seen through a 1023-bit code (its correlation with its bipolar replica), on a constant
    background, with noise of one unit a pattern (0.125 in the mean: the threshold 0.625)."""
    from spslidar.codes import make_code
    from spslidar.correlate import make_replica
    from spslidar.pipeline.gate import code_sidelobes

    code = make_code(kind, 1023, 0.5, rng=np.random.default_rng(5),
                     index=2 if kind == "gold" else 0).astype(np.float64)
    f = make_replica(code, "bipolar")
    r = np.fft.irfft(np.fft.rfft(code) * np.conj(np.fft.rfft(f)), n=code.size)
    lags = np.arange(300, 900)
    profile = sum(h * r[(lags - d) % code.size] / r[0] for d, h in returns.items()) + 37.0
    corr = profile[None, :] + np.random.default_rng(seed).normal(0.0, 1.0, (m, lags.size))
    return corr, np.ones(m), lags, code_sidelobes(code, f)


def test_the_automatic_gate_keeps_a_codes_returns_not_their_sidelobes():
    """Returns seen through a code with sidelobes: the plain threshold keeps every delay a
    strong return's sidelobes lift past 5 deviations; taken one at a time, each one's
    sidelobes removed, the gate keeps the returns. A wall split over two bins (2432 and
    1311, the audit's) through a Gold code: exactly its two delays (a delay taken is taken
    again where the other's sidelobes made its first height wrong: without that, 500 of 600
    delays); 200 returns of 3-10 units among 600 delays through a random code: all of them
    and at most two more (the background read from the delays not taken: the whole
    profile's median, lifted by the returns, kept all 600)."""
    from spslidar.pipeline.gate import occupied_lags

    corr, sigma, lags, sl = _profile_of("gold", {645: 2432.0, 644: 1311.0})
    assert occupied_lags(corr, sigma, dilate=0).sum() > 100
    kept = occupied_lags(corr, sigma, dilate=0, lags=lags, sidelobes=sl)
    assert lags[kept].tolist() == [644, 645]
    rng = np.random.default_rng(1)
    where = np.sort(rng.choice(lags, 200, replace=False))
    heights = rng.uniform(3, 10, 200)
    corr, sigma, lags, sl = _profile_of("random", dict(zip(where, heights, strict=True)))
    kept = lags[occupied_lags(corr, sigma, dilate=0, lags=lags, sidelobes=sl)]
    assert np.setdiff1d(where, kept).size == 0 and np.setdiff1d(kept, where).size <= 2


def test_a_wall_far_in_a_wide_gate_through_a_gold_code(tmp_path):
    """An outside audit's wall at 50 m in a 40-60 m gate through a 1023-bit Gold code at 5 GHz
    read 0.09-3.5 m RMSE (the plain gate kept 385 of 669 delays, 159 of them for the
    sidelobes); now it solves the wall's delays and the noise's sample (38) and reads as an
    m-sequence does (measured 2026-11-29 at 32x32, m_n = 1: m_s 0.1 / 1 / 10, seeds 0-1,
    3.46-4.18 / 0.093-0.314 / 0.0129 m before, 0.041-0.044 / 0.013 / 0.013 m now; the
    m-sequence 0.042 / 0.014 m)."""
    np.save(tmp_path / "wall.npy", np.full((16, 16), 50.0))
    rmse = {}
    for code in ("gold", "mseq"):
        out = tmp_path / code
        assert main(["run", "--scene", str(tmp_path / "wall.npy"), "--size", "16", "--code",
                     code, "--code-length", "1023", "--bit-rate", "5e9", "--compression",
                     "0.25", "--signal", "1", "--noise", "1", "--range-gate", "40", "60",
                     "--no-figure", "--out", str(out)]) == 0
        m = _metrics(out)
        assert m["n_slices_solved"] <= 45
        rmse[code] = m["depth_rmse_m"]
    assert rmse["gold"] < 1.5 * rmse["mseq"] + 0.005


def test_sidelobes_of_a_return_beyond_the_gate_fall_back_to_the_plain_gate():
    """A bright return beyond the gate leaves its sidelobes across it with no peak in it to
    explain them: taking them one at a time cascaded over every delay (a review: 1 336 of
    1 336, and 1.5 s on a 24 000-delay gate); the plain threshold's delays are kept instead,
    in bounded time."""
    import time

    from spslidar.pipeline.gate import occupied_lags

    corr, sigma, lags, sl = _profile_of("gold", {100: 5000.0, 640: 300.0})
    plain = occupied_lags(corr, sigma, dilate=0)
    t0 = time.perf_counter()
    kept = occupied_lags(corr, sigma, dilate=0, lags=lags, sidelobes=sl)
    assert time.perf_counter() - t0 < 5.0  # (1024 steps of 600 delays at most; ~0.05 s)
    np.testing.assert_array_equal(kept, plain)
    assert kept[lags == 640].all()
