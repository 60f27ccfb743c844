"""The calibration file, ``CAL.json``: written all or nothing with a checksum of its content,
read back and checked against the instrument setting it is applied to (bit rate, code length)
and against itself (a field of the wrong kind, an IRF that does not sum to 1, a ``lag_shift``
that contradicts ``delay_s``, an edit since ``spslidar calibrate`` wrote it). What the
calibration measures is :mod:`spslidar.pipeline.calibration`."""

from __future__ import annotations

import contextlib
import errno
import hashlib
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError
from ..outwrite import sha256_file

__all__ = ["CAL_KIND", "check_calibration", "check_calibration_out", "code_bits", "code_note",
           "code_sha256", "content_sha256", "edited", "load_calibration", "write_calibration"]

#: format tag of a calibration file
CAL_KIND = "spslidar-calibration"
#: a calibration file is a few kilobytes; anything far larger is not one (read whole)
MAX_CAL_BYTES = 64 * 2**20


#: the largest system delay a calibration may hold: cables and electronics give nanoseconds,
#: a kilometre of fibre 5 microseconds
MAX_DELAY_S = 1e-3


def _file_of_a_calibration(path: Path) -> bool:
    """Whether ``path`` can be a calibration to read whole: a regular file of at most
    ``MAX_CAL_BYTES`` (a FIFO hung the command, ``/dev/zero`` ran out of memory)."""
    return path.is_file() and path.stat().st_size <= MAX_CAL_BYTES


def check_calibration_out(out: str | os.PathLike, overwrite: bool = False) -> Path:
    """Refuse (one line) to write ``CAL.json`` over anything but a calibration spslidar
    wrote, and that only with ``overwrite``, or where it cannot be written (a file in its
    folder's place, the nearest existing folder not writable, a path through a loop of
    symbolic links or a link to nowhere, a path too long with its temporary name): checked
    before the work and again at the end. Missing folders are not made here
    (:func:`write_calibration` makes them).

    A symbolic link is never replaced nor written through, even with ``overwrite`` and even
    where it leads to a calibration spslidar wrote: it is refused, naming where it leads, as
    ``run --save-ptu`` refuses a link to a PTU it wrote under another name (name the file
    itself to replace it). A link among the folders of the path (``--out linkdir/CAL.json``)
    is followed."""
    from ..errors import SpslidarError

    if out is None or not str(out).strip():
        raise SpslidarError("--out must name the calibration file (CAL.json)")
    path = Path(out)
    seps = (os.sep, os.altsep) if os.altsep else (os.sep,)
    if path.is_dir() or str(out).endswith(seps) or path.name in ("", ".", ".."):
        # (--out runs/newdir/ wrote a file named newdir: Path drops the trailing separator,
        # an outside audit of 2026-12-02)
        raise SpslidarError(f"--out {out} is a folder; name the calibration file (CAL.json)")
    if path.is_symlink():
        # (exists() follows links: a dangling link or a loop was replaced by a file without
        # --overwrite, and with it a link to a calibration became a file, its target left as
        # it was: an audit of 2026-11-30)
        leads = os.readlink(path)
        where = (f"to {leads}" if path.exists() else
                 f"to {leads}, a loop of symbolic links" if _loops(path) else
                 f"to {leads}, which does not exist")
        raise SpslidarError(f"--out {out} is a symbolic link {where}; spslidar does not "
                            f"replace a link, nor write through it, even with --overwrite: "
                            f"name the file itself, or another one")
    # (--out loopA/CAL.json, or through a dangling link, calibrated, then could not make
    # its folder: an audit of 2026-11-30) the folders of its path must lead somewhere
    for folder in (path.parent, *path.parent.parents):
        if folder.is_symlink() and not folder.exists():
            why = ("a loop of symbolic links" if _loops(folder) else
                   f"{os.readlink(folder)}, which does not exist")
            raise SpslidarError(f"--out {out}: {folder} is a symbolic link to {why}; choose "
                                f"another path")
    if path.exists():
        # (whose file it is said first: "use --overwrite" was said of a user's file, which
        # --overwrite then refused, an outside audit of 2026-12-03)
        try:
            # (a FIFO hung the command, /dev/zero ran out of memory, a deeply nested file
            # ended in a RecursionError: an audit of 2026-11-29)
            if not _file_of_a_calibration(path):
                raise ValueError("not a calibration's size or kind of file")
            old = json.loads(path.read_text(encoding="utf-8-sig"))  # (as it is loaded)
            ours = old.get("kind") == CAL_KIND
        except (OSError, ValueError, AttributeError, RecursionError):
            ours = False
        if not ours:
            raise SpslidarError(f"--out {out} exists and is not a spslidar calibration; "
                                f"refusing to replace it")
        if edited(old):
            raise SpslidarError(f"--out {out} was edited since spslidar calibrate wrote it; "
                                f"refusing to replace it (move it away, or choose another "
                                f"name)")
        if not overwrite:
            raise SpslidarError(f"--out {out} exists; use --overwrite to replace it")
    if path.parent.exists() and not path.parent.is_dir():
        raise SpslidarError(f"--out {out}: {path.parent} is a file, not a folder")
    from ..outdir import _check_writable

    # (a read-only folder failed after the work, naming a temporary file); missing folders
    # are made when the file is written, as reconstruct --out makes its own: here, the
    # nearest one that exists must be a folder one can write in (nothing is made yet, so a
    # refusal or a failed calibration leaves no empty folders behind)
    _check_writable(path.parent, f"--out {out}", make_parents=True)
    from ..outdir import check_name_fits

    check_name_fits(path, f"--out {out}")
    return path


