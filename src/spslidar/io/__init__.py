"""Reading and writing measured data.

:mod:`spslidar.io.ptu` reads PicoQuant T3 PTU time-tag files into per-pattern histograms over
the code period and writes simulated acquisitions as T3 PTU files. Reading decodes records with
the ``ptufile`` package (a core dependency of spslidar); writing needs only NumPy. A T2 file
that recorded the code's sync is read as its T3 file would be (:mod:`spslidar.io.ptu_t2`,
which decodes T2 records itself). :func:`~spslidar.io.ptu_scan.scan_ptu` counts what a file
holds before any option is chosen (``spslidar inspect``).
:mod:`spslidar.io.timestamps` turns another vendor's time tagger's absolute timestamps into
T3 events and a PTU file.
"""

from __future__ import annotations

from .ptu import PtuAcquisition, ptu_info, read_ptu_histograms
from .ptu_scan import scan_ptu
from .ptu_write import write_acquisition_ptu, write_ptu_t3, write_ptu_t3_stream
from .timestamps import T3Events, t3_from_timestamps, write_ptu_from_timestamps

__all__ = [
    "PtuAcquisition",
    "T3Events",
    "ptu_info",
    "read_ptu_histograms",
    "scan_ptu",
    "t3_from_timestamps",
    "write_acquisition_ptu",
    "write_ptu_from_timestamps",
    "write_ptu_t3",
    "write_ptu_t3_stream",
]
