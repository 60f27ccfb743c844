"""A calibration as ``reconstruct`` uses it, on inputs an audit of 2026-11-28 chose: one read
through the noise, an IRF ten bins wide, a code other than the one calibrated with."""

from __future__ import annotations

import json
import warnings

import numpy as np
import pytest

from spslidar.cli import main
from spslidar.errors import ConfigError

COMMON = ["--size", "8", "--code-length", "1023", "--compression", "0.5",
          "--system-delay", "3.3e-9", "--range-gate", "1", "14", "--no-figure"]


def _acquire(d, name, depth, extra):
    np.save(d / f"{name}.npy", np.full((8, 8), depth))
    assert main(["run", "--scene", str(d / f"{name}.npy"), *COMMON, *extra, "--save-ptu",
                 str(d / f"{name}.ptu"), "--out", str(d / f"r_{name}")]) == 0
    return ["--ptu", str(d / f"{name}.ptu"), "--patterns", str(d / f"{name}_patterns.npy"),
            "--code", str(d / f"{name}_code.npy"), "--bit-rate", "10e9"]


def _calibrate(d, files, name="cal.json"):
    assert main(["calibrate", *files, "--distance", "10", "--out", str(d / name)]) == 0
    return d / name


def _reconstruct(d, files, cal, gate=("11", "13.5"), out="rec"):
    assert main(["reconstruct", *files, "--range-gate", *gate, "--calibration", str(cal),
                 "--out", str(d / out), "--no-figure"]) == 0
    return json.loads((d / out / "metrics.json").read_text())


def test_a_weak_calibration_is_said_again_where_it_is_used(tmp_path, capsys):
    """``calibrate`` warned of a response 10.8 noise deviations high; ``reconstruct`` said
    nothing of it (the audit's map through such a calibration: RMSE 0.0745 m against 0.003 m).
    Now the file keeps the warnings, ``reconstruct`` says it again and ``metrics.json`` keeps
    the response's height."""
    weak = ["--signal", "0.05", "--noise", "0.5", "--irf", "gaussian:150e-12,tail:400e-12"]
    cal = _calibrate(tmp_path, _acquire(tmp_path, "wall", 10.0, weak))
    assert "read through the noise" in capsys.readouterr().err
    kept = json.loads(cal.read_text())
    assert kept["peak_to_noise"] < 20 and any("read through the noise" in w
                                              for w in kept["warnings"])
    good = ["--signal", "1", "--noise", "0.02", "--irf", "gaussian:150e-12,tail:400e-12"]
    m = _reconstruct(tmp_path, _acquire(tmp_path, "scene", 12.3, good), cal)
    err = capsys.readouterr().err
    assert "its IRF is read through the noise" in err and str(cal) in err
    assert m["calibration"]["peak_to_noise"] == kept["peak_to_noise"]
    assert m["calibration"]["warnings"] == kept["warnings"]


def test_a_wide_irf_is_not_said_to_be_noise(tmp_path, capsys):
    """A 10-bin IRF spreads each return over about 12 slices either side of its peak; its own
    shoulders were read as the noise beside it, and a map of RMSE 7 mm was said to be mostly
    noise (1.15 against 2.08). A gate without the scene is still said to be noise."""
    wide = ["--signal", "1", "--noise", "0.02", "--irf", "gaussian:1e-9"]
    cal = _calibrate(tmp_path, _acquire(tmp_path, "wall", 10.0, wide))
    # (a wall at one range: its 10-bin response let a 6-bin plane fit 0.55 deviations
    # better, which is said but not removed; removed, the delay moved 1.3 bins)
    assert json.loads(cal.read_text())["target"]["model"] == "range"
    err = capsys.readouterr().err
    assert "may be a flat wall" in err
    # a response this wide loses surfaces before brighter ones: said by both commands, kept
    # in the file (an outside audit of 2026-12-02 lost a step before a wall without a word)
    assert "bins wide (FWHM)" in err
    assert any("bins wide (FWHM)" in w for w in json.loads(cal.read_text())["warnings"])
    scene = _acquire(tmp_path, "scene", 12.3, wide)
    capsys.readouterr()
    m = _reconstruct(tmp_path, scene, cal)
    err = capsys.readouterr().err
    assert "mostly noise" not in err and "bins wide (FWHM)" in err
    assert any("bins wide (FWHM)" in w for w in m["warnings"])
    assert m["peak_to_noise_p90"] > 2 * m["peak_to_noise_floor"]
    depth = np.load(tmp_path / "rec" / "depth.npy")
    assert np.nanmedian(np.abs(depth - 12.3)) < 0.015  # a bin: the map is good
    miss = _reconstruct(tmp_path, scene, cal, gate=("4", "6.5"), out="miss")
    assert "mostly noise" in capsys.readouterr().err
    assert miss["peak_to_noise_p90"] < miss["peak_to_noise_floor"]