def _loops(link: Path) -> bool:
    """Whether following ``link`` ends in a loop of symbolic links (False: it ends at a path
    that does not exist, or does)."""
    try:
        os.stat(link)
    except OSError as exc:
        return exc.errno == errno.ELOOP
    return False


def write_calibration(cal: dict[str, Any], out: str | os.PathLike, overwrite: bool = False):
    """Write ``CAL.json``: a new file, or (with ``overwrite``) a calibration spslidar wrote;
    never a user's other file (all or nothing, under a temporary name). Missing folders of
    its path are made."""
    from ..errors import SpslidarError
    from ..outwrite import atomic_write_text

    path = check_calibration_out(out, overwrite)
    made = [p for p in (path.parent, *path.parent.parents) if not p.exists()]
    body = {k: v for k, v in cal.items() if k != "content_sha256"}
    try:  # the missing folders only (exist_ok: an existing one is left as it is)
        path.parent.mkdir(parents=True, exist_ok=True)
        atomic_write_text(path, json.dumps({**body, "content_sha256": content_sha256(body)},
                                           indent=1) + "\n")
    except BaseException as exc:  # (Ctrl-C too) the folders made for it go with it
        for folder in made:  # deepest first; one something else was put in stays
            with contextlib.suppress(OSError):
                folder.rmdir()
        if isinstance(exc, OSError):
            raise SpslidarError(f"--out {out}: cannot write {path} "
                                f"({exc.strerror or type(exc).__name__})") from None
        raise
    return path


def code_sha256(code: np.ndarray) -> str:
    """The SHA-256 of a code's bits (one byte each): ``code_sha256`` in ``CAL.json``, and
    what ``reconstruct`` compares it with (``same_code`` in ``metrics.json``)."""
    return hashlib.sha256(np.asarray(code, np.uint8).tobytes()).hexdigest()


def code_bits(code: np.ndarray) -> str:
    """A code's bits as hexadecimal (``np.packbits``, L / 4 characters): ``code_bits`` in
    ``CAL.json``, so that ``reconstruct`` can tell a code that is the calibration's shifted
    (:func:`code_note`) from another one."""
    return np.packbits(np.asarray(code, np.uint8) != 0).tobytes().hex()


def _bits_of(cal: dict[str, Any]) -> np.ndarray | None:
    """The calibration's code bits where it holds them intact (files before 2026-11-29 do
    not), else None."""
    text, n = cal.get("code_bits"), cal.get("code_length")
    if not isinstance(text, str) or not isinstance(n, int):
        return None
    try:
        bits = np.unpackbits(np.frombuffer(bytes.fromhex(text), np.uint8))[:n]
    except ValueError:
        return None
    return bits if bits.size == n and code_sha256(bits) == cal.get("code_sha256") else None


