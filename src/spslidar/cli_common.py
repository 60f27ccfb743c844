"""What the sub-commands' parsers share (``cli``, ``cli_measured``, ``cli_snr``): the stage
choices and option flags read from the registries, the value types of ``--max-time``,
``--max-memory`` and ``--fov``, the list of files a command has written (which the
interrupted line names), and the command line's streams: its one-line warnings and its
tolerant stdout and stderr (moved out of ``cli``, which had grown past 700 lines). Its own
module, so that the sub-commands' modules import it and ``cli`` imports them, with no import
back.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from .errors import library_notice, numbers_blanked, warning_origin

#: what this command wrote so far (the interrupted line says it)
_WRITTEN: list[str] = []
#: the warnings said while the plugins loaded: a replaced built-in stage, which the run's
#: own warnings repeat for metrics.json, is said once on stderr
SAID_AT_LOAD: set[str] = set()


def say_warnings(warns: list[str]) -> None:
    """A result's warnings on stderr, one line each, but those said at the plugins' load."""
    for w in warns:
        if w not in SAID_AT_LOAD:
            print(f"spslidar: warning: {w}", file=sys.stderr)


def _choices(option: str):
    """The registered names and their one-line help for a stage option."""
    from .config import registries

    reg = registries()[option]
    return reg.names(), reg.help_text()


def _stage_name(option: str):
    """An argparse ``type`` that reads a stage's name in any case (``--solver FISTA``), before
    argparse checks it against the registered names."""
    from .config import registries

    return registries()[option].canonical


def _add_regulariser_option(g) -> None:
    """``--regulariser``, its choices and help from the registry (run's and reconstruct's)."""
    from .solvers import REGULARISERS

    g.add_argument("--regulariser", choices=("auto", *REGULARISERS.names()),
                   default=argparse.SUPPRESS,
                   help=f"auto: the solver's default; {REGULARISERS.help_text()}")


def _add_stage_options(g, option: str, skip_taken: bool = False) -> list[str]:
    """The flags of the options that the stages of one registry declare
    (:class:`~spslidar.registry.Option`): type, help, unit and default from the declaration,
    the stages that take each named in its help (every registry's: only the detectors' had
    flags, so a plugin solver's or estimator's option had none, an audit). ``skip_taken``:
    an option whose flag the command already has is left without one (``snr``'s --method
    beside a plugin code family's ``method``: it runs at its default there), where otherwise
    a taken flag is a one-line error. Returns the config keys given a flag."""
    from .config import registries

    reg = registries()[option]
    added = []
    for name, opt in reg.options().items():
        owners = ", ".join(reg.owners(name))
        kind = {"float": float, "int": int}.get(opt.kind.__name__)
        extra = ({"choices": ("on", "off")} if opt.kind is bool else
                 {"choices": opt.choices} if opt.choices else
                 {"type": kind, "metavar": opt.unit.upper() or "X"} if kind else {})
        try:
            g.add_argument(opt.flag, default=argparse.SUPPRESS, **extra,
                           help=f"{owners}: {opt.describe()}")
            added.append(name)
        except argparse.ArgumentError:  # (argparse's traceback, exit 1, an audit of plugins)
            if skip_taken:  # (a command that only borrows the stage: its own flag kept)
                continue
            from .errors import ConfigError

            other = [f"--{r.option} {', '.join(r.owners(name))}"
                     for r in registries().values() if r is not reg and r.owners(name)]
            whose = f"an option of {other[0]}" if other else "the command's own"
            raise ConfigError(f"{opt.flag}, an option of --{option} {owners}, is already a "
                              f"flag of this command ({whose}): the stage must name it "
                              f"otherwise") from None
    return added


def _duration(text: str) -> float:
    """``--max-time``: seconds, or a number with a unit (``90s``, ``10min``, ``2h``, ``1d``)."""
    from .machine import parse_duration

    try:
        return parse_duration(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc).replace("--max-time must be", "must be")) \
            from None


def _memory(text: str) -> float:
    """``--max-memory`` in gigabytes: a number (GB), or one with a unit (``500MB``, ``2GB``,
    ``1.5GiB``; ``2GB`` was an invalid float while ``--max-time`` took units)."""
    from .errors import ConfigError
    from .machine import parse_memory

    try:
        return parse_memory(text)
    except ConfigError as exc:
        raise argparse.ArgumentTypeError(str(exc).replace("--max-memory: ", "")) from None


def _fov(text: str) -> float:
    """``--fov`` in degrees, in (0, 180)."""
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {text!r}") from None
    if not 0.0 < value < 180.0:
        raise argparse.ArgumentTypeError(f"must lie in (0, 180) degrees, got {text}")
    return value


#: the fields of view (degrees) ``--fov`` takes without a warning
FOV_SANE = (0.01, 120.0)


def warn_fov(fov: float | None) -> None:
    """Say a ``--fov`` outside :data:`FOV_SANE` (``--fov 179.999`` put a 10 m wall's corners
    at 7e-8 m, and 1e-300 every point on the axis, without a word: an outside audit of
    2026-12-01; a typo, most likely). Called by the commands, whose warnings are one line."""
    if fov is not None and not FOV_SANE[0] <= fov <= FOV_SANE[1]:
        import warnings

        warnings.warn(f"--fov {fov:g} degrees is outside the {FOV_SANE[0]:g}-{FOV_SANE[1]:g} "
                      f"degrees a single-pixel lidar's optics span: the point cloud is "
                      f"written through it as given", UserWarning, stacklevel=2)


def _add_fov_option(p: argparse.ArgumentParser) -> None:
    p.add_argument("--fov", type=_fov, default=None, metavar="DEG",
                   help="full field of view across the image, degrees, for points.ply (default "
                        "10; the paper gives no optics)")


def _written(out) -> list[str]:
    """The result files in ``out``, in a fixed order, for the closing line."""
    from pathlib import Path

    order = ("metrics.json", "depth.npy", "reflectivity.npy", "confidence.npy", "depth2.npy",
             "points.ply", "truth.npy", "valid.npy", "depth.png")
    try:
        have = {p.name for p in Path(out).iterdir()}
    except OSError:  # (a folder the umask left unreadable, 0777: the files are in it, and
        # the closing line's listing made a written run exit 2, a review of 2026-11-30)
        return ["(the folder's mode, from the umask, forbids listing it)"]
    return [name for name in order if name in have]


class _OneLineWarnings:
    """``warnings.showwarning`` of the command line: ``spslidar CMD: warning: ...`` on stderr,
    one line, without the warning's source line. A warning that comes again from the same
    place with only its numbers changed (the GMAPD's fixed point, once per block of patterns)
    is counted, not repeated: :meth:`close` says how many more came."""

    def __init__(self, command: str):
        self.command = command
        self.repeats: dict[tuple, int] = {}
        self.first: dict[tuple, str] = {}

    def __call__(self, message, category, filename, lineno, file=None, line=None):
        if library_notice(category):  # a library's deprecation: not the run's
            return
        text = " ".join(str(message).split())
        key = (category, filename, lineno, numbers_blanked(text))
        if key in self.repeats:
            self.repeats[key] += 1
            return
        self.repeats[key] = 0
        self.first[key] = text
        print(f"spslidar {self.command}: warning: {text}"
              f"{warning_origin(category, filename, lineno)}",
              file=sys.stderr if file is None else file)

    def close(self) -> None:
        for key, n in self.repeats.items():
            category, filename, lineno, _ = key
            if n:
                what = (f"the warning above (\"{' '.join(self.first[key].split()[:8])} ...\")"
                        if not warning_origin(category, filename, lineno) else
                        f"the {category.__name__} of {Path(filename).name}:{lineno} above")
                print(f"spslidar {self.command}: warning: {what} came {n} more time"
                      f"{'s' if n > 1 else ''} (its numbers changed)", file=sys.stderr)
        self.repeats.clear()
        self.first.clear()


class _Tolerant:
    """``sys.stdout`` or ``sys.stderr`` while a command runs: a write that the stream refuses
    (a full disk, a closed pipe: ``| head -1``, ``2>/dev/full``) is dropped, and so is every
    later one, and a character its encoding lacks is escaped. A warning written to a full
    disk's log threw the finished run away (exit 1 or 120, no output, no word anywhere), a
    closed pipe after the outputs were written was "error: Broken pipe: while writing --out"
    (they were complete), and ``PYTHONIOENCODING=ascii`` a traceback after them (an outside
    audit of 2026-11-30). Only in a process of its own (``main()`` without ``argv``), whose
    stream's descriptor is pointed at ``os.devnull`` once it fails, so that Python's last
    flush does not fail again (its "Exception ignored" lines and exit 120)."""

    def __init__(self, stream, own: bool):
        self._stream, self._own, self.failed = stream, own, False

    def write(self, text: str) -> int:
        if self.failed:
            return len(text)
        try:
            return self._stream.write(text)
        except UnicodeEncodeError:
            enc = getattr(self._stream, "encoding", None) or "ascii"
            return self.write(text.encode(enc, "backslashreplace").decode(enc))
        except (OSError, ValueError):  # (ValueError: a closed file)
            self._fail()
            return len(text)

    def flush(self) -> None:
        if not self.failed:
            try:
                self._stream.flush()
            except (OSError, ValueError):
                self._fail()

    def _fail(self) -> None:
        self.failed = True
        if not self._own:
            return
        try:
            null = os.open(os.devnull, os.O_WRONLY)
            try:
                os.dup2(null, self._stream.fileno())
            finally:
                os.close(null)
        except (OSError, ValueError, AttributeError):
            pass

    def __getattr__(self, name: str):
        return getattr(self._stream, name)