def test_a_gate_too_short_for_the_response_gives_no_verdict_and_says_so(tmp_path, capsys):
    """Through a 28-slice gate a 10-bin response leaves 3 independent slices beside a
    return: the white-noise reference read 6.30 there and a good map (5.15 at every gate,
    its noise maxima the response's own wings) was said to be mostly noise; through 22
    slices the verdict was dropped without a word (an audit, on a real file). Both now say
    that no verdict was given, and why; a 42-slice gate judges as before."""
    wide = ["--signal", "1", "--noise", "0.02", "--irf", "gaussian:1e-9"]
    cal = _calibrate(tmp_path, _acquire(tmp_path, "wall", 10.0, wide))
    scene = _acquire(tmp_path, "scene", 12.3, wide)
    for i, gate in enumerate([("12.1", "12.5"), ("12.15", "12.45")]):
        m = _reconstruct(tmp_path, scene, cal, gate=gate, out=f"short{i}")
        assert m["peak_to_noise_p90"] is None
        said = [w for w in m["warnings"] if "nothing here checks" in w]
        assert len(said) == 1 and "beside a return 25 slices wide" in said[0]
        assert not any("mostly noise" in w for w in m["warnings"])
    m = _reconstruct(tmp_path, scene, cal, gate=("12.0", "12.6"), out="long")
    assert m["peak_to_noise_p90"] > m["peak_to_noise_floor"]
    assert not any("nothing here checks" in w for w in m["warnings"])


@pytest.mark.parametrize("code", ["mseq", "random"])
def test_metrics_say_whether_the_calibration_saw_the_same_code(tmp_path, code):
    """The delay and IRF are the instrument's, so a calibration measured with other code
    bits of the same length applies (the audit: 0.0024 m either way); ``metrics.json`` says
    whether the bits were the same (``code_sha256`` was written and never read)."""
    inst = ["--signal", "1", "--noise", "0.02", "--irf", "gaussian:150e-12,tail:400e-12"]
    cal = _calibrate(tmp_path, _acquire(tmp_path, "wall", 10.0, inst))
    m = _reconstruct(tmp_path, _acquire(tmp_path, "scene", 12.3, [*inst, "--code", code]), cal)
    assert m["calibration"]["same_code"] is (code == "mseq")
    # and said where it is not (only metrics.json said it, an audit): "another code"
    said = [w for w in m["warnings"] if "measured with another code" in w]
    assert len(said) == (code != "mseq")


def test_a_code_shifted_from_the_calibrations_is_named_with_its_range(tmp_path, capsys):
    """A code file that is the calibration's rotated by 100 bits (a generator started at
    another bit, or a file rotated by mistake) moved every depth 1.5 m without a word (an
    outside audit): the shift is now named with its range; the calibration stores its code's
    bits for that, and one without them (an earlier version's) still says "another code"."""
    from spslidar.pipeline.calibration_file import code_bits, code_note, code_sha256

    inst = ["--signal", "1", "--noise", "0.02"]
    cal = _calibrate(tmp_path, _acquire(tmp_path, "wall", 10.0, inst))
    files = _acquire(tmp_path, "scene", 12.3, inst)
    code = np.load(tmp_path / "scene_code.npy")
    np.save(tmp_path / "rolled.npy", np.roll(code, 100))
    files[files.index(str(tmp_path / "scene_code.npy"))] = str(tmp_path / "rolled.npy")
    m = _reconstruct(tmp_path, files, cal, out="rolled")
    said = [w for w in m["warnings"] if "shifted by +100 bits (1.499 m of range)" in w]
    assert len(said) == 1, m["warnings"]
    assert "shifted" in capsys.readouterr().err
    data = json.loads(cal.read_text())
    assert data["code_bits"] == code_bits(code)
    del data["code_bits"]
    assert "another code of the same length" in code_note(data, np.roll(code, -7), 10e9)
    assert "shifted by -7 bits" in code_note({**data, "code_bits": code_bits(code)},
                                             np.roll(code, -7), 10e9)
    assert code_note({"code_sha256": code_sha256(code)}, code, 10e9) is None
    damaged = {**data, "code_bits": "zz", "code_length": 1023}
    assert "another code" in code_note(damaged, np.roll(code, 3), 10e9)


