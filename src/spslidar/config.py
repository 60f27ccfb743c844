"""The run configuration: one dataclass, the same keys on the command line and in TOML files.

Keys are the long option names of ``spslidar run`` with ``-`` or ``_`` (``code-length`` and
``code_length`` are the same key). Unknown keys and invalid values raise
:class:`~spslidar.errors.ConfigError` with a one-line message.
"""

from __future__ import annotations

import contextvars
import dataclasses
import functools
import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from . import registry as _registry
from .config_files import (  # noqa: F401  (re-exported: imported from here elsewhere)
    CLI_ONLY_KEYS,
    FILE_KEYS,
    MAX_CONFIG_BYTES,
    check_toml_bytes,
    names_a_file,
    read_config_bytes,
    read_toml,
    resolve_file_paths,
)
from .constants import MAX_COUNT_MEAN, MAX_DEPTH_M
from .errors import ConfigError

LIDARS = ("psst", "conventional")
REPLICAS = ("auto", "bipolar", "zero-mean", "unipolar")
FAIRNESS = ("energy", "power")


#: said where a flag is given as text: TOML's booleans are bare words
_UNQUOTED = " (in TOML: true or false without quotes)"


def _real(v: Any) -> float:
    """A real number as float; text and booleans are not (``range_gate = [19.9, "20.9"]``
    was read as numbers while ``size = "16"`` was refused)."""
    if isinstance(v, (str, bytes, bool)):
        raise TypeError(f"not a number: {v!r}")
    return float(v)