def code_note(cal: dict[str, Any], code: np.ndarray, bit_rate: float) -> str | None:
    """What to say where the acquisition's code is not the calibration's (None where it is):
    the delay it measured holds only if both code files give the bits as sent from the sync
    on. A code that is the calibration's shifted by ``s`` bits (a generator started at
    another bit, or a code file rotated by mistake) moves every depth by ``s`` bits if the
    hardware sent the same phase both times, so the shift is named with its range (an audit's
    ``np.roll(code, 100)`` put every depth 1.5 m off without a word)."""
    code = np.asarray(code, np.uint8) != 0
    if cal.get("code_sha256") == code_sha256(code.astype(np.uint8)):
        return None
    head = "the calibration was measured with another code of the same length"
    tail = ("its delay holds only where both code files give the bits as sent from the sync "
            "on; if not, calibrate with this acquisition's code")
    theirs = _bits_of(cal)
    if theirs is not None:
        from ..codes.sequences import periodic_xcorr
        from ..constants import SPEED_OF_LIGHT

        # r[k] = sum_t theirs[t] code[t + k]: peaks at the shift that makes one the other
        s = int(np.argmax(periodic_xcorr(theirs, code.astype(np.uint8))))
        if np.array_equal(np.roll(theirs != 0, s), code):
            s = s if s <= code.size // 2 else s - code.size
            metres = abs(s) * SPEED_OF_LIGHT / (2.0 * float(bit_rate))
            return (f"the calibration was measured with this code shifted by {s:+d} bits "
                    f"({metres:.4g} m of range): {tail}; a code file rotated by mistake moves "
                    f"every depth by that much")
    return f"{head}: {tail}"


def content_sha256(cal: dict[str, Any]) -> str:
    """The SHA-256 of a calibration's content (its JSON, keys sorted, without this key):
    written with it, so that a file edited afterwards is known (an audit's ``lag_shift``
    edited by one bin moved every depth by 15 mm without a word, and ``calibrate
    --overwrite`` replaced a hand-annotated file)."""
    body = {k: v for k, v in cal.items() if k != "content_sha256"}
    return hashlib.sha256(json.dumps(body, sort_keys=True).encode("utf-8")).hexdigest()


def edited(cal: dict[str, Any]) -> bool:
    """Whether a calibration's content differs from the checksum it was written with (False
    for a file of an earlier version, written without one)."""
    return "content_sha256" in cal and cal["content_sha256"] != content_sha256(cal)


def load_calibration(path: str | os.PathLike, bit_rate: float, code: np.ndarray):
    """Read ``CAL.json`` and check that it belongs to this instrument setting (bit rate and
    the code's length: the delay and IRF are the instrument's, so a calibration measured with
    other code bits of the same length applies, and ``metrics.json`` says whether they were
    the same); one line otherwise, and for a file edited since it was written."""
    p = Path(path)
    if p.exists() and not _file_of_a_calibration(p):
        # (/dev/zero: a MemoryError traceback, an audit of 2026-11-29)
        raise ConfigError(f"--calibration {p} is not a calibration file (not a regular file "
                          f"of at most {MAX_CAL_BYTES // 2**20} MiB)")
    try:
        # (utf-8-sig: a file a Windows editor saved with a byte-order mark was "not JSON")
        cal = json.loads(p.read_text(encoding="utf-8-sig"))
    except OSError as exc:
        raise ConfigError(f"cannot read --calibration {p}: {exc.strerror or exc}") from None
    except (ValueError, RecursionError):  # (a deeply nested file: RecursionError)
        raise ConfigError(f"--calibration {p} is not a calibration file (not JSON)") from None
    if not isinstance(cal, dict) or cal.get("kind") != CAL_KIND:
        raise ConfigError(f"--calibration {p} is not a file written by 'spslidar calibrate'")
    if edited(cal):
        raise ConfigError(f"--calibration {p} was edited after spslidar calibrate wrote it "
                          f"(its content no longer matches its checksum, content_sha256); "
                          f"calibrate again")
    cal = check_calibration(cal, f"--calibration {p}", bit_rate, code)
    if "content_sha256" not in cal:
        # (files of 0.2.0 before 2026-11-28 have none; a file whose checksum was deleted
        # took a lag_shift edited by one bin, 15 mm on every depth, without a word: an audit)
        import warnings

        warnings.warn(f"--calibration {p} has no checksum (content_sha256): written before "
                      f"2026-11-28, or edited and the checksum removed; only its fields' "
                      f"consistency is checked, so calibrate again if in doubt", UserWarning,
                      stacklevel=2)
    cal["file"] = str(p)
    cal["file_sha256"] = sha256_file(p)
    return cal


