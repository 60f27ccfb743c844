"""A calibration's detector channels: each channel has its own cable and electronics delay,
and channel 0's calibration applied to channel 1 (cabled 0.5-3 ns later) biased every depth
by 7.6-37.9 cm without a word (an outside lab audit of 2026-11-30). The calibration records
the channels it read; ``reconstruct`` says where they are not the ones it reads. Files
written with two channels seeing the same returns."""

from __future__ import annotations

import json

import numpy as np
from test_repeats import BIT_RATE, DWELL, C, L, M, N
from test_screen_blocks import _scene

from spslidar.cli import main


def _two_channels(path, name, depth, skew, seed=3):
    """A HydraHarp file of two detector channels seeing the same returns, channel 1 cabled
    ``skew`` bins later; ``depth`` a map (a flat wall for a calibration)."""
    from spslidar.io import write_ptu_t3

    rng = np.random.default_rng(seed)
    code = np.zeros(L)
    code[np.random.default_rng(0).permutation(L)[: L // 2 + 1]] = 1.0
    pats = (np.random.default_rng(1).random((M, N, N)) < 0.5).astype(np.float32)
    delay = np.rint(2 * depth.ravel() / (C / BIT_RATE)).astype(int)
    amp = np.zeros((M, L))
    for d in np.unique(delay):
        amp[:, d % L] += pats.reshape(M, -1)[:, delay == d].sum(axis=1) * 0.8
    lam = DWELL * (3e-4 * np.fft.ifft(np.fft.fft(amp, axis=1)
                                      * np.fft.fft(code)[None, :], axis=1).real + 2e-4)
    ns, dt, ch, mk = [], [], [], []
    for k in range(M):
        ns.append([k * DWELL]), dt.append([0]), ch.append([0]), mk.append([1])
        for c, shift in ((0, 0), (1, skew)):
            counts = rng.poisson(np.clip(np.roll(lam[k], shift), 0, None))
            t = np.repeat(np.arange(L), counts)
            s = k * DWELL + rng.integers(0, DWELL, t.size)
            ns.append(s), dt.append(t), ch.append(np.full(t.size, c)), mk.append(np.zeros(t.size))
    ns, dt, ch, mk = (np.concatenate(a).astype(np.int64) for a in (ns, dt, ch, mk))
    order = np.lexsort((-mk, ns))
    write_ptu_t3(path / f"{name}.ptu", nsync=ns[order], dtime=dt[order], channel=ch[order],
                 marker=mk[order], resolution_s=1 / BIT_RATE, sync_rate_hz=BIT_RATE / L)
    np.save(path / "patterns.npy", pats)
    np.save(path / "code.npy", code.astype(np.uint8))


def test_a_calibration_on_other_channels_is_said(tmp_path, capsys):
    """Channel 0's calibration applied to channel 1 (cabled 10 bins, 1 ns, later) biased
    every depth by the cable's 15 cm without a word: the calibration now records the
    channels it read, and reconstruct says where they are not the channels it reads."""
    depth, _ = _scene()
    _two_channels(tmp_path, "wall", np.full((N, N), 3.6), 10)
    _two_channels(tmp_path, "scan", depth, 10, seed=4)
    base = ["--patterns", str(tmp_path / "patterns.npy"), "--code", str(tmp_path / "code.npy"),
            "--bit-rate", "10e9", "--dead-time", "0"]
    for chan in ("0", "1"):
        assert main(["calibrate", "--ptu", str(tmp_path / "wall.ptu"), *base, "--distance",
                     "3.6", "--channel", chan, "--out", str(tmp_path / f"cal{chan}.json")]) == 0
    assert main(["calibrate", "--ptu", str(tmp_path / "wall.ptu"), *base, "--distance", "3.6",
                 "--out", str(tmp_path / "calall.json")]) == 0
    cal = json.loads((tmp_path / "cal0.json").read_text())["measured_from"]
    assert cal["channel"] == [0] and cal["channels"] == [0]
    merged = json.loads((tmp_path / "calall.json").read_text())
    assert merged["measured_from"]["channel"] is None
    assert merged["measured_from"]["channels"] == [0, 1]
    # (the merged response's two peaks, the channels' own: named as such, not only as a
    # second surface or the instrument's reflection)
    assert any("the detector channels 0, 1 were merged here: the second return may be their "
               "cables' difference in delay" in w for w in merged["warnings"])
    one = json.loads((tmp_path / "cal0.json").read_text())
    assert not any("were merged here" in w for w in one["warnings"])
    capsys.readouterr()

    def run(cal, *chan):
        out = tmp_path / f"r_{cal}_{'-'.join(chan) or 'all'}"
        assert main(["reconstruct", "--ptu", str(tmp_path / "scan.ptu"), *base,
                     "--range-gate", "2.5", "4", "--calibration", str(tmp_path / f"{cal}.json"),
                     "--out", str(out), "--no-figure", *(("--channel", *chan) if chan else ())
                     ]) == 0
        err = capsys.readouterr().err
        m = json.loads((out / "metrics.json").read_text())
        bias = float(np.nanmean(np.load(out / "depth.npy") - depth))
        return err, m, bias

    err, m, bias = run("cal0", "1")
    assert ("the calibration was measured on detector channel 0, and this acquisition is read "
            "on channel 1") in err
    assert m["ptu"]["channel"] == [1] and bias > 0.1  # (the cable's 15 cm)
    err, m, bias = run("cal1", "1")
    assert "the calibration was measured on detector" not in err and abs(bias) < 0.03
    err, _, _ = run("cal0")
    assert "this acquisition is read on channels 0, 1 merged" in err
    err, m, _ = run("calall")
    assert "the calibration was measured on detector" not in err and m["ptu"]["channel"] is None


def test_a_calibration_edited_by_hand_does_not_say_its_channels():
    """``measured_from`` as text, or channels that are not numbers, was a traceback (a
    review): such a calibration says nothing of its channels, so nothing is said."""
    from spslidar.pipeline.blocks import channel_note

    class Data:
        photons_per_channel = {0: 100, 1: 100}

    for source in ("lab A", {"channels": ["a"]}, {"channels": [True]}, {"channels": 0}, None):
        assert channel_note({"measured_from": source}, Data(), 1) is None
    assert "channel 0" in channel_note({"measured_from": {"channels": [0]}}, Data(), 1)


def test_a_calibrations_damaged_records_are_refused_in_one_line():
    """A calibration edited by hand whose ``measured_from`` is not an object was an
    AttributeError traceback in ``reconstruct``; channels that are no detector numbers
    skipped the channel check, and a ``peak_to_noise`` of -5 was said as a response -5
    deviations high (an outside audit of 2026-12-02). Each is one line now; the intact
    records, and a calibration of an earlier version without them, are taken."""
    import pytest

    from spslidar.errors import ConfigError
    from spslidar.pipeline.calibration_file import check_calibration

    code = np.ones(31)
    good = {"irf_offsets": [-1, 0, 1], "irf_values": [0.25, 0.5, 0.25], "bit_rate_hz": 1e10,
            "delay_s": 0.0, "irf_fwhm_bins": 2.0, "code_length": 31, "lag_shift": 0,
            "lag_fraction": 0.0, "peak_to_noise": 40.0, "warnings": ["a line"],
            "detector": {"dead_time_s": 0.0}, "target": {"kind": "range"},
            "measured_from": {"ptu": "wall.ptu", "channels": [0, 1], "channel": None}}
    assert check_calibration(dict(good), "c", 1e10, code)["peak_to_noise"] == 40.0
    # (+inf is calibrate's own where the side noise is 0: taken)
    check_calibration({**good, "peak_to_noise": float("inf")}, "c", 1e10, code)
    old = {k: v for k, v in good.items()
           if k not in ("peak_to_noise", "warnings", "detector", "target", "measured_from")}
    check_calibration(old, "c", 1e10, code)
    for key, value, said in (
            ("measured_from", 5, "measured_from is damaged"),
            ("measured_from", "lab wall 2024-05-01", "measured_from is damaged"),
            ("measured_from", {"channels": 5}, "measured_from is damaged"),
            ("measured_from", {"channels": ["a"]}, "measured_from is damaged"),
            ("measured_from", {"channels": [True]}, "measured_from is damaged"),
            ("measured_from", {"channels": [128]}, "measured_from is damaged"),
            ("measured_from", {"channel": "1"}, "measured_from is damaged"),
            ("peak_to_noise", -5, "peak_to_noise -5 is damaged"),
            ("peak_to_noise", "40", "peak_to_noise '40' is damaged"),
            ("peak_to_noise", float("nan"), "peak_to_noise nan is damaged"),
            ("peak_to_noise", True, "peak_to_noise True is damaged"),
            ("warnings", "one line", "warnings are damaged"),
            ("warnings", [1], "warnings are damaged"),
            ("detector", "SPAD", "detector record is damaged"),
            ("target", [1], "target record is damaged")):
        with pytest.raises(ConfigError, match="calibrate again") as exc:
            check_calibration({**good, key: value}, "c", 1e10, code)
        assert said in str(exc.value) and "\n" not in str(exc.value)