@dataclass
class Config:
    """Everything that defines one simulated acquisition and reconstruction.

    See ``spslidar run --help`` and ``docs/model.md`` for the meaning of each key. A config is
    validated (and its values normalised) once, when it is made; the choices of ``code``,
    ``patterns``, ``detector``, ``solver`` and ``depth`` come from the stages' registries
    (:func:`registries`), each entry checking the config with its own rules.

    Examples
    --------
    >>> from spslidar import Config
    >>> cfg = Config(scene="camera", size=16, code_length=2047)
    >>> cfg.replace(noise=5).noise, cfg.noise  # a validated copy; the original is unchanged
    (5.0, 10.0)
    >>> Config.from_dict({"code-length": 1023}).code_length  # command-line spelling too
    1023
    >>> Config(noise=-1)
    Traceback (most recent call last):
    ...
    spslidar.errors.ConfigError: --noise must be in [0, inf), got -1
    """

    # scene
    #: built-in scene name (``camera``, ``motorcycle``...) or a file: ``.npy`` depth in metres,
    #: ``.npz`` with ``depth`` (+ ``reflectivity``, ``valid``), ``.png``/``.tif`` grey image mapped
    #: into [``depth_min``, ``depth_max``]
    scene: str = "camera"
    #: [pixels] the scene and the DMD are ``size`` x ``size`` pixels (Q = size^2 unknowns per range
    #: slice)
    size: int = 64
    #: [m] rescale the scene's depth into [``depth_min``, ``depth_max``] (default: the scene's own
    #: range)
    depth_min: float | None = None
    #: [m] upper end of the rescaled depth range (see ``depth_min``)
    depth_max: float | None = None
    # lidar and code
    #: ``psst``: the laser gated by a pseudo-random code (the paper's lidar); ``conventional``:
    #: periodic single pulses in the same acquisition time (the paper's baseline)
    lidar: str = "psst"
    #: code family that gates the laser (its registry: ``spslidar.codes.CODES``)
    code: str = "mseq"
    #: [bits] bits per code period T; 2^n - 1 for ``mseq`` and ``gold``; sets the acquisition time
    #: per pattern (T / ``bit_rate``) for both lidars
    code_length: int = 16383
    #: share R_a of '1' bits of a ``random`` (Bernoulli) code, in (0, 1)
    ones_ratio: float = 0.5
    #: member of the Gold family, or cyclic shift of the m-sequence (default: Gold member 2, the
    #: first true Gold code, as members 0 and 1 are the preferred pair's m-sequences; shift 0)
    code_index: int | None = None
    #: [Hz] return-to-zero bit rate, equal to the TDC bin rate (10 GHz: 100 ps, 1.5 cm bins)
    bit_rate: float = 10e9
    #: [bits] laser pulse width as a fraction of a bit (0.5: return-to-zero)
    pulse_width: float = 0.5
    #: [Hz] pulse rate of the conventional lidar (default: the fastest whose unambiguous range
    #: covers the range gate)
    rep_rate: float | None = None
    #: conventional against PSST: the same pulse energy (``energy``, the paper's premise) or the
    #: same average power (``power``)
    fairness: str = "energy"
    #: code periods accumulated per DMD pattern (the dwell); signal and noise photons grow with it
    periods: int = 1
    #: [s] extra delay of every return by the instrument's cables and electronics (a real
    #: instrument, :mod:`spslidar.instrument`; ``spslidar calibrate`` measures it)
    system_delay: float = 0.0
    #: instrument response of every return: ``gaussian:FWHM[,tail:TAU[,weight:W]]`` (seconds) or a
    #: ``.npy`` file per TDC bin; ``None``: none
    irf: str | None = None
    # patterns
    #: DMD pattern kind (its registry: ``spslidar.patterns.PATTERNS``)
    patterns: str = "gaussian"
    #: spread of the grey-level ``gaussian`` patterns, ``clip(0.5 + sigma N(0, 1), 0, 1)``
    pattern_sigma: float = 0.25
    #: row ordering of ``hadamard`` patterns: ``cake-cutting`` (fewest constant pieces first),
    #: ``sequency``, ``random`` or ``natural``
    hadamard_order: str = "cake-cutting"
    #: how +-1 Hadamard rows are shown on a 0/1 DMD: ``shifted`` ((1 + h) / 2, the DC removed by
    #: QCR) or ``differential`` (two frames, half the time each)
    hadamard_realisation: str = "shifted"
    #: M / Q, DMD patterns per pixel, in (0, 1]
    compression: float = 0.25
    # photons
    #: [photons] m_s: mean signal photons per laser pulse per DMD pixel (mirror on, reflectivity
    #: 1); a pattern collects m_s sum(Phi alpha) per pulse (equation 8)
    signal: float = 5.0
    #: [counts] m_n: mean noise counts per TDC bin per pixel (ambient + background + dark), N^2 m_n
    #: per bin in all (equations 9-10, each term read per pixel: docs/reading.md)
    noise: float = 10.0
    #: shares of ``noise`` that are ambient light (through the scene), background and dark counts;
    #: three non-negative numbers summing to 1
    noise_split: tuple[float, float, float] = (1 / 3, 1 / 3, 1 / 3)
    #: ambient light added unmodulated as N^2 m_n1 (``paper``) or through the DMD patterns
    #: (``modulated``)
    ambient: str = "paper"
    #: [counts/s] extra background counts per second, in physical units
    background_rate: float = 0.0
    #: [counts/s] extra dark counts per second
    dark_count_rate: float = 0.0
    #: detector model (its registry: ``spslidar.detectors.DETECTORS``); its options
    #: (``dead_time``, ``jitter``...) are listed below
    detector: str = "linear"
    #: use the expected counts (no Poisson noise)
    noiseless: bool = False
    # processing
    #: matched-filter replica of the code: ``bipolar`` (2s - 1), ``zero-mean`` (s - mean s),
    #: ``unipolar`` (s) or ``auto`` (for ``psst`` bipolar where the code is balanced, zero-mean
    #: otherwise: :func:`spslidar.correlate.auto_replica`; unipolar for ``conventional``)
    replica: str = "auto"
    #: [m] the delays reconstructed, (MIN, MAX) in metres (default: the scene's depth window padded
    #: by 3 bins, placed from its true depths: said where it reaches beyond the unambiguous range)
    range_gate: tuple[float, float] | None = None
    #: drop the range slices without returns before solving (default: on for large gates)
    auto_gate: bool | None = None
    #: quadratic correlation reconstruction (equations 11-17): solve with the covariance of the
    #: measurements and the patterns instead of the raw matched-filter outputs
    qcr: bool = True
    #: ``centred`` least squares or the paper's literal ``covariance`` form ||Delta - H p||
    qcr_form: str = "centred"
    #: compressive-sensing solver of all range slices (its registry:
    #: ``spslidar.solvers.SOLVERS``)
    solver: str = "fista"
    #: regulariser of the solver: ``auto`` (the solver's default) or one of
    #: ``spslidar.solvers.REGULARISERS``
    regulariser: str = "auto"
    #: regularisation weight (default: ``lam_scale`` x the noise level estimated from the
    #: measurements, but at least ``LAM_FLOOR`` x ``||A^H y||_inf``; a ``noiseless`` run has no
    #: noise level and always takes the floor: see
    #: :func:`spslidar.pipeline.weights.default_weight`)
    lam: float | None = None
    #: multiple of the estimated noise level used as the weight (default: the solver's)
    lam_scale: float | None = None
    #: maximum solver iterations (default: the solver's, ``FLOORED_ITERATIONS`` (5) times as
    #: many where the floor set the weight, ``metrics['lam_floored']``)
    iterations: int | None = None
    #: relative-change stopping tolerance of the solver
    tol: float = 1e-4
    #: place each return below a bin from its peak and two neighbours (depth.profile.subbin_offset)
    subbin: bool = False
    #: constrain the reconstructed return strengths to be non-negative (photon returns cannot be
    #: negative)
    nonneg: bool = True
    #: depth estimator (its registry: ``spslidar.depth.ESTIMATORS``)
    depth: str = "mrf"
    #: floating-point precision of the reconstruction
    dtype: str = "float32"
    #: random seed of the patterns, the code (random) and the photon counts
    seed: int = 0
    #: [GB] refuse a run whose estimated peak memory exceeds this (default: the memory available
    #: now)
    max_memory: float | None = None
    #: [s] refuse a run whose estimated time exceeds this many seconds (default 1 h; a
    #: string with a unit, "10min" or "2h", is read as on the command line)
    max_time: float = 3600.0
    # where the numeric core runs (spslidar.backends)
    #: array library of the numeric core: ``numpy``, ``torch`` or ``cupy`` (``pip install
    #: spslidar[gpu]``); every stage choice runs, on the device where it has a kernel
    #: (:mod:`spslidar.backends.device`), else on the host through the same chain
    backend: str = "numpy"
    #: where the backend runs: ``cpu`` or ``cuda`` (needs ``torch`` or ``cupy``)
    device: str = "cpu"
    #: the options the stages declare (:func:`stage_options`: ``dead_time``, ``jitter``...),
    #: read as attributes (``cfg.dead_time``); every declared option is here once validated
    extra: dict[str, Any] = field(default_factory=dict)

    # -- construction -------------------------------------------------------------------
    @classmethod
    def from_dict(cls, d: dict[str, Any] | None = None, **kw) -> Config:
        """Build from a mapping (keys with ``-`` or ``_``); unknown keys are an error."""
        if d is not None and not isinstance(d, Mapping):
            raise ConfigError(f"a configuration is a mapping of keys to values, got "
                              f"{type(d).__name__}")
        merged, spelled = underscored_keys(d or {})
        for k, v in kw.items():  # the keywords override the mapping
            key = str(k).replace("-", "_")
            merged[key], spelled[key] = v, str(k)
        declared = stage_options()
        names = ({f.name for f in dataclasses.fields(cls)} - {"extra"}) | set(declared)
        clean: dict[str, Any] = {}
        extra: dict[str, Any] = {}
        for key, v in merged.items():
            if key not in names:
                close = close_names(key, names)
                # (a TOML of a plugin stage's options, read without the plugin, said only
                # "unknown config key 'window'": an outside audit of 2026-12-01)
                hint = (f" (did you mean {', '.join(close)}?)" if close else
                        " (a plugin stage's option? load its plugin with --plugin MODULE or "
                        "SPSLIDAR_PLUGINS)")
                raise ConfigError(f"unknown config key {spelled[key]!r}{hint}")
            if key in declared and v is None:
                # a stage option no chosen stage used is null in metrics.json's config: read
                # back, it is the default (a run's config then round-trips)
                continue
            (extra if key in declared else clean)[key] = v
        return cls(**clean, extra=extra)

    def __getattr__(self, name: str) -> Any:
        # a stage's declared option (only called when normal lookup fails)
        if name.startswith("__") or name == "extra":
            raise AttributeError(name)
        declared = stage_options()
        if name in declared:
            return self.__dict__.get("extra", {}).get(name, declared[name][1].default)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    @classmethod
    def from_toml(cls, path: str | Path, **overrides) -> Config:
        """Read a TOML file (top-level keys, or a ``[run]`` table) and apply overrides."""
        return cls.from_dict({**read_toml(path), **overrides})

    def __post_init__(self) -> None:
        self.validate()
        object.__setattr__(self, "_checked", True)

    def __setattr__(self, name: str, value: Any) -> None:
        # once built, an assignment is checked as Config(...) checks a keyword, and a stage's
        # option goes where the run reads it: ``cfg.dead_time = 1e-7`` was kept on the object
        # but ignored by the run, ``cfg.nosie = 5`` was accepted, ``cfg.noise = -5`` waited
        # for the run to be refused
        if not self.__dict__.get("_checked", False):  # while __init__ fills the fields
            object.__setattr__(self, name, value)
            return
        if name.startswith("_"):
            raise AttributeError(f"Config has no attribute {name!r}")
        checked = Config.from_dict({**self.to_dict(), name: value})
        self.__dict__.update(checked.__dict__)

    def replace(self, **kw) -> Config:
        """A validated copy with some keys changed."""
        return Config.from_dict({**self.to_dict(), **kw})

    def to_dict(self) -> dict[str, Any]:
        d = dataclasses.asdict(self)
        d.update(d.pop("extra"))
        for k in ("noise_split", "range_gate"):
            if d[k] is not None:
                d[k] = list(d[k])
        return d

    # -- validation ---------------------------------------------------------------------
    def validate(self) -> None:  # noqa: C901 - a flat list of checks
        """Check and normalise every field (run by ``__post_init__`` and on assignment):
        NumPy scalars as Python's, stage names in any case as registered, each stage's
        declared options bounded, numbers in their ranges, the range gate, the memory and
        time limits and the backend; each failure one :class:`ConfigError` line naming the
        flag."""
        for f in dataclasses.fields(self):  # NumPy scalars (np.int64(8), np.bool_) as Python's
            v = getattr(self, f.name)
            if type(v).__module__ == "numpy" and getattr(v, "ndim", None) == 0:
                setattr(self, f.name, v.item())

        def choice(name, options):
            v = getattr(self, name)
            if v not in options:
                raise ConfigError(f"unknown {name.replace('_', '-')} {v!r}; "
                                  f"choose one of {', '.join(options)}")

        def number(name, lo=None, hi=None, lo_open=False, hi_open=False, integer=False,
                   optional=False):
            v = getattr(self, name)
            if v is None and optional:
                return
            opt = name.replace("_", "-")
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                # (a TOML's `size = true` was said as "got True", Python's spelling: an
                # outside audit of 2026-12-03)
                got = f"{str(v).lower()} (a true/false value)" if isinstance(v, bool) else repr(v)
                raise ConfigError(f"--{opt} must be a number, got {got}")
            try:  # a NaN, an infinity or an integer beyond any float is none of these
                finite = math.isfinite(float(v))
            except OverflowError:
                finite = False
            if not finite:
                shown = v if isinstance(v, float) else f"an integer of {len(str(abs(v)))} digits"
                raise ConfigError(f"--{opt} must be finite, got {shown}")
            if integer:
                if isinstance(v, float) and not v.is_integer():
                    raise ConfigError(f"--{opt} must be an integer, got {v}")
                v = int(v)
                setattr(self, name, v)
            else:
                setattr(self, name, float(v))
            if not math.isfinite(v):
                raise ConfigError(f"--{opt} must be finite, got {v}")
            if lo is not None and (v < lo or (lo_open and v == lo)):
                rng_txt = f"{'(' if lo_open else '['}{lo}, {hi if hi is not None else 'inf'}" \
                          f"{')' if hi_open or hi is None else ']'}"
                raise ConfigError(f"--{opt} must be in {rng_txt}, got {v}")
            if hi is not None and (v > hi or (hi_open and v == hi)):
                rng_txt = f"{'(' if lo_open else '['}{lo}, {hi}{')' if hi_open else ']'}"
                raise ConfigError(f"--{opt} must be in {rng_txt}, got {v}")

        choice("lidar", LIDARS)
        from .solvers import REGULARISERS

        choice("regulariser", ("auto", *REGULARISERS.names()))
        choice("replica", REPLICAS)
        choice("fairness", FAIRNESS)
        choice("ambient", ("paper", "modulated"))
        choice("qcr_form", ("centred", "covariance"))
        if not isinstance(self.dtype, str):  # np.float32 or np.dtype("float32"): its name
            import numpy as np  # (a NumPy type was "unknown dtype <class ...>", an audit)

            try:
                self.dtype = np.dtype(self.dtype).name
            except TypeError:
                pass  # refused by choice() below, as given
        choice("dtype", ("float32", "float64"))
        from .patterns import HADAMARD_ORDERS, HADAMARD_REALISATIONS

        choice("hadamard_order", HADAMARD_ORDERS)
        choice("hadamard_realisation", HADAMARD_REALISATIONS)
        if not isinstance(self.scene, (str, Path)) or str(self.scene) == "":
            raise ConfigError("--scene must be a built-in scene name or a file path")
        self.scene = str(self.scene)
        number("size", 4, 2048, integer=True)
        number("depth_min", 0, MAX_DEPTH_M, optional=True)
        number("depth_max", 0, MAX_DEPTH_M, lo_open=True, optional=True)
        if self.depth_min is not None and self.depth_max is not None \
                and self.depth_min >= self.depth_max:
            raise ConfigError(f"--depth-min ({self.depth_min}) must be below --depth-max "
                              f"({self.depth_max})")
        number("code_length", 2, 2**24, integer=True)
        number("ones_ratio", 0, 1, lo_open=True, hi_open=True)
        number("code_index", 0, integer=True, optional=True)
        number("bit_rate", 0, lo_open=True)
        if not 1e6 <= self.bit_rate <= 1e13:
            # a bin of 150 m or more resolves no depth; one shorter than 0.1 ps (15 um) is
            # beyond any time-to-digital converter (the fastest bin at about 1 ps)
            raise ConfigError(f"--bit-rate must be in [1e6, 1e13] bits (TDC bins) per second, "
                              f"got {self.bit_rate:g}: its bins would be "
                              f"{149896229.0 / self.bit_rate:.3g} m deep")
        number("pulse_width", 0, 1, lo_open=True)
        number("rep_rate", 0, lo_open=True, optional=True)
        number("periods", 1, 2**31, integer=True)
        number("pattern_sigma", 0, lo_open=True)
        number("compression", 0, 1, lo_open=True)
        n_pat = max(1, int(round(self.compression * self.size * self.size)))
        if n_pat < 2:
            # QCR centres the measurements over the patterns: one pattern leaves nothing
            raise ConfigError(f"--compression {self.compression:g} gives {n_pat} pattern at "
                              f"{self.size}x{self.size}; at least 2 are needed (use at least "
                              f"{2 / self.size ** 2:.3g})")
        number("signal", 0, lo_open=True)
        number("noise", 0)
        number("background_rate", 0)
        number("dark_count_rate", 0)
        # one pixel's expected counts per bin beyond what a float32 count holds exactly: no
        # image of N x N >= 16 such pixels can run (signal=1e38 overflowed to an infinite mean
        # deep in the detector); the detector checks the whole image's means again
        per_bin = {"signal": self.signal, "noise": self.noise,
                   "background_rate": self.background_rate / self.bit_rate
                   if math.isfinite(self.bit_rate) and self.bit_rate > 0 else 0.0,
                   "dark_count_rate": self.dark_count_rate / self.bit_rate
                   if math.isfinite(self.bit_rate) and self.bit_rate > 0 else 0.0}
        for name, v in per_bin.items():
            if v > MAX_COUNT_MEAN:
                raise ConfigError(f"--{name.replace('_', '-')} {getattr(self, name):g} gives "
                                  f"about {v:.3g} expected photons per TDC bin per pixel, more "
                                  f"than the {MAX_COUNT_MEAN:.3g} a count holds exactly (a "
                                  f"real detector saturates at about one count per dead time)")
        for reg in registries().values():  # "FISTA", "GMAPD": names are read in any case
            setattr(self, reg.option, reg.canonical(getattr(self, reg.option)))
        self._validate_stage_options()
        number("lam", 0, optional=True)
        number("lam_scale", 0, lo_open=True, optional=True)
        number("iterations", 1, integer=True, optional=True)
        number("tol", 0)
        number("seed", 0, integer=True)
        if isinstance(self.max_memory, str):  # "500MB", "2GB" as on the command line
            from .machine import parse_memory

            self.max_memory = parse_memory(self.max_memory)
        number("max_memory", 0, lo_open=True, optional=True)
        if isinstance(self.max_time, str):  # "90s", "10min", "2h" as on the command line
            from .machine import parse_duration

            self.max_time = parse_duration(self.max_time)
        number("max_time", 0, lo_open=True)
        number("system_delay", 0, 1e-3)
        if self.irf is not None:
            from .instrument import parse_irf

            self.irf = str(self.irf) if str(self.irf).strip() else None
            parse_irf(self.irf)  # one line for a malformed spec
        if self.auto_gate is not None and not isinstance(self.auto_gate, bool):
            raise ConfigError(f"auto-gate must be true or false, got {self.auto_gate!r}"
                              f"{_UNQUOTED if isinstance(self.auto_gate, str) else ''}")
        for flag in ("qcr", "subbin", "noiseless", "nonneg"):
            if not isinstance(getattr(self, flag), bool):
                raise ConfigError(f"{flag} must be true or false, got {getattr(self, flag)!r}"
                                  f"{_UNQUOTED if isinstance(getattr(self, flag), str) else ''}")
        try:
            split = tuple(_real(v) for v in self.noise_split)
        except (TypeError, ValueError):
            raise ConfigError(f"noise-split must be three numbers, got {self.noise_split!r}") \
                from None
        if len(split) != 3 or min(split) < 0 or abs(sum(split) - 1) > 1e-6:
            raise ConfigError(f"noise-split must be three non-negative shares summing to 1, "
                              f"got {list(split)}")
        self.noise_split = split
        if self.range_gate is not None:
            try:
                g = tuple(_real(v) for v in self.range_gate)
            except (TypeError, ValueError):
                raise ConfigError(f"--range-gate must be two numbers MIN MAX, got "
                                  f"{self.range_gate!r}") from None
            if len(g) != 2 or not all(math.isfinite(v) for v in g) or g[0] < 0 or g[1] <= g[0]:
                raise ConfigError(f"--range-gate must be MIN MAX with 0 <= MIN < MAX metres, "
                                  f"got {list(g)}")
            if g[1] > MAX_DEPTH_M:
                raise ConfigError(f"--range-gate {g[0]:g} {g[1]:g} reaches beyond any lidar "
                                  f"range (at most {MAX_DEPTH_M:.0e} m): are the values in "
                                  f"metres?")
            self.range_gate = g
        for reg in registries().values():
            reg.get(getattr(self, reg.option)).check(self)
        from .backends import check_backend

        if _ENVIRONMENT.get():  # (not while a file's overridden values are checked alone)
            check_backend(self.backend, self.device)


    def _validate_stage_options(self) -> None:
        """Each option a stage declares: normalised and bounded by its declaration, and
        refused (one line) when given to a stage that does not take it."""
        declared = stage_options()
        unknown = set(self.extra) - set(declared)
        if unknown:
            raise ConfigError(f"unknown config key {sorted(unknown)[0]!r}")
        for name, (reg, opt) in declared.items():
            given = name in self.extra
            value = opt.check(self.extra.get(name, opt.default))
            chosen = getattr(self, reg.option)
            takes = any(o.name == name for o in reg.get(chosen).options)
            if given and not takes and value != opt.default:
                owners = ", ".join(reg.owners(name))
                mine = ", ".join(o.flag for o in reg.get(chosen).options) or "no options"
                raise ConfigError(f"{opt.flag} is an option of --{reg.option} {owners}, not of "
                                  f"--{reg.option} {chosen} (which takes {mine})")
            self.extra[name] = value


