"""Sphinx directives that render reference pages from the code's own declarations.

``.. spslidar-cli::``
    The command-line reference: every sub-command of :func:`spslidar.cli.build_parser`, its
    usage, description and every option (flags, metavar, choices, default, help), grouped as
    ``--help`` groups them. Nothing is copied by hand: a new flag appears at the next build.

``.. spslidar-config::``
    Every field of :class:`spslidar.config.Config` and every option a stage declares
    (:class:`spslidar.registry.Option`): key, command-line flag, type, unit, default, choices
    and meaning. The meaning is the field's ``#:`` comment in ``config.py`` (its unit the
    ``[unit]`` it starts with), else the option's own help; the choices come from the stage
    registries and the ``run`` parser, as the command line gets them. A field without a
    description is a build warning (an error under ``-W``).

``.. spslidar-metrics::``
    The keys of ``metrics.json``: a tiny run is made at build time and every key it writes is
    listed with its description from :data:`METRICS`; a key without one is a build warning, a
    described key no run writes is listed as written by ``reconstruct`` only.
"""

from __future__ import annotations

import argparse
import dataclasses
import re
import textwrap

from docutils import nodes
from docutils.statemachine import StringList
from sphinx.util import logging
from sphinx.util.docutils import SphinxDirective

logger = logging.getLogger(__name__)


def _rst_escape(text: str) -> str:
    """Help text as inline reST: ``*``, ``_``, backquotes and ``|`` literal."""
    return re.sub(r"([*_`|\\])", r"\\\1", text)


def _literal(text: str) -> str:
    text = str(text)
    return f"``{text}``" if text and "``" not in text else _rst_escape(text)


class _Generated(SphinxDirective):
    """A directive whose body is generated reST, parsed in place."""

    def render(self) -> list[str]:  # pragma: no cover - overridden
        raise NotImplementedError

    def run(self) -> list[nodes.Node]:
        lines = self.render()
        node = nodes.section() if self.has_sections else nodes.container()
        node.document = self.state.document
        source = self.get_source_info()[0]
        content = StringList([line for line in lines], source=source)
        if self.has_sections:
            from sphinx.util.nodes import nested_parse_with_titles

            nested_parse_with_titles(self.state, content, node)
        else:
            self.state.nested_parse(content, self.content_offset, node)
        return node.children

    has_sections = False


# -- the command-line reference ------------------------------------------------------------
def _default(action: argparse.Action) -> str:
    if action.default in (None, argparse.SUPPRESS) or isinstance(
            action, (argparse._StoreTrueAction, argparse._HelpAction,
                     argparse._VersionAction)):
        return ""
    if isinstance(action.default, (list, tuple)):
        return " ".join(map(str, action.default))
    return str(action.default)


def _names(action: argparse.Action) -> str:
    if not action.option_strings:
        return _literal(action.metavar or action.dest)
    metavar = action.metavar
    if action.nargs == 0:
        arg = ""
    elif isinstance(metavar, tuple):
        arg = " " + " ".join(metavar)
    elif metavar:
        arg = f" {metavar}"
    elif action.choices:
        arg = " {" + ",".join(map(str, action.choices)) + "}"
    else:
        arg = " " + action.dest.upper()
    return ", ".join(_literal(o + arg) for o in action.option_strings)


def _action_rows(actions: list[argparse.Action]) -> list[str]:
    rows = []
    for a in actions:
        if isinstance(a, (argparse._HelpAction, argparse._SubParsersAction)):
            continue
        help_text = _rst_escape(a.help or "")
        if a.choices and not (a.metavar and not a.option_strings):
            help_text += " Choices: " + ", ".join(_literal(c) for c in a.choices) + "."
        elif a.choices:
            help_text += " Choices: " + ", ".join(_literal(c) for c in a.choices) + "."
        default = _default(a)
        if default and "default" not in (a.help or ""):
            help_text += f" Default: {_literal(default)}."
        if a.required:
            help_text = "**Required.** " + help_text
        rows.append(f"   * - {_names(a)}")
        rows.append(f"     - {help_text.strip() or '(see the sub-command description)'}")
    return rows


