"""What a Windows or macOS machine does differently, checked from Linux: text files opened
with the platform's default encoding (cp1252 on Windows) instead of UTF-8.

A portability audit of 2026-11-30 found the marker, ``metrics.json`` and ``/proc`` read and
written with the locale's encoding (all ASCII today, so nothing broke; the first non-ASCII
name would have been written in cp1252 on Windows and read back wrongly on Linux).
"""

from __future__ import annotations

import os
import subprocess
import sys


def test_no_text_file_of_spslidar_is_opened_with_the_locale_s_encoding(tmp_path):
    """Python's ``-X warn_default_encoding`` warns at every ``open`` without an encoding: a
    run, its ``--save-ptu`` companions, an overwrite and a reconstruction raise none from
    spslidar's own files (third-party ones, scikit-image's lazy loader, are not ours)."""
    code = ("import sys, warnings; warnings.filterwarnings('error', category=EncodingWarning,"
            " module=r'spslidar(\\.|$)'); "
            "from spslidar.cli import main; sys.exit(main(sys.argv[1:]))")
    run = ["run", "--size", "8", "--code-length", "255", "--no-figure",
           "--save-ptu", str(tmp_path / "a.ptu"), "--out", str(tmp_path / "r")]
    rec = ["reconstruct", "--ptu", str(tmp_path / "a.ptu"), "--patterns",
           str(tmp_path / "a_patterns.npy"), "--code", str(tmp_path / "a_code.npy"),
           "--bit-rate", "10e9", "--range-gate", "19.9", "20.9", "--out", str(tmp_path / "q")]
    for argv in (run, [*run, "--overwrite"], rec):
        done = subprocess.run([sys.executable, "-X", "warn_default_encoding", "-c", code,
                               *argv], capture_output=True, text=True, timeout=300,
                              env={**os.environ, "PYTHONWARNINGS": ""}, cwd=tmp_path)
        # (an EncodingWarning raised in spslidar's own code ends the command)
        assert done.returncode == 0, done.stderr