_dataclass_init = Config.__init__


@functools.wraps(_dataclass_init)
def _init(self, *args: Any, extra: dict[str, Any] | None = None, **kw: Any) -> None:
    # Config(dead_time=..., jitter=...): the options the stages declare are keywords too
    declared = stage_options()
    options = {k: kw.pop(k) for k in list(kw) if k in declared}
    unknown = sorted(set(kw) - {f.name for f in dataclasses.fields(Config)})
    if unknown:  # as from_dict says it (with its hint), not Python's "unexpected keyword"
        Config.from_dict({unknown[0]: kw[unknown[0]]})
    _dataclass_init(self, *args, extra={**(extra or {}), **options}, **kw)


def close_names(key: str, names) -> list[str]:
    """The names a misspelt ``key`` may have meant, sorted: those similar to it by
    ``difflib`` (up to three) and those sharing its first three letters."""
    import difflib

    names = sorted(names)
    close = set(difflib.get_close_matches(key, names, 3, 0.7))
    return sorted(close | {n for n in names if n.startswith(key[:3])})


Config.__init__ = _init


def underscored_keys(d: Mapping[str, Any], what: str = "config key"
                     ) -> tuple[dict[str, Any], dict[str, str]]:
    """``d`` with each key as a configuration reads it (``code-length`` is ``code_length``),
    and each key as it was written; two spellings of one key are a mistake, refused in one
    line (``{what} 'code_length' given twice ('code_length' and 'code-length')``). A sweep's
    ``[base]`` and ``[grid]`` are read so too (their seeds and columns had followed the
    spelling: an outside audit of 2026-12-01)."""
    merged: dict[str, Any] = {}
    spelled: dict[str, str] = {}
    for k, v in d.items():
        key = str(k).replace("-", "_")
        if key in merged:
            raise ConfigError(f"{what} {key!r} given twice ({spelled[key]!r} and {k!r})")
        merged[key], spelled[key] = v, str(k)
    return merged, spelled