def check_calibration(cal: dict, what: str, bit_rate: float, code: np.ndarray) -> dict:
    """A calibration's fields (IRF, delay, bit rate, code length), checked against this
    instrument setting; one line (:class:`ConfigError`) naming what is missing or wrong."""
    try:
        offsets = np.asarray(cal["irf_offsets"], dtype=np.int64)
        values = np.asarray(cal["irf_values"], dtype=np.float64)
        numbers = [float(cal[k]) for k in ("bit_rate_hz", "delay_s", "irf_fwhm_bins")]
        whole = [int(cal[k]) for k in ("code_length", "lag_shift")]
        numbers.append(float(cal.get("lag_fraction", 0.0)))
    except (KeyError, TypeError, ValueError, OverflowError) as exc:  # (an int of 21 digits)
        raise ConfigError(f"{what} is incomplete or damaged ({type(exc).__name__}: "
                          f"{exc}); calibrate again") from None
    if (offsets.shape != values.shape or values.ndim != 1 or not values.size
            or not np.all(np.isfinite(values)) or values.min() < 0 or values.sum() <= 0
            or not all(np.isfinite(numbers)) or whole[0] < 2):
        raise ConfigError(f"{what}: its IRF or numbers are damaged; calibrate again")
    _check_consistent(cal, offsets, values, numbers, whole, what)
    if abs(numbers[0] - float(bit_rate)) > 1e-9 * float(bit_rate):
        raise ConfigError(f"{what} was measured at {numbers[0]:g} bits/s, "
                          f"not {float(bit_rate):g}")
    if int(cal["code_length"]) != int(np.asarray(code).size):
        raise ConfigError(f"{what} was measured with a code of "
                          f"{cal['code_length']} bits, not {np.asarray(code).size}")
    calibration_shifts(cal, what)
    _check_records(cal, what)
    return cal


def _check_records(cal: dict, what: str) -> None:
    """The records ``reconstruct`` reads besides the numbers (where they are there): what it
    was measured from, its detector channels, its response's height and its warnings (a file
    edited by hand, ``"measured_from": 5``, was an AttributeError traceback; ``"channels": 5``
    skipped the channel check, ``"peak_to_noise": -5`` was said as a response -5 deviations
    high: an outside audit of 2026-12-02)."""
    def channel_list(v: Any) -> bool:
        return v is None or (isinstance(v, list) and all(
            isinstance(c, int) and not isinstance(c, bool) and 0 <= c < 128 for c in v))

    source = cal.get("measured_from")
    if source is not None and not (isinstance(source, dict) and channel_list(
            source.get("channels")) and channel_list(source.get("channel"))):
        raise ConfigError(f"{what}: its measured_from is damaged (an object whose channels "
                          f"are detector numbers 0-127); calibrate again")
    ptn = cal.get("peak_to_noise")  # (+inf is calibrate's own where the side noise is 0)
    if ptn is not None and not (isinstance(ptn, (int, float)) and not isinstance(ptn, bool)
                                and not math.isnan(ptn) and ptn > 0):
        raise ConfigError(f"{what}: its peak_to_noise {ptn!r} is damaged (a response's height "
                          f"in noise deviations, above 0); calibrate again")
    said = cal.get("warnings")
    if said is not None and not (isinstance(said, list)
                                 and all(isinstance(w, str) for w in said)):
        raise ConfigError(f"{what}: its warnings are damaged (a list of lines); calibrate again")
    for key in ("detector", "target"):
        if cal.get(key) is not None and not isinstance(cal[key], dict):
            raise ConfigError(f"{what}: its {key} record is damaged ({cal[key]!r}); calibrate "
                              f"again")


def calibration_shifts(cal: dict, what: str = "the calibration") -> dict[int, int]:
    """The whole bins each detector channel was moved by when the calibration was measured
    (``channel_shifts_bins``, ``calibrate --align-channels``; empty where none was), which a
    scan read through it must be moved by too; one line where the field is damaged."""
    raw = cal.get("channel_shifts_bins") or {}
    try:
        out = {int(c): v for c, v in dict(raw).items()}
    except (TypeError, ValueError):
        out = None
    if out is None or not all(isinstance(v, int) and not isinstance(v, bool)
                              and 0 <= c < 128 for c, v in out.items()):
        raise ConfigError(f"{what}: its channel_shifts_bins is damaged ({raw!r}); calibrate "
                          f"again")
    return out