def cli_lines() -> list[str]:
    from spslidar.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    helps = {c.dest: c.help for c in sub._choices_actions}
    out = [f"The ``spslidar`` command has {len(sub.choices)} sub-commands: "
           + ", ".join(f":ref:`{name} <cli-{name}>`" for name in sub.choices) + ". "
           "Every option below is taken from the parser itself "
           "(``spslidar.cli.build_parser()``), so this page is ``spslidar <command> --help`` "
           "at the version of this site.", "",
           ".. code-block:: text", ""]
    out += ["   " + line for line in parser.format_usage().strip().splitlines()]
    out += ["", ".. list-table:: Sub-commands", "   :header-rows: 1", "   :widths: 20 80", "",
            "   * - command", "     - what it does"]
    for name in sub.choices:
        out += [f"   * - :ref:`spslidar {name} <cli-{name}>`",
                f"     - {_rst_escape(helps.get(name, ''))}"]
    out.append("")
    for name, p in sub.choices.items():
        out += [f".. _cli-{name}:", "", f"``spslidar {name}``",
                "-" * (len(name) + 13), "", _rst_escape(p.description or helps.get(name, "")), "",
                ".. code-block:: text", ""]
        usage = p.format_usage().strip()
        out += ["   " + line for line in textwrap.dedent(usage).splitlines()] + [""]
        for group in p._action_groups:
            actions = [a for a in group._group_actions
                       if not isinstance(a, argparse._HelpAction)]
            if not actions:
                continue
            title = {"positional arguments": "Arguments", "options": "Options",
                     "optional arguments": "Options"}.get(group.title, group.title.capitalize())
            out += [f".. list-table:: {title}", "   :header-rows: 1", "   :widths: 30 70",
                    "   :class: cli-options", "",
                    "   * - option", "     - meaning"]
            out += _action_rows(actions) + [""]
    return out


class CliDirective(_Generated):
    has_sections = True

    def render(self) -> list[str]:
        return cli_lines()


# -- the Config reference ------------------------------------------------------------------
def _field_docs() -> dict[str, str]:
    """The ``#:`` comments of :class:`Config`'s fields (as autodoc reads them)."""
    from sphinx.pycode import ModuleAnalyzer

    docs = ModuleAnalyzer.for_module("spslidar.config").find_attr_docs()
    return {name: " ".join(lines).strip() for (cls, name), lines in docs.items()
            if cls == "Config"}


def _run_actions() -> dict[str, argparse.Action]:
    from spslidar.cli import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    return {a.dest: a for a in sub.choices["run"]._actions}


def _type_name(tp) -> str:
    text = tp if isinstance(tp, str) else getattr(tp, "__name__", str(tp))
    return text.replace("typing.", "")


def config_rows(warn=None) -> list[tuple[str, ...]]:
    """(key, flag, type, unit, default, choices, meaning) of every config key."""
    from spslidar.config import Config, registries, stage_options

    docs = _field_docs()
    actions = _run_actions()
    regs = registries()
    rows = []
    for f in dataclasses.fields(Config):
        if f.name == "extra":
            continue
        text = docs.get(f.name, "")
        unit = ""
        m = re.match(r"\s*\[([^\]]*)\]\s*(.*)", text, re.S)
        if m:
            unit, text = m.group(1), m.group(2)
        action = actions.get(f.name)
        if not text and action is not None and action.help:
            text = _rst_escape(action.help)  # the comments are reST already, help is not
        if not text and warn is not None:
            warn(f"Config.{f.name} has no description: add a '#:' comment in config.py")
        choices = ""
        if f.name in regs:
            reg = regs[f.name]
            choices = "; ".join(f"``{n}``: {_rst_escape(reg.get(n).help or reg.get(n).display)}"
                                for n in reg.names())
        elif action is not None and action.choices:
            choices = ", ".join(_literal(c) for c in action.choices)
        default = f.default if f.default is not dataclasses.MISSING else "(empty)"
        flag = (", ".join(_literal(o) for o in action.option_strings)
                if action is not None else "(Python and TOML only)")
        rows.append((f"``{f.name}``", flag, _literal(_type_name(f.type)), _rst_escape(unit),
                     _literal(repr(default)), choices, text))
    for name, (reg, opt) in stage_options().items():
        owners = ", ".join(f"``{o}``" for o in reg.owners(name))
        text = _rst_escape(opt.help)
        if opt.why:
            text += f" Bounds: {_rst_escape(opt.why)}."
        text += f" Taken by ``{reg.option}`` {owners}."
        bounds = ""
        if opt.lo is not None or opt.hi is not None:
            lo = "-inf" if opt.lo is None else f"{opt.lo:g}"
            hi = "inf" if opt.hi is None else f"{opt.hi:g}"
            bounds = (f"{'(' if opt.lo_open or opt.lo is None else '['}{lo}, {hi}"
                      f"{')' if opt.hi_open or opt.hi is None else ']'}")
        choices = (", ".join(_literal(c) for c in opt.choices) if opt.choices
                   else "``on``, ``off``" if opt.kind is bool else _literal(bounds))
        rows.append((f"``{name}``", _literal(opt.flag), _literal(opt.kind.__name__),
                     _rst_escape(opt.unit), _literal(repr(opt.default)), choices, text))
    return rows