def stage_options() -> dict:
    """Every option the stages declare (:class:`~spslidar.registry.Option`), by config key:
    ``{name: (registry, option)}``. An option named as one of :class:`Config`'s own keys, or
    declared by another registry too, is a one-line ConfigError naming it: a plugin
    detector's ``signal`` took the key over (``Config(signal=7)`` was refused as "an option of
    --detector noisy", and its detector got the 7 while the physics kept 5), an estimator's
    option of a detector option's name was taken for the detector's (an audit of plugins).
    Declared alike by two registries, it was one key for both stages here while the command
    line refused it (one flag per stage kind, an audit of stop 64): refused here too, as
    the command line does; within one registry (``dead_time`` of every detector) a name
    declared alike is one key."""
    own = _config_fields()
    out: dict = {}
    for reg in registries().values():
        for name, opt in reg.options().items():
            owners = f"--{reg.option} {', '.join(reg.owners(name))}"
            if name in own:
                raise ConfigError(f"{opt.flag}, an option of {owners}, has the name of one of "
                                  f"spslidar's own config keys: the stage must name it "
                                  f"otherwise")
            other, first = out.get(name, (reg, opt))
            if other is not reg:
                alike = "alike" if _declared(first) == _declared(opt) else "otherwise"
                raise ConfigError(f"{opt.flag} is declared by {owners} and, {alike}, by "
                                  f"--{other.option} {', '.join(other.owners(name))}: one "
                                  f"of them must name it otherwise (one config key and "
                                  f"flag is one stage kind's)")
            out.setdefault(name, (reg, opt))
    return out


