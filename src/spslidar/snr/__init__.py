"""Output SNR of one pattern's matched filter: equation (10) against a Monte-Carlo simulation.

Shen et al. (section II.B.2) derive the signal (eq. 8) and the noise variance (eq. 9) of the
matched-filter output ``C_i(tau)`` of one DMD pattern over one code period, and from them the
output SNR (eq. 10)::

    SNR = (T R_a M_2 a m_s)^2 / (R_a T M_2 a m_s + R_a T N^2 m_n)
        = T R_a (M_2 a m_s)^2 / (M_2 a m_s + N^2 m_n)

with ``T`` the code length, ``R_a`` the share of '1' bits, ``M_2`` the number of mirrors on,
``a`` the mean reflectivity, ``m_s`` the mean signal photons per laser pulse per DMD pixel
(mirror on, reflectivity 1) and ``m_n`` the mean noise counts per TDC bin per pixel (so
``N^2 m_n`` per bin, see ``docs/reading.md`` and ``docs/model.md``).

:func:`snr_theory` evaluates eq. (10) (:mod:`spslidar.snr.theory`, with the input checks);
:func:`snr_simulated` measures the same quantity from Poisson photon counts correlated with the
**unipolar** replica, the definition eq. (10) uses (the noise is counted over the ``R_a T``
"on" bits of the replica; :mod:`spslidar.snr.simulate`); :func:`snr_table` sweeps code kinds,
lengths and ones ratios and :func:`plot_snr` draws the sweep (:mod:`spslidar.snr.table`). The
``spslidar snr`` sub-command is in :mod:`spslidar.cli_snr`
(:func:`~spslidar.cli_snr.add_snr_parser`, :func:`~spslidar.cli_snr.cmd_snr`); the package does
not import the command line.

Only the standard library is imported with this package, so the command-line tool can import it
at start-up without loading NumPy; the numerical modules are imported on first use.
"""

from __future__ import annotations

from typing import Any

from spslidar.registry import lazy_exports
from spslidar.snr.theory import SNR_INTERVALS, SNR_METHODS, mirrors_on, snr_theory

__all__ = [
    "SNR_CODES",
    "SNR_METHODS",
    "SNR_INTERVALS",
    "mirrors_on",
    "snr_theory",
    "snr_simulated",
    "snr_table",
    "plot_snr",
]

_numeric = lazy_exports(__name__, {
    "snr_simulated": "simulate",
    "snr_table": "table",
    "plot_snr": "table",
})


def __getattr__(name: str) -> Any:
    if name == "SNR_CODES":  # the code families of the registry
        from spslidar.snr import theory

        return theory.SNR_CODES
    return _numeric(name)


def __dir__() -> list[str]:
    # the lazy names too, so dir() and a REPL's completion list them (an audit of 2026-11-30)
    return sorted(set(globals()) | set(__all__))