def test_a_long_tail_is_read_past_forty_bins(tmp_path):
    """A 4 ns diffusion tail holding 90 % of the response at 10 GHz was cut at 40 bins and
    every calibrated depth read long (the audit, 16x16: +21.8 mm; with the tail read to 160
    bins +8.7 mm). The IRF now goes on while it stands above the noise past its end."""
    tail = ["--signal", "1", "--noise", "0.02", "--irf", "gaussian:150e-12,tail:4e-9,weight:0.9",
            "--compression", "1"]
    cal = json.loads(_calibrate(tmp_path, _acquire(tmp_path, "wall", 10.0, tail)).read_text())
    offsets, values = np.array(cal["irf_offsets"]), np.array(cal["irf_values"])
    assert offsets.max() > 40 and values[offsets > 40].sum() > 0.1
    assert abs(cal["delay_s"] - 3.3e-9) < 0.02e-9  # seeds 0-7: 3.309-3.318 ns
    _reconstruct(tmp_path, _acquire(tmp_path, "scene", 12.3, tail), tmp_path / "cal.json")
    depth = np.load(tmp_path / "rec" / "depth.npy")
    # the whole map moves with the solve's noise on so broad a response: seeds 0-7 at all 64
    # patterns -19..+10 mm (at 32 patterns -16..+205 mm, the top of a response 90 % tail too
    # flat for half the data; an audit of 2026-11-29 found the test passing on seed 0 only)
    assert abs(np.nanmean(depth - 12.3)) < 0.025


def test_a_wide_response_is_read_from_its_rising_edge(tmp_path):
    """A Gaussian IRF of 25 bins FWHM (2.5 ns at 10 GHz; a HydraHarp's 16 ps bins under a
    400 ps response are as many) was read from 8 bins before its peak: FWHM said as 20.6
    bins, the noise read inside its rising edge (5.35 deviations from 17 M photons) and the
    wall read 1.47 cm short through it (an audit). Now the response is read from where it
    rises, and the wall through it is within a few millimetres."""
    wide = ["--signal", "1", "--noise", "0.02", "--irf", "gaussian:2.5e-9", "--compression", "1"]
    files = _acquire(tmp_path, "wall", 10.0, wide)
    cal = json.loads(_calibrate(tmp_path, files).read_text())
    assert min(cal["irf_offsets"]) < -16
    # a Gaussian of 25 bins integrated over whole bins reads sqrt(25^2 + 1) = 25.02; 4 %
    # for the noise on its shoulders
    assert abs(cal["irf_fwhm_bins"] - 25.02) < 1.0
    assert cal["peak_to_noise"] > 15  # read inside its own rising edge: 5
    # the peak of a wide top read on the response smoothed (seeds 0-7: 3.287-3.311 ns; its
    # largest bin gave 2.99-3.53 ns, an audit of 2026-11-29)
    assert abs(cal["delay_s"] - 3.3e-9) < 0.03e-9
    m = _reconstruct(tmp_path, files, tmp_path / "cal.json", gate=("9", "11"))
    depth = np.load(tmp_path / "rec" / "depth.npy")
    # the map moves with the solve's noise on a response this broad (seeds 0-7: -46..+31 mm;
    # before the response was read from its rising edge, 1.47 cm short on seed 0 alone)
    assert abs(np.nanmean(depth - 10.0)) < 0.05
    assert m["coverage"] == 1.0