def _declared(opt) -> tuple:
    """What makes two declarations of an option one config key (as within a registry:
    :meth:`~spslidar.registry.Registry.add`): default, kind and bounds."""
    return (opt.default, opt.kind, opt.lo, opt.hi)


@functools.lru_cache(maxsize=1)
def _config_fields() -> frozenset[str]:
    """:class:`Config`'s own keys (its dataclass fields, ``extra`` aside)."""
    return frozenset(f.name for f in dataclasses.fields(Config)) - {"extra"}


def chosen_stage_options(cfg: Config, option: str) -> dict[str, Any]:
    """The options that the stage ``cfg`` chose in registry ``option`` (``code``,
    ``patterns``, ``detector``, ``solver``, ``depth``) declares, as the keywords it is built
    with (each :class:`~spslidar.registry.Option`'s ``param``, default its name): the value
    given, else its default. Every registry's options reach their stage so (only the
    detectors' did: a pattern kind's, solver's or estimator's own option was validated,
    written to ``metrics.json`` and never given to it, an audit of 2026-11-28)."""
    entry = registries()[option].get(getattr(cfg, option))
    return {opt.param or opt.name: cfg.extra.get(opt.name, opt.default) for opt in entry.options}


def registries() -> dict:
    """The registries whose entries a config chooses among, by config key."""
    from .codes import CODES
    from .depth import ESTIMATORS
    from .detectors import DETECTORS
    from .patterns import PATTERNS
    from .solvers import SOLVERS

    return {r.option: r for r in (CODES, PATTERNS, DETECTORS, SOLVERS, ESTIMATORS)}


