"""A simulated acquisition written as a lab's own files (``run --save-ptu``): the photons of
every pattern as a T3 PTU file with a marker per pattern, and beside it the mirror states and
the code that ``spslidar reconstruct`` reads with it, so the measured path can be run on a
known scene (:func:`write_measurement_ptu`, re-exported by :mod:`spslidar.pipeline.real`).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError
from .chain import Measurement

__all__ = ["check_ptu_photons", "ptu_companions", "write_measurement_arrays",
           "write_measurement_ptu"]


def check_ptu_photons(meas: Measurement, max_photons: float = 2e7) -> float:
    """The photons :func:`write_measurement_ptu` would write (expected), refused in one line
    beyond ``max_photons``: ``run --save-ptu`` checks it once the acquisition is simulated,
    before the solve (it was checked after it, 34 s into a run it then refused, an audit)."""
    acq = meas.acq
    noise_bin = np.asarray(meas.sim["noise_per_bin"], np.float64)
    expected = float(np.asarray(meas.sim["signal_counts"]).sum()
                     + noise_bin.sum() * acq.period * acq.n_periods)
    if expected > max_photons:
        # (a GMAPD's flux per dead time is its operating point: fewer periods, not less
        # light; lowering --signal took it out of the 1-10 photons per dead time where it
        # works, an outside audit of stop 68)
        # (at one period, the default, "lower --periods" could not be done: a shorter code or
        # fewer patterns can, an audit of the docs of 2026-12-01)
        fewer = "a shorter --code-length or fewer patterns (--compression, --size)"
        gmapd = meas.config.detector == "gmapd"
        if meas.acq.n_periods > 1:
            how = ("lower --periods (the dwell: a GMAPD keeps its photons per dead time)"
                   if gmapd else "lower --periods, or --signal / --noise")
        else:
            how = (f"use {fewer} (a GMAPD keeps its photons per dead time)" if gmapd
                   else f"lower --signal / --noise, or use {fewer}")
        # (a GMAPD's file holds fewer detections, but every photon reaching it is drawn one
        # by one before its dead time keeps them: "expected photons" read as the file's, an
        # outside audit of 2026-12-03)
        what = ("expected photons reaching the detector (each drawn, though its dead time "
                "records fewer)" if gmapd else "expected photons")
        raise ConfigError(f"--save-ptu writes photon by photon: {expected:.3g} {what} "
                          f"exceed {max_photons:.3g}; {how}")
    return expected


def write_measurement_ptu(meas: Measurement, path: str | os.PathLike, *,
                          max_photons: float = 2e7) -> dict[str, Any]:
    """Write a simulated acquisition photon by photon as a T3 PTU file (``run --save-ptu``).

    The expected counts per TDC bin of every pattern are those of the simulation
    (:func:`spslidar.forward.expected_counts`, eq. 4 plus the noise of eq. 9); the photons are
    drawn afresh (linear Poisson counting, from the measurement's own seed), each placed in a
    uniformly drawn code period of the pattern's dwell, and written with a marker per pattern
    (:func:`spslidar.io.write_acquisition_ptu`). So the file is another realisation of the same
    acquisition: ``reconstruct`` on it gives ``run``'s depth map to within the photon noise.
    With ``--detector gmapd`` the file holds what that detector records, detection by
    detection (:func:`spslidar.detectors.events.simulate_events`: its dead time, jitter and
    afterpulses, free-running through each pattern's dwell), which ``reconstruct
    --dead-time`` corrects as ``run`` does its own histograms.

    Raises
    ------
    ConfigError
        More than ``max_photons`` expected photons (not a low-flux acquisition), or a code
        period longer than the T3 dtime field (32768 bins).
    """
    from ..backends.patterns import host_patterns
    from ..forward import expected_counts
    from ..io import write_acquisition_ptu

    # (a device's pattern set has no apply_rows: --save-ptu ended in an AttributeError)
    acq, patterns, scene, cfg = meas.acq, host_patterns(meas.patterns), meas.scene, meas.config
    if acq.period > 32768:
        raise ConfigError(f"--save-ptu: a code period of {acq.period} bins exceeds the T3 dtime "
                          "field (32768 bins)")
    noise_bin = np.asarray(meas.sim["noise_per_bin"], np.float64)
    check_ptu_photons(meas, max_photons)
    from ..instrument import instrument_weights

    shifts, weights = instrument_weights(scene, acq, cfg)  # system delay and IRF as run's
    rng = np.random.default_rng(np.random.SeedSequence([cfg.seed, 0x505455]))
    m = patterns.shape[0]
    photons = 0
    detector = None
    if cfg.detector == "gmapd":  # (photon by photon, as the detector records them)
        from ..detectors import build_detector
        from ..detectors.events import simulate_events
        from .plan import detector_options

        detector = build_detector(cfg.detector, **detector_options(cfg))

    armed: list[float | None] = [None]  # (the first pattern after a warm-up)

    def detected(lam_row: np.ndarray) -> np.ndarray:
        """One pattern's ``(period, bin)`` detections by the GMAPD, which goes on through
        the pattern change (its detector was reset at each one, 137 of 930 698 gaps were
        shorter than the dead time, all across a marker: an outside audit of 2026-11-30)."""
        _, times = simulate_events(lam_row, acq.n_periods, detector, rng, armed_at=armed[0])
        span = acq.n_periods * acq.period * acq.bin_width
        last = times[-1] if times.size else (-np.inf if armed[0] is None else armed[0]
                                             - detector.dead_time)
        armed[0] = max(last + detector.dead_time - span, -span)
        at = np.minimum(np.floor(times / acq.bin_width).astype(np.int64),
                        acq.n_periods * acq.period - 1)
        return np.stack([at // acq.period, at % acq.period], axis=1)

    def events():  # pattern by pattern, drawn as the file is written (memory: 64 patterns')
        nonlocal photons
        for k0 in range(0, m, 64):
            rows = slice(k0, min(m, k0 + 64))
            amp = np.asarray(patterns.apply_rows(rows, weights), np.float64)
            lam = expected_counts(amp, shifts, acq.code, acq.signal_per_pulse, noise_bin[rows],
                                  acq.n_periods)
            if detector is not None:
                for row in np.asarray(lam, np.float64):
                    events_k = detected(row)
                    photons += len(events_k)
                    yield events_k
                continue
            counts = rng.poisson(np.asarray(lam, np.float64))
            for row in counts:
                bins = np.repeat(np.arange(acq.period), row)
                photons += bins.size
                yield np.stack([rng.integers(0, acq.n_periods, bins.size), bins], axis=1)

    n = write_acquisition_ptu(path, events(), acq.period, acq.bin_width,
                              periods_per_pattern=acq.n_periods)
    return {"records": n, "photons": photons}


def ptu_companions(ptu_path) -> tuple[str, str]:
    """The two arrays written beside a PTU file by ``run --save-ptu``:
    ``<stem>_patterns.npy`` and ``<stem>_code.npy``."""
    base = Path(ptu_path)
    return (str(base.with_name(base.stem + "_patterns.npy")),
            str(base.with_name(base.stem + "_code.npy")))


def write_measurement_arrays(meas, ptu_path, paths=None) -> tuple[str, str]:
    """Beside a PTU file written by :func:`write_measurement_ptu`, the two arrays
    ``spslidar reconstruct`` needs with it: ``<stem>_patterns.npy``, the ``(M, N, N)`` mirror
    states in marker order, and ``<stem>_code.npy``, the unipolar bits of one code period
    (:func:`ptu_companions`), or into the two ``paths`` given (written as ``.npy`` whatever
    their names).

    Returns
    -------
    (str, str)
        The two paths.
    """
    from ..backends.patterns import host_patterns

    n = meas.config.size
    q = n * n
    patterns = host_patterns(meas.patterns)
    pats = np.empty((patterns.shape[0], q), dtype=np.float32)
    step = 4096  # columns of the identity at a time: memory bounded for implicit patterns
    for start in range(0, q, step):
        eye = np.zeros((q, min(step, q - start)))
        eye[np.arange(start, start + eye.shape[1]), np.arange(eye.shape[1])] = 1.0
        pats[:, start:start + eye.shape[1]] = patterns.apply_rows(
            slice(0, patterns.shape[0]), eye)
    p_path, c_path = ptu_companions(ptu_path) if paths is None else (str(p) for p in paths)
    from ..outwrite import atomic_file

    with atomic_file(p_path) as fh:  # a failed write leaves no partial file
        np.save(fh, pats.reshape(-1, n, n))
    with atomic_file(c_path) as fh:
        np.save(fh, np.asarray(meas.acq.code, dtype=np.uint8))
    return str(p_path), str(c_path)