def test_a_wide_top_is_read_through_its_noise():
    """The delay of a response whose top spans many bins is read on the response smoothed
    over a quarter of that top: over eight noise draws of a 25-bin Gaussian at 0.5 M
    photons, within half a bin of the truth (the largest bin moved it by up to 2.3 bins)."""
    from spslidar.codes.sequences import lfsr_sequence
    from spslidar.pipeline.calibration import measure_response

    code = lfsr_sequence(10).astype(float)
    n, delay = code.size, 123.0
    t = (np.arange(n) - delay + n // 2) % n - n // 2
    irf = np.exp(-0.5 * (t / (25 / 2.3548)) ** 2)
    mean = np.fft.irfft(np.fft.rfft(code) * np.fft.rfft(irf), n)
    mean = 5e5 * mean / mean.sum() + 50.0
    errors = []
    for seed in range(8):
        hist = np.random.default_rng(seed).poisson(mean).astype(float)
        got = measure_response(hist, code, 1e-10, 0.0, pulse_width=1.0)["delay_bins"]
        errors.append(got - delay)
    assert np.max(np.abs(errors)) < 0.5, errors


def test_a_plane_the_data_barely_tell_whose_response_drowns_is_read_as_one_range(
        tmp_path, capsys):
    """An 8 x 8 wall at one range through a 25-bin IRF (seed 4) was fitted as a plane at
    1.06 deviations, its response with the plane removed 6.3 deviations high against 28 for
    one range and its delay 1.1 ns short (an audit). Now one range is kept and the plane
    said."""
    inst = ["--signal", "1", "--noise", "0.02", "--irf", "gaussian:2.5e-9", "--seed", "4"]
    cal = json.loads(_calibrate(tmp_path, _acquire(tmp_path, "wall", 10.0, inst)).read_text())
    assert cal["target"]["model"] == "range" and "leaves a response" in cal["target"]["reason"]
    assert "response with that spread removed stands only" in capsys.readouterr().err
    assert abs(cal["delay_s"] - 3.3e-9) < 0.05e-9


# (its broad, noisy top also reads as a second return, and its height through the noise:
# not what is tested here)
@pytest.mark.filterwarnings("ignore:the calibration.s response holds a second return")
@pytest.mark.filterwarnings("ignore:the calibration's response stands")
def test_a_response_wider_than_a_quarter_period_is_said_to_be_cut():
    """A response that still stands above the background where the IRF's window ends (a
    quarter of the code period) is cut there, and says so (a real fluorescence file read
    as a calibration gave "IRF FWHM 49.00 bins", the window's width, without a word)."""
    from spslidar.codes.sequences import lfsr_sequence
    from spslidar.pipeline.calibration import measure_response

    code = lfsr_sequence(10).astype(float)
    n = code.size
    irf = np.exp(-0.5 * (((np.arange(n) + n // 2) % n - n // 2) / 120.0) ** 2)
    hist = np.fft.irfft(np.fft.rfft(code) * np.fft.rfft(irf), n) * 50 + 5
    hist = np.random.default_rng(0).poisson(hist).astype(float)
    with pytest.warns(RuntimeWarning, match="still stands above the background"):
        measure_response(hist, code, 1e-10, 0.0)


@pytest.mark.filterwarnings("ignore:the calibration.s response holds a second return")
@pytest.mark.filterwarnings("ignore:the calibration's response stands")
def test_a_fluorescence_decay_through_a_short_pulse_code_is_said_or_refused():
    """A decay through a one-pulse code of 132 bits (the real hazelnut FLIM file read as a
    calibration, an outside audit): its first 40-bin window already reaches past a quarter
    of the period and was not said; a slower decay, read as noise inside itself, was refused
    as "no clear return ... acquire longer". Both are said to be broader than a flat
    target's; a narrow response through the same code is not."""
    from spslidar.pipeline.calibration import measure_response

    rng = np.random.default_rng(0)
    for n, tau, peak, background, refused in ((132, 12.0, 13_500, 30, False),
                                              (1563, 400.0, 5_000, 160, True)):
        code = np.zeros(n)
        code[0] = 1.0
        t = np.arange(float(n))
        hist = rng.poisson(peak * np.exp(-t / tau) + background).astype(float)
        if refused:  # (the real beads file's shape: 5 000 over 160 in 16 ps bins)
            with pytest.raises(ConfigError, match="still stands above the background .* a "
                                                  "flat target's response is narrower"):
                measure_response(hist, code, 1.6e-11, 0.0)
        else:
            with pytest.warns(RuntimeWarning, match="still stands above the background 40 "
                                                    "bins after its peak"):
                measure_response(hist, code, 1e-10, 0.0)
        narrow = rng.poisson(peak * np.exp(-0.5 * ((t - 20) / 0.8) ** 2)
                             + background).astype(float)
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)
            measure_response(narrow, code, 1e-10, 0.0)
    # codes so short that the window past the tail wraps onto the peak: no cut is said of a
    # narrow response (a 63-bit code's was, in every seed: a review of the change)
    for n in (31, 40, 63, 64):
        code = np.zeros(n)
        code[0] = 1.0
        t = np.arange(float(n))
        narrow = rng.poisson(2000 * np.exp(-0.5 * ((t - 10) / 0.8) ** 2) + 30).astype(float)
        with warnings.catch_warnings(record=True) as said:
            warnings.simplefilter("always")
            measure_response(narrow, code, 1e-10, 0.0)
        assert not [w for w in said if "still stands" in str(w.message)], n



@pytest.mark.parametrize("fwhm, said", [(1.73, False), (2.49, False), (2.5, True), (3.3, True),
                                        ("3.3", False), (None, False), (True, False)])
def test_a_wide_response_is_said_from_its_width(fwhm, said):
    """The README's instrument (1.73 bins, where the calibrated depths were measured) is not
    warned of; about 3 bins, where the audit lost a step before a wall, is."""
    from spslidar.pipeline.calibrated import WIDE_RESPONSE_BINS, wide_response_note
    from spslidar.pipeline.real import calibration_warnings

    assert WIDE_RESPONSE_BINS == 2.5
    note = wide_response_note(fwhm)
    assert (note is not None) == said
    warned = calibration_warnings({"irf_fwhm_bins": fwhm, "peak_to_noise": 100.0})
    assert warned == ([note] if said else [])