_registry._CHOOSERS[:] = [registries]  # (a stage's option is checked where registered)


#: whether validation checks what this machine has (the backend): not for a config file's
#: values that the command line overrides (:func:`check_overridden`)
_ENVIRONMENT: contextvars.ContextVar[bool] = contextvars.ContextVar("spslidar_environment",
                                                                     default=True)


def unchosen_options(base: dict[str, Any], overrides: dict[str, Any],
                     source: str) -> tuple[dict[str, Any], list[str]]:
    """A config file's keys less the options of a stage the command line replaced, and a
    warning for each left out: a file's ``detector = "gmapd"`` and ``jitter = 1e-10`` run
    with ``--detector linear`` were refused as "--jitter is an option of --detector gmapd",
    a flag the user never typed, where the command line is to override the file (an outside
    audit). An option the new stage declares too (``dead_time``) is kept."""
    given = {str(k).replace("-", "_"): v for k, v in overrides.items() if v is not None}
    own = {str(k).replace("-", "_"): k for k in base}
    out, notes = dict(base), []
    for key, reg in registries().items():
        if key not in given or key not in own:
            continue
        old, new = base[own[key]], given[key]
        if not isinstance(old, str) or not isinstance(new, str):
            continue
        old, new = reg.canonical(old), reg.canonical(new)
        if old == new or old not in reg or new not in reg:
            continue
        keep = {o.name for o in reg.get(new).options}
        for opt in reg.get(old).options:
            if opt.name in own and opt.name not in keep and opt.name not in given:
                out.pop(own[opt.name])
                notes.append(f"{source}'s {opt.name} (an option of --{key} {old}) is left "
                             f"out: --{key} {new} on the command line replaces its {old}")
    return out, notes


