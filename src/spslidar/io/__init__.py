"""Reading and writing measured data.

:mod:`spslidar.io.ptu` reads PicoQuant T3 PTU time-tag files into per-pattern histograms over
the code period and writes simulated acquisitions as T3 PTU files. Reading decodes records with
the ``ptufile`` package (a core dependency of spslidar); writing needs only NumPy.
"""

from __future__ import annotations

from .ptu import PtuAcquisition, ptu_info, read_ptu_histograms
from .ptu_write import write_acquisition_ptu, write_ptu_t3, write_ptu_t3_stream

__all__ = [
    "PtuAcquisition",
    "ptu_info",
    "read_ptu_histograms",
    "write_acquisition_ptu",
    "write_ptu_t3",
    "write_ptu_t3_stream",
]