class ConfigDirective(_Generated):
    def render(self) -> list[str]:
        rows = config_rows(warn=lambda msg: logger.warning(msg, location=self.get_location()))
        out = [".. list-table::",
               "   :header-rows: 1", "   :widths: 22 22 56", "   :class: config-table",
               "", "   * - key and flag", "     - type, unit, default", "     - meaning"]
        for key, flag, kind, unit, default, choices, text in rows:
            out.append(f"   * - {key}")
            out += ["", f"       {flag}"]
            out.append(f"     - {kind}" + (f" in {unit}" if unit else ""))
            out += ["", f"       default {default}"]
            out.append(f"     - {text or '(no description)'}")
            if choices:
                out += ["", f"       *Choices:* {choices}"]
        return out + [""]


# -- metrics.json ----------------------------------------------------------------------------
def _thresholds() -> str:
    """Each registered depth estimator's default low-confidence threshold, from its class (a
    hand-written list went stale: ``guarded`` and ``evidence`` said 0.25, wrote 0.5)."""
    from spslidar.depth import ESTIMATORS

    return ", ".join(f"``{e.name}`` {e.load().LOW_CONFIDENCE:g}" for e in ESTIMATORS)


#: Description of every key of metrics.json (dotted for nested keys).
METRICS: dict[str, str] = {
    "depth_rmse_m": "Depth RMSE (eq. 19 of the paper, which calls it MSE) over the pixels with "
                    "a known truth and a detected return, metres; null without a truth.",
    "depth_mae_m": "Mean absolute depth error over the same pixels, metres.",
    "depth_bias_m": "Mean signed depth error (estimate minus truth), metres.",
    "depth_max_abs_error_m": "Largest absolute depth error, metres.",
    "depth_median_abs_error_m": "Median absolute depth error over the same pixels, metres.",
    "ignored_options": "The options set where the rest of the configuration gives them no "
                       "effect (``--fairness`` of a PSST lidar, ``--lam-scale`` beside "
                       "``--lam``...), each with the warning the run gave; ``config`` keeps "
                       "them as given.",
    "off_5cm_fraction": "Share of the same pixels whose depth is off by more than 5 cm (what "
                        "the depth benchmarks quote).",
    "depth_rmse_bins": "The RMSE in TDC bins (``bin_depth_m``).",
    "chance_rmse_m": "The RMSE of depths drawn at random, uniformly over the range gate (its "
                     "first unambiguous range where it is longer), on the pixels the RMSE is "
                     "over: about what a map of noise scores (a curve of RMSE against the "
                     "signal flattens here, set by the gate's width); null without a truth.",
    "n_valid": "Pixels with a known truth (``valid.npy``).",
    "missing_fraction": "Share of the valid pixels without a detected return (without a "
                        "ground truth: of all pixels).",
    "coverage": "Share of all pixels the RMSE is computed over: a known truth and a detected "
                "return (without a ground truth: a detected return).",
    "has_truth": "Whether the scene has a ground truth (false for a measured acquisition).",
    "scene_name": "The scene used, by its canonical name (a built-in's lower-case name, "
                  "``procedural:SEED`` with the seed as a plain integer, a file's name; a "
                  "measured acquisition's PTU file); ``config.scene`` keeps the spelling given.",
    "scene_note": "What the scene is, in words (``procedural:SEED``: its layout and depth "
                  "range, e.g. ``a clutter at 2.51-5.56 m``); null for the other scenes.",
    "edge_correlation": "Correlation of the Sobel edges of the estimate and of the truth "
                        "(the paper's Fig. 5 and 7).",
    "bin_depth_m": "Depth of one TDC bin, c / (2 x bit rate), metres (1.5 cm at 10 GHz).",
    "unambiguous_range_m": "Range covered by one code period (PSST) or one pulse period "
                           "(conventional), metres.",
    "range_gate_m": "The depths reconstructed, [min, max] metres, as asked for: the slices "
                    "are whole TDC bins, the gate's ends rounded outward, so a depth (with "
                    "``--subbin``) can lie up to about one bin (1.5 cm at 10 GHz) past it.",
    "n_slices": "Range slices (delays) in the gate.",
    "n_slices_solved": "Slices passed to the solver (fewer than ``n_slices`` with the "
                       "automatic gate).",
    "auto_gate": "Whether the automatic range gate dropped empty slices.",
    "n_patterns": "DMD patterns M.",
    "code_description": "The code, in words.",
    "code_period_bins": "Code (or pulse) period in TDC bins.",
    "code_ones": "'1' bits in one code period (laser pulses per period).",
    "n_periods": "Code periods accumulated per pattern (``periods``).",
    "acquisition_time_per_pattern_s": "Dwell time per DMD pattern, seconds.",
    "signal_per_pulse": "m_s, signal photons per pulse per pixel (mirror on, reflectivity 1).",
    "replica": "Matched-filter replica used: bipolar or unipolar.",
    "mean_signal_counts_per_pattern": "Mean signal counts per pattern over its dwell: the "
                                      "simulation's own (``run``); for a measured file "
                                      "(``reconstruct``) the returns inside the range gate, "
                                      "read off the correlations "
                                      "(:func:`spslidar.correlate.split_counts`).",
    "returns_outside_gate_fraction": "For a measured file (``reconstruct``), the share of "
                                     "its returns that lie outside the range gate, read over "
                                     "the code's whole period "
                                     "(:func:`spslidar.correlate.returns_outside`; a warning "
                                     "above 5 %); None for a simulation.",
    "mean_noise_counts_per_pattern": "Mean noise (background) counts per pattern over its "
                                     "dwell: the simulation's own; for a measured file the "
                                     "counts that are not signal in the gate.",
    "correlation_noise_sigma": "Standard deviation of the matched-filter output's noise "
                               "(with ``--noiseless``, what the same run with Poisson noise "
                               "would have).",
    "depth_estimator": "The depth estimator used.",
    "low_confidence_fraction": "Share of all pixels that have a depth of low confidence "
                               "(``confidence.npy`` below ``low_confidence_threshold``); a "
                               "pixel without a return has no depth, confidence 0, and is "
                               "not counted (it is in ``missing_fraction``).",
    "low_confidence_threshold": "The depth estimator's confidence below which a depth is "
                                "flagged low-confidence: " + _thresholds() + ".",
    "peak_to_noise_p90": "90th percentile over the pixels of each profile's peak over its "
                         "own largest noise peak beside it "
                         "(:func:`~spslidar.depth.profile.peak_to_noise`); null under 16 "
                         "slices, and where no pixel has a noise peak to compare with (a "
                         "``--noiseless`` run).",
    "peak_to_noise_floor": "The level below which at most a tenth of the pixels hold a "
                           "return and the run warns that the map is mostly noise: 1.4 "
                           "times what non-negative white noise gives at as many effective "
                           "slices (:func:`~spslidar.depth.profile.noise_only_ratio`); null "
                           "under 16 slices.",
    "two_surface_fraction": "Share of the pixels with a second surface (``depth2.npy``), "
                            "where the estimator looks for one; else null.",
    "mean_reflectivity": "Mean of ``reflectivity.npy`` over the pixels with a return.",
    "reflectivity_method": "How ``reflectivity.npy`` was read: ``refit`` (the return "
                           "strengths refitted with the depth held, :mod:`spslidar.refit`, "
                           "with its TV ``weight``, its ``iterations`` and the ``delays`` "
                           "its returns touch) or ``window`` (each profile summed over its "
                           "return's bins: a device's solve, a calibrated instrument, a "
                           "unipolar replica's plateau).",
    "depth_info": "What the depth estimator reports (iterations, smoothness, pixels changed "
                  "from the argmax...); the keys depend on the estimator.",
    "lam": "Regularisation weight used by the solver.",
    "lam_scale": "Its multiple of the noise level (``lam = lam_scale x noise_level``).",
    "lam_floored": "Whether ``lam`` was raised to its floor.",
    "noise_level": "Noise level that reaches the solver's prox, estimated from the "
                   "measurements (the weight is ``lam_scale`` times it, or the floor); with "
                   "``--noiseless``, the level the same run with Poisson noise would have: no "
                   "noise reaches the prox and the weight is the floor (``lam_floored``).",
    "solver_info": "What the solver reports: ``solver``, ``iterations``, ``final_objective``, "
                   "``stop_reason``, ``time_s`` and solver-specific keys.",
    "detector": "The detector model and its flux: ``model``, ``count_rate_hz``, and for a "
                "simulation ``counts_per_dead_time`` with ``gmapd_saturated`` and a ``note`` "
                "where a real GMAPD would saturate (the linear counter's); the GMAPD "
                "reports ``dead_fraction`` and ``incident_per_dead_time`` (the photons that "
                "reached it, the simulation's own) instead, and for the conventional lidar "
                "``incident_per_pulse`` and ``detections_per_pulse``; ``reconstruct`` (and a "
                "calibration file's ``detector``) writes ``model: measured``, the measured "
                "``count_rate_hz``, the ``dead_time_s`` given (``null``: none) and whether "
                "the histograms were ``corrected`` for it, and with a dead time the "
                "GMAPD's ``counts_per_dead_time``, ``dead_fraction`` and "
                "``incident_per_dead_time`` read from the counts, ``afterpulse_prob`` and "
                "``afterpulse_delay_s``.",
    "estimate": "The memory (GB) and time (s) estimated before a simulated run "
                "(``time_s_at_floor`` where the weight met its floor and the run was priced "
                "again with the floored iteration cap; ``time_s_reconstruct``, the solve "
                "and depth stage priced again, where ``spslidar.reconstruct`` changed a "
                "simulation's processing); empty for ``reconstruct``, whose file is priced "
                "as it is read.",
    "warnings": "The warnings printed on stderr.",
    "timing_s": "Wall-clock seconds by stage (scene, setup, simulate, qcr, solve, depth, "
                "reflectivity (the refit, where it ran), "
                "metrics, write); ``total`` is the run up to the metrics, the time the "
                "summary line prints, and leaves out ``write`` (the output folder), which is "
                "timed after it.",
    "config": "The validated configuration, every key resolved to the value used (``auto`` "
              "and unset keys replaced): ``run`` writes every key of "
              ":class:`~spslidar.Config`, ``reconstruct`` the processing keys and those its "
              "options measured (a simulation's scene, photons and patterns did not apply).",
    "seed": "The random seed.",
    "version": "spslidar version that wrote the file.",
    "plugins": "The plugins loaded in the process that wrote the file (``--plugin``, "
               "``SPSLIDAR_PLUGINS``), by module or path; empty without any.",
    "code_fingerprint": "A hash of spslidar's source and the plugins' "
                        "(``spslidar.plugins.code_fingerprint``): two files with the same "
                        "one were written by the same code.",
    "point_cloud": ("``points.ply``: file name, field of view (degrees), number of points "
                    "and of second-surface points among them, the per-point fields."),
    "ptu": "``reconstruct`` only: the PTU file read (a list of them, read in that order, "
           "where several were given: the counts are then summed over them), its photons "
           "(``n_photons``: all the files' photons read, every repeat, where ``--frame`` "
           "solves one; ``counts_per_pattern``: the photons solved) "
           "and code periods per pattern solved (``patterns_solved``: their rows of "
           "``--patterns``), the background, the blocks left out (``blocks_left_out``: a "
           "dropout or a stall, ``spslidar.pipeline.screen``; numbered through the repeats, "
           "block "
           "``r M + i`` showing pattern ``i``), ``repeats`` (``--repeats``: each pattern's "
           "blocks summed; ``frame``, ``--frame``: one repeat alone), ``first_pattern`` "
           "(``--first-pattern``: a free-running DMD, block ``b`` showing pattern "
           "``(first_pattern + b) mod M``, the number given or found; null when not given; "
           "``first_pattern_found``: true where ``auto`` found it from the data) with "
           "``blocks_per_pattern`` "
           "(the blocks kept of each pattern, summed, in ``--patterns`` order; null without "
           "``--first-pattern``), ``channel`` "
           "(``--channel``: the detector channels read; null for all, merged), ``settle_s`` "
           "and "
           "``n_dropped_settling`` (``--settle``), and ``timing_drift_bins`` (with "
           "``timing_drift_se_bins``): how much later the returns arrive at the last pattern "
           "than at the first, and ``timing_drift_span_bins``, how far apart the eight "
           "groups of patterns read (null with fewer than 64 patterns or no return to "
           "time), ``code_periods_per_sync`` (a sync divider folded) and ``sync_channel`` "
           "(``--sync-channel``: a T2 file's detector channel read as the sync; null for "
           "the file's own sync), and ``channels`` where several detector channels were read "
           "together: ``delays_bins``, each against the one with the most photons as the "
           "histograms show them, ``shifts_bins``, the whole bins each was moved by "
           "(``--align-channels``, or the calibration's), and ``rate_spread``, each "
           "channel's photon rate over the blocks against a constant rate's spread (about 1 "
           "for a laser monitor, which is given no delay); null for one channel; of "
           "several files, a list of each file's (each aligned by its own delays).",
    "inputs": "``reconstruct`` only: what the patterns and the code were read from: "
              "``patterns`` (``file`` as given, null for an array; ``pattern_size``, "
              "``--pattern-size``; ``n_patterns``, ``side``) and ``code`` (``file``; "
              "``family``, the name, length and index of a named code family such as "
              "``mseq``; ``bits``), each with the ``sha256`` of what was read (the patterns "
              "as float32 rows, the code one byte a bit), the same whatever the file's "
              "format, so that two results can be told to share their patterns and code. "
              "``CAL.json`` holds the same record as ``measured_from.inputs``.",
    "calibration": "``reconstruct`` only: the calibration applied (``--calibration``: its file "
                   "and SHA-256, delay, lag shift and fraction, IRF width, the filter's "
                   "``spread``, the factor on the default ``lam_scale``, how the depths were read "
                   "below a bin (``sub_bin``), the target's geometry "
                   "(``target``: one range or a flat wall's spread), the response's "
                   "``peak_to_noise`` and the calibration's warnings, ``same_code``: whether "
                   "the code bits were the calibration's), or null.",
}