def _check_consistent(cal: dict, offsets: np.ndarray, values: np.ndarray, numbers: list,
                      whole: list, what: str) -> None:
    """What :func:`~spslidar.pipeline.calibration.calibrate_ptu` writes holds together; a
    file edited by hand that breaks it is refused (a ``lag_fraction`` of 5 moved every depth
    by 8 cm, offsets as strings or all zeros, a ``lag_shift`` that contradicts ``delay_s``,
    were all taken)."""
    def items(key: str) -> list:
        v = cal[key]
        return list(v) if isinstance(v, (list, tuple, np.ndarray)) else [v]

    def exact_ints(key: str) -> bool:  # (NumPy's integers too: a dict built in Python)
        return all(isinstance(i, (int, np.integer)) and not isinstance(i, (bool, np.bool_))
                   for i in items(key))

    def reals(key: str) -> bool:
        return all(isinstance(i, (int, float, np.integer, np.floating))
                   and not isinstance(i, (bool, np.bool_)) for i in items(key))

    if not (exact_ints("irf_offsets") and exact_ints("lag_shift") and exact_ints("code_length")
            and reals("irf_values") and all(reals(k) for k in ("bit_rate_hz", "delay_s",
                                                                  "irf_fwhm_bins"))
            and ("lag_fraction" not in cal or reals("lag_fraction"))):
        raise ConfigError(f"{what}: a field holds text or a value of the wrong kind (offsets "
                          f"and lag_shift are whole numbers); calibrate again")
    if (np.any(np.diff(offsets) <= 0) or 0 not in offsets
            or np.abs(offsets).max() >= whole[0] / 2):
        # (offsets [0, 1023] of a 1023-bit code wrapped onto one bin and were taken)
        raise ConfigError(f"{what}: irf_offsets must be distinct, increasing bin offsets "
                          f"around 0, within half the code's period; calibrate again")
    if abs(values.sum() - 1.0) > 1e-6 or not numbers[2] > 0:
        # (irf_values x 1e6 passed, and scaled every reflectivity by 1e-6, without a word)
        raise ConfigError(f"{what}: irf_values must sum to 1 (they sum to {values.sum():.6g}) "
                          f"and irf_fwhm_bins be positive ({numbers[2]:g}); calibrate again")
    if abs(numbers[3]) > 0.5 + 1e-9:
        raise ConfigError(f"{what}: lag_fraction {numbers[3]:g} is outside [-0.5, 0.5] bins "
                          f"(the rest of the delay is lag_shift); calibrate again")
    period = whole[0]
    if not abs(numbers[1]) <= MAX_DELAY_S:  # (10**30 bins overflowed the lags: an audit)
        raise ConfigError(f"{what}: delay_s {numbers[1]:g} s is beyond any instrument's "
                          f"system delay (at most {MAX_DELAY_S:g} s); calibrate again")
    delay_bins = numbers[1] * numbers[0]  # delay_s x bit rate
    miss = (delay_bins - (whole[1] - numbers[3]) + period / 2) % period - period / 2
    # the sub-bin peak lies within 1 + 1/64 bins of the lag's (not NaN: a delay_s of 1e300
    # overflowed to inf and passed, an audit of 2026-11-29)
    if not abs(whole[1]) <= abs(delay_bins) + 2 * period:  # (calibrate: within a period)
        raise ConfigError(f"{what}: lag_shift {whole[1]} is more than two code periods from "
                          f"delay_s ({delay_bins:.4g} bins); calibrate again")
    if not abs(miss) <= 1.5:
        raise ConfigError(f"{what}: lag_shift {whole[1]} and lag_fraction {numbers[3]:g} "
                          f"disagree with delay_s ({delay_bins:.4g} bins) by {miss:.3g} "
                          f"bins; calibrate again")
    if "delay_bins" in cal and not (reals("delay_bins") and abs(
            float(cal["delay_bins"]) - delay_bins) <= 1e-6 * max(1.0, abs(delay_bins))):
        # (written as delay_s x bit rate; an edited delay_bins of 500 was taken, an audit)
        raise ConfigError(f"{what}: delay_bins {cal['delay_bins']!r} disagrees with delay_s x "
                          f"bit_rate_hz ({delay_bins:.6g} bins); calibrate again")
