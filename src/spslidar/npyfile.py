"""Reading a user's ``.npy`` and ``.npz`` files without trusting them.

``np.load`` allocates what a file's header declares and parses the header's Python literal:
a header claiming a huge or negative shape, a malformed literal, or an archive whose members
inflate to gigabytes gave tracebacks or took the machine's memory (outside audits of
2026-11-29 and 2026-11-30, fuzzed files). These readers check the header (and an archive's
declared sizes) first and refuse in one line.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .errors import ConfigError, first_line

__all__ = ["check_npz_sizes", "load_npy"]


def load_npy(path: str | os.PathLike, what: str,
             error: type[Exception] = ConfigError) -> np.ndarray:
    """A ``.npy`` array, its header checked first: a shape the file's body cannot hold (or a
    negative one), a header that does not parse, Python objects, or an array too large for
    this machine are refused in one line (``error``) before anything is allocated."""
    import tokenize

    import numpy.lib.format as npformat

    from .machine import _gb, available_memory

    p = Path(path)
    if not p.is_file():
        raise error(f"{what} file not found: {p}" if not p.exists() else
                    f"{what} {p} is not a file (a folder or a device)")
    try:
        with open(p, "rb") as fh:
            version = npformat.read_magic(fh)
            read_header = {(1, 0): npformat.read_array_header_1_0,
                           (2, 0): npformat.read_array_header_2_0}.get(version)
            if read_header is not None:  # (version 3.0: np.load below checks the same)
                shape, _fortran, dtype = read_header(fh)
                body = p.stat().st_size - fh.tell()
                if any(int(d) < 0 for d in shape):  # (np.load's memory map: OverflowError)
                    raise error(f"cannot read {what} {p}: its header declares the shape "
                                f"{tuple(shape)} (a corrupt .npy file)")
                if dtype.hasobject:
                    raise error(f"cannot read {what} {p}: it holds Python objects, "
                                "not numbers")
                size = float(np.prod(shape, dtype=np.float64)) * dtype.itemsize
                if size > body:
                    amount = _gb(size) if size >= 1e6 else f"{size:.0f} bytes"
                    raise error(
                        f"cannot read {what} {p}: its header declares an array of shape "
                        f"{tuple(shape)} ({dtype}, {amount}) but only {body} bytes follow it "
                        f"(a truncated or corrupt .npy file)")
        head = np.load(p, allow_pickle=False, mmap_mode="r")  # a memory map reads no data
    except error:
        raise
    except (ValueError, OSError, EOFError, OverflowError, SyntaxError, tokenize.TokenError,
            RecursionError) as exc:  # (the last three: a header whose literal does not parse)
        msg = first_line(exc)
        if isinstance(exc, (SyntaxError, tokenize.TokenError, RecursionError)):
            msg = "its header does not parse (a corrupt .npy file)"
        try:
            with open(p, "rb") as fh:
                zipped = fh.read(4) == b"PK\x03\x04"
        except OSError:  # (unreadable: the first error says so)
            zipped = False
        if zipped:  # (said as NumPy's "the magic string is not correct ... got b'PK...'")
            msg = "it is an .npz archive (np.savez); save the one array with np.save"
        elif "magic string" in msg:  # (a TIFF, .mat, PNG or text file: NumPy's bytes, an audit)
            msg = ("it is not a .npy file (spslidar reads arrays saved with numpy.save; "
                   "load a TIFF, .mat, image or text file in Python and np.save it)")
        raise error(f"cannot read {what} {p} as a .npy array: {msg}") from None
    need = float(head.size) * 8 * 2  # float64 copies while checking
    if need > 0.8 * available_memory():
        raise error(f"{what} {p} holds an array of shape {head.shape}: {_gb(need)} to "
                    f"check, more than the memory available")
    return np.array(head)


def check_npz_sizes(path: str | os.PathLike, what: str,
                    error: type[Exception] = ConfigError) -> None:
    """Refuse (one line, ``error``, naming ``what``) an ``.npz`` archive whose members would
    inflate past the memory available: a 2.2 MB archive of a deflated 14000x14000 float64
    depth took 3.4 GB before its refusal."""
    import zipfile

    from .machine import _gb, available_memory

    try:
        with zipfile.ZipFile(path) as z:
            size = float(sum(i.file_size for i in z.infolist()))
    except (OSError, zipfile.BadZipFile, ValueError) as exc:
        raise error(f"cannot read {what} as an .npz archive: {exc}") from None
    if 2 * size > 0.8 * available_memory():
        raise error(f"{what}: its arrays inflate to {_gb(size)}, more than the memory "
                    f"available")