def metrics_lines(warn) -> list[str]:
    import tempfile
    from pathlib import Path

    import spslidar

    r = spslidar.run(scene="camera", size=8, code_length=63, seed=0, depth="argmax",
                     iterations=5)
    with tempfile.TemporaryDirectory() as tmp:
        import json

        out = r.save(Path(tmp) / "out", figure=False)
        keys = list(json.loads((Path(out) / "metrics.json").read_text()))
    for k in keys:
        if k not in METRICS:
            warn(f"metrics.json key {k!r} has no description in docs/_ext/spslidar_docs.py")
    keys += [k for k in METRICS if k not in keys]
    out = [".. list-table:: The keys of ``metrics.json``", "   :header-rows: 1",
           "   :widths: 25 75", "", "   * - key", "     - meaning"]
    for k in keys:
        out += [f"   * - ``{k}``", f"     - {METRICS.get(k, '')}"]
    return out + [""]


class MetricsDirective(_Generated):
    def render(self) -> list[str]:
        return metrics_lines(lambda msg: logger.warning(msg, location=self.get_location()))


# -- short cross-references ------------------------------------------------------------------
def resolve_short_reference(app, env, node, contnode):
    """Resolve a Python reference written with a short name (``:func:`snr_simulated``` in a
    sibling module, ``:class:`Config```) to the documented object whose full name ends with
    it, preferring the one nearest the referring module; ``None`` (unresolved) when there is
    none. Docstrings name objects as their readers do, not by their defining module."""
    if node.get("refdomain") != "py":
        return None
    target = node.get("reftarget", "").lstrip("~.")
    if not target:
        return None
    domain = env.get_domain("py")
    matches = [name for name in domain.objects
               if name == target or name.endswith("." + target)]
    if not matches:
        return None
    here = (node.get("py:module") or "").split(".")

    def nearness(name: str) -> tuple[int, int]:
        parts = name.split(".")
        common = 0
        for a, b in zip(parts, here, strict=False):
            if a != b:
                break
            common += 1
        return (-common, len(parts))

    best = sorted(matches, key=nearness)[0]
    entry = domain.objects[best]
    from sphinx.util.nodes import make_refnode

    return make_refnode(app.builder, node["refdoc"], entry.docname, entry.node_id, contnode,
                        best)


def setup(app):
    app.connect("missing-reference", resolve_short_reference)
    app.add_directive("spslidar-cli", CliDirective)
    app.add_directive("spslidar-config", ConfigDirective)
    app.add_directive("spslidar-metrics", MetricsDirective)
    return {"parallel_read_safe": True, "parallel_write_safe": True, "version": "1"}