def check_overridden(base: dict[str, Any], overrides: dict[str, Any], source: str) -> None:
    """Refuse, in one line, a config file's value that the command line overrides but that is
    invalid in itself (not a number, out of its range, an unknown name): ``size = 16.5``
    with ``--size 8`` ran, and the same file without the flag was refused (an audit of
    2026-11-29).

    A value counts as invalid only where it is refused beside the defaults, beside the
    file's own other values and beside the run's (the file's and the command line's), and
    what this machine has (the backend) is not asked: a file's ``compression = 0.0002``
    beside its own ``size = 128`` (one pattern at the default 64x64) and a GPU file's
    ``backend = "torch"`` overridden by ``--backend numpy`` on a machine without PyTorch are
    not refused (a review of 2026-11-30). A stage's option is checked by its declaration.

    Parameters
    ----------
    base : dict
        The file's keys (dashed or not) and values.
    overrides : dict
        The command line's, ``None`` where a flag was not given.
    source : str
        The file, as the message names it.
    """
    declared = stage_options()
    given = {str(k).replace("-", "_"): v for k, v in overrides.items() if v is not None}
    own = {str(k).replace("-", "_"): v for k, v in base.items()}
    merged = {**own, **given}
    token = _ENVIRONMENT.set(False)
    try:
        for k, v in base.items():
            key = str(k).replace("-", "_")
            if key not in given:
                continue
            try:
                if key in declared:
                    declared[key][1].check(v)
                else:
                    refusals = []
                    for context in ({}, own, merged):
                        try:
                            Config.from_dict({**context, key: v})
                            break
                        except ConfigError as err:
                            refusals.append(err)
                    else:  # refused in every context: the first one's reason
                        raise refusals[0]
            except ConfigError as err:
                raise ConfigError(f"config file {source}: {err} (--{key.replace('_', '-')} "
                                  f"on the command line overrides it, but the file must hold "
                                  f"valid values)") from None
    finally:
        _ENVIRONMENT.reset(token)
