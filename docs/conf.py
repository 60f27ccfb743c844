"""Sphinx configuration of the spslidar documentation site.

Build with warnings as errors (as ``.ci/run`` does)::

    python -m pip install -e ".[docs]"
    python -m sphinx -W --keep-going -b html docs docs/_build/html

The API reference is generated at build time from :data:`API_SECTIONS`: every module of the
installed ``spslidar`` package that exists when the site is built gets a page, placed in the
first section whose patterns match its name (modules that match none are listed under "Other
modules"). Adding a module to a section is one pattern in that section's list.
"""

from __future__ import annotations

import fnmatch
import os
import pkgutil
import re
import sys
from pathlib import Path

import spslidar

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE / "_ext"))  # spslidar_docs: the CLI, Config and metrics directives

# -- project --------------------------------------------------------------------------------
project = "spslidar"
author = "the spslidar authors"
copyright = "the spslidar authors, BSD-3-Clause"  # noqa: A001 - Sphinx's name
release = spslidar.__version__
version = ".".join(release.split(".")[:2])

# No intersphinx (its inventories are fetched over the network) and no viewcode (its "[docs]"
# back-links point to the objects' defining modules, which re-exports leave without anchors).
# MathJax is served by the site itself (sphinx-mathjax-offline copies it into _static/): the
# pages typeset their math offline, with no CDN.
extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx-mathjax-offline",
    "numpydoc",
    "myst_parser",
    "sphinx_design",
    "sphinx_gallery.gen_gallery",
    "matplotlib.sphinxext.plot_directive",
    "spslidar_docs",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
# only pages are sources: build output, the gallery's inputs, the reproduction run's own
# files (its report.md is the source of docs/reproduction.md, its section.md files are
# fragments of it) and the gallery's generated .ipynb/.py/.zip are not
exclude_patterns = [
    "_build",
    "_ext",
    "reproduction/**",
    "auto_examples/**/*.ipynb",
    "auto_examples/**/*.py",
    "auto_examples/**/*.zip",
    "auto_examples/**/*.md5",
    "auto_examples/**/*.json",
    "auto_examples/*.ipynb",
    "auto_examples/*.py",
    "auto_examples/*.zip",
    "auto_examples/*.md5",
    "auto_examples/*.json",
    "check_site.py",
    "sg_execution_times.rst",
    "**/sg_execution_times.rst",
    "**/.ipynb_checkpoints",
    "Thumbs.db",
    ".DS_Store",
]
templates_path: list[str] = []

# -- HTML -----------------------------------------------------------------------------------
html_theme = "pydata_sphinx_theme"
html_title = f"spslidar {release}"
html_short_title = "spslidar"
html_theme_options = {
    "logo": {"text": "spslidar"},
    "navbar_align": "left",
    "header_links_before_dropdown": 8,
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "secondary_sidebar_items": ["page-toc"],
    "footer_start": ["copyright"],
    "footer_end": ["sphinx-version"],
    "icon_links": [],
    "show_prev_next": True,
    "pygments_light_style": "default",
    "pygments_dark_style": "monokai",
}
# pages without sub-pages, and the architecture page whose diagrams need the full width
html_sidebars = {"index": [], "install": [], "getting_started": [], "reproduction": [],
                 "changelog": [], "architecture": []}
html_context = {"default_mode": "light"}
html_static_path = ["_static"]
html_css_files = ["spslidar.css"]
html_show_sourcelink = False
html_copy_source = False

# -- MyST (the Markdown pages) --------------------------------------------------------------
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist", "substitution"]
myst_substitutions = {"release": release}
myst_heading_anchors = 3
myst_dmath_double_inline = True

# -- cross-references: every one must resolve (nitpicky), except the names of other
# libraries' types in signatures (no intersphinx inventories offline)
nitpicky = True
nitpick_ignore_regex = [
    (r"py:.*", r"(np|numpy|scipy|torch|cupy|dask|matplotlib|pathlib|os|argparse|typing|"
               r"collections|concurrent|numbers|types|io|json|enum|dataclasses|tomllib|"
               r"threading|multiprocessing|joblib|ptufile|functools)(\..*)?"),
    (r"py:.*", r"(Path|PathLike|Any|Callable|Iterator|Iterable|Sequence|Mapping|"
               r"ArrayLike|NDArray|Figure|Axes|Self|Literal|Union|Optional|Namespace|"
               r"ArgumentParser|Executor|Future|Generator|TypeVar|Protocol|ModuleType)"),
    (r"py:.*", r"(int|float|str|bool|dict|list|tuple|set|object|type|bytes|callable|"
               r"None|optional|array|array-like|ndarray|path|default|or|of|shape|"
               r"iterable|sequence|mapping|datetime)"),
    (r"py:.*", r"(dict|tuple|list|set|type)\[.*"),
    # private helpers and undocumented internals that docstrings name for the code's readers
    # (left as code text, not links)
    (r"py:.*", r"(.*\.)?_[A-Za-z].*"),
    # module constants without documentation of their own, objects built at run time (the
    # registries) and helpers the package does not export: named in docstrings, not
    # documented, so left as code text
    (r"py:.*", r"(.*\.)?(ANNOUNCE_SECONDS|BAND_MIN_SIZE|MAX_TRIALS|POWER_CHUNK|WIENER_REG|"
               r"SOLVERS|REGULARISERS|CalibratedFilter(\.response)?|FistaInfo|"
               r"auto_truncation|estimate_seconds|lfsr_sequence|DepthEstimate\.depth2|"
               r"Solver\.solve)"),
    (r"py:.*", r"spslidar(\.\w+)*\.(\s.*)?"),  # a reference broken across two lines
]

# -- matplotlib's plot directive (the user guide's figures are drawn by the library) --------
plot_include_source = True
plot_html_show_source_link = False
plot_html_show_formats = False
plot_formats = [("png", 110)]
plot_rcparams = {"figure.autolayout": False}
plot_pre_code = "import numpy as np\nimport matplotlib.pyplot as plt\n"

# -- autodoc / numpydoc ---------------------------------------------------------------------
autodoc_default_options = {
    "members": True,
    "undoc-members": True,
    "show-inheritance": True,
}
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_preserve_defaults = True
autosummary_generate = False  # module pages are written by _write_api_pages() below
# autosummary's one-line summaries end at the first ". " that is not a known abbreviation: the
# docstrings cite the paper as "eq. (5)" and "Fig. 4", which must not end a summary
import sphinx.ext.autosummary as _autosummary  # noqa: E402

_autosummary.WELL_KNOWN_ABBREVIATIONS = (*_autosummary.WELL_KNOWN_ABBREVIATIONS, "eq.", "Eq.",
                                         "eqs.", "Fig.", "fig.", "cf.", "approx.", "no.")
numpydoc_show_class_members = False  # autodoc's :members: lists them once
numpydoc_class_members_toctree = False
numpydoc_attributes_as_param_list = False
numpydoc_xref_param_type = False


# -- sphinx-gallery -------------------------------------------------------------------------
os.environ.setdefault("MPLBACKEND", "Agg")
sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",
    "ignore_repr_types": r"matplotlib\.(text|axes|colorbar|image|lines|legend)",
    "ignore_pattern": r"__init__\.py",
    "backreferences_dir": "gen_modules/backreferences",
    "doc_module": ("spslidar",),
    "within_subsection_order": "FileNameSortKey",
    "nested_sections": True,
    "image_scrapers": ("matplotlib",),
    "remove_config_comments": True,
    "abort_on_example_error": False,
    "only_warn_on_example_error": False,
    "show_memory": False,
    "min_reported_time": 0,
    "download_all_examples": False,
    # the computation-time pages load jQuery and DataTables from CDNs: not on an offline site
    "write_computation_times": False,
    "plot_gallery": "True",
}

# -- API reference --------------------------------------------------------------------------
#: (page, title, introduction, module-name patterns), in the order of the physics chain.
#: A module goes to the first section with a matching pattern (fnmatch); a new module is
#: placed by adding its name (or a pattern) to one list.
API_SECTIONS: list[tuple[str, str, str, list[str]]] = [
    ("top", "Package, configuration and results",
     "The four entry points, ``spslidar.run(config) -> Result`` and its two halves "
     "``measure`` and ``reconstruct``, the :class:`~spslidar.config.Config` every run is made "
     "from (every key below, with its unit, default and choices) and the "
     ":class:`~spslidar.pipeline.results.Result` it returns.",
     ["spslidar", "spslidar.config", "spslidar.version", "spslidar.errors",
      "spslidar.constants", "spslidar.registry"]),
    ("scenes", "Scenes",
     "What the lidar looks at: built-in scenes, procedural scenes and your own depth maps.",
     ["spslidar.scenes", "spslidar.scenes.*", "spslidar.scene_cache", "spslidar.scene_build"]),
    ("codes", "Codes",
     "Temporal pseudo-random codes that gate the laser: m-sequences, Gold codes, "
     "Bernoulli bits and their periodic correlation.",
     ["spslidar.codes", "spslidar.codes.*"]),
    ("patterns", "Patterns",
     "Spatial DMD patterns (dense random and Hadamard) that sample the scene.",
     ["spslidar.patterns", "spslidar.patterns.*"]),
    ("operators", "Operators",
     "Linear operators: the pattern matrix, image-domain operators (gradient, wavelet), "
     "Hadamard transforms, adjoint tests.",
     ["spslidar.operators", "spslidar.operators.*"]),
    ("forward", "Forward model",
     "Expected photon counts per TDC bin (equation 4 of the paper).",
     ["spslidar.forward"]),
    ("detectors", "Detectors and the instrument",
     "Detector models (linear counting, the Geiger-mode APD with dead time and pile-up), time "
     "tags, and a real instrument's system delay and response (IRF).",
     ["spslidar.detector", "spslidar.detectors", "spslidar.detectors.*",
      "spslidar.instrument"]),
    ("correlate", "Correlation and QCR",
     "The matched filter (equations 5-6) and quadratic correlation reconstruction "
     "(equations 11-17).",
     ["spslidar.correlate", "spslidar.qcr"]),
    ("snr", "Output SNR",
     "The output SNR of one pattern's matched filter, equation (10), against its Monte-Carlo "
     "simulation (``spslidar snr``).",
     ["spslidar.snr", "spslidar.snr.*"]),
    ("solvers", "Solvers",
     "Sparse/TV reconstruction solvers (FISTA, TwIST, TVAL3, GPSR) and regularisers "
     "(equation 18).",
     ["spslidar.solvers", "spslidar.solvers.*"]),
    ("depth", "Depth estimators",
     "Depth from the reconstructed range slices: ML argmax (equations 2-3), censoring, "
     "guarded, MRF.",
     ["spslidar.depth", "spslidar.depth.*"]),
    ("metrics", "Metrics, products and figures",
     "Depth RMSE (equation 19), coverage, edges; the reflectivity image (refitted with the "
     "depth held) and point cloud; the library's figures.",
     ["spslidar.metrics", "spslidar.products", "spslidar.refit", "spslidar.figures"]),
    ("pipeline", "Pipeline",
     "One acquisition and reconstruction end to end, measured acquisitions (PTU) and "
     "calibration, and the result folder.",
     ["spslidar.pipeline", "spslidar.pipeline.*", "spslidar.outdir", "spslidar.outwrite",
      "spslidar.outfiles", "spslidar.machine", "spslidar.npyfile"]),
    ("backends", "Backends",
     "Where the numeric core runs (NumPy, array-API libraries, GPU).",
     ["spslidar.backends", "spslidar.backends.*"]),
    ("io", "Input and output",
     "Real time-tag data: PicoQuant PTU files read into per-pattern histograms, and written; "
     "another vendor's timestamps turned into T3 events; a lab's pattern and code files "
     "(images, TIFF, MATLAB, text).",
     ["spslidar.io", "spslidar.io.*"]),
    ("experiments", "Experiments",
     "Parameter sweeps and the reproduction of the paper's experiments.",
     ["spslidar.experiments", "spslidar.experiments.*"]),
    ("plugins", "Stages of your own",
     "A plugin's stages from the command line (``--plugin``), and the conformance checks "
     "every stage is held to (``spslidar check``, ``spslidar.testing.check_stage``).",
     ["spslidar.plugins", "spslidar.testing", "spslidar.testing.*"]),
    ("cli", "Command line",
     "The ``spslidar`` command; its options are listed in full in the :doc:`../cli`.",
     ["spslidar.cli", "spslidar.cli_*", "spslidar.interrupts"]),
]

#: Extra reST at the top of a section page (after its introduction).
SECTION_HEAD = {
    "top": """
Entry points
------------

.. autosummary::
   :nosignatures:

   spslidar.run
   spslidar.measure
   spslidar.reconstruct
   spslidar.config.Config
   spslidar.pipeline.results.Result

.. _config-keys:

Every configuration key
-----------------------

A :class:`~spslidar.config.Config` is made from keyword arguments, a dict, a TOML file
(:meth:`~spslidar.config.Config.from_toml`) or the options of ``spslidar run``: the same keys
everywhere (``code_length`` in Python and TOML, ``--code-length`` on the command line). This
table is generated from the declarations the command line is built from (the dataclass fields
and their ``#:`` comments in ``config.py``, the stage registries and the options each stage
declares), so it lists every key of this version.

.. spslidar-config::

.. _result-attributes:

What a run returns: ``Result``
------------------------------

:func:`spslidar.run` and :func:`spslidar.reconstruct` return a
:class:`~spslidar.pipeline.results.Result`. Its arrays are read-only views, so that what
``save()`` writes agrees with its metrics; ``result.depth.copy()`` gives one to edit:

.. list-table::
   :header-rows: 1
   :widths: 22 78

   * - attribute
     - meaning
   * - ``depth``
     - The estimated depth map, ``(N, N)`` metres; NaN where no return was detected.
   * - ``truth``
     - The ground-truth depth, ``(N, N)`` metres (all NaN for a measured acquisition).
   * - ``depth_rmse``
     - The depth RMSE of equation (19) in metres (``metrics["depth_rmse_m"]``); ``None``
       without a truth.
   * - ``reflectivity``
     - Per-pixel reflectivity read off the reconstruction: an estimate of alpha in [0, 1] for
       a simulation, detected photons per pulse for a measured acquisition; NaN without a
       return.
   * - ``confidence``, ``low_confidence``
     - Per-pixel confidence of the depth in [0, 1], and the mask of low-confidence pixels.
   * - ``depth2``
     - A second surface per pixel (metres; NaN where one surface), where the depth estimator
       looks for one (``guarded``), else ``None``.
   * - ``slices``
     - The reconstructed range slices, one image per gated delay: ``(K, N, N)``.
   * - ``lags``, ``corr``
     - The gated delays (TDC bins) and the matched-filter outputs ``(M, K)`` the solver used.
   * - ``metrics``
     - Everything ``metrics.json`` holds (:doc:`../outputs`).
   * - ``timing``
     - Wall-clock seconds by stage.
   * - ``warnings``
     - Warnings of the run (also printed by the command line).
   * - ``config``, ``scene``
     - The validated :class:`~spslidar.config.Config` and the scene that was measured.
   * - ``has_truth``
     - Whether the scene has a ground truth.
   * - ``summary()``, ``points()``, ``save()``
     - Two lines of text; the point cloud; the result folder (:doc:`../outputs`).
""",
}

API_DIR = HERE / "api"  # generated at build time (git-ignored)


def _discover(package: str = "spslidar") -> list[str]:
    """Names of the package's modules that exist now (files on disk, not imported)."""
    pkg = sys.modules[package] if package in sys.modules else __import__(package)
    names = [package]
    for info in pkgutil.walk_packages(pkg.__path__, prefix=package + "."):
        if any(part.startswith("_") for part in info.name.split(".")):
            continue
        names.append(info.name)
    return sorted(set(names))


def _underline(text: str, char: str) -> str:
    return f"{text}\n{char * len(text)}\n"


def _write(path: Path, text: str) -> None:
    """Write only when the text changed (Sphinx rebuilds by modification time)."""
    if not path.exists() or path.read_text() != text:
        path.write_text(text)


def _module_page(name: str) -> str:
    package = name == "spslidar" or (
        Path(spslidar.__file__).parent.joinpath(*name.split(".")[1:], "__init__.py").exists())
    # a package's __all__ re-exports its submodules' API, which their own pages document:
    # the package page holds only what the package itself defines
    options = "   :ignore-module-all:\n" if package else ""
    text = (f".. This page is generated by docs/conf.py at build time; do not edit.\n\n"
            f"{_underline(f'``{name}``', '=')}\n"
            f".. automodule:: {name}\n{options}")
    aliases = _reexports(name) if package else []
    if aliases:
        text += ("\n" + _underline("Re-exported names", "-") + "\n"
                 f"Importable from ``{name}``; each is documented in full in its own module.\n\n"
                 + "\n".join(aliases))
    used = _example_names(name)
    if used:  # the gallery examples that use this module's objects (sphinx-gallery backrefs)
        text += ("\n.. minigallery::\n   :add-heading: Examples using this module\n\n"
                 + "\n".join(f"   {u}" for u in used) + "\n")
    return text


def _example_names(name: str) -> list[str]:
    """Every name under which the gallery's backreferences may record this module's public
    objects: ``module.obj`` and ``package.obj`` for each package above it that re-exports it
    (sphinx-gallery records the shortest public path, e.g. ``spslidar.run``)."""
    import importlib

    try:
        module = importlib.import_module(name)
    except Exception:  # noqa: BLE001 - autodoc reports the failed import as a warning
        return []
    public = getattr(module, "__all__", None) or [a for a in vars(module) if a[0] != "_"]
    parts = name.split(".")
    parents = [importlib.import_module(".".join(parts[:i])) for i in range(1, len(parts))]
    names = []
    for attr in public:
        obj = getattr(module, attr, None)
        if getattr(obj, "__module__", None) != name:
            continue
        names.append(f"{name}.{attr}")
        for pkg in parents:
            try:
                if getattr(pkg, attr, None) is obj:
                    names.append(f"{pkg.__name__}.{attr}")
            except Exception:  # noqa: BLE001 - a lazy export that fails to import
                pass
    return names


def _reexports(name: str) -> list[str]:
    """Short entries for the functions and classes a package's ``__all__`` takes from its
    submodules, each linking to its full documentation. They make the public paths
    (``spslidar.run``, ``spslidar.codes.make_code``) link targets, for cross-references and
    for the gallery's code links."""
    import importlib
    import inspect

    try:
        module = importlib.import_module(name)
    except Exception:  # noqa: BLE001 - autodoc reports the failed import as a warning
        return []
    entries = []
    for attr in getattr(module, "__all__", ()):
        try:
            obj = getattr(module, attr)
        except Exception:  # noqa: BLE001 - a lazy export that fails to import is not listed
            continue
        home = getattr(obj, "__module__", None)
        qual = getattr(obj, "__qualname__", None)
        if not (home and qual and home != name and home.startswith("spslidar")):
            continue
        doc = (inspect.getdoc(obj) or "").strip().split("\n\n")[0].replace("\n", " ")
        if inspect.isclass(obj):
            head, role = f".. py:class:: {attr}", "class"
        elif callable(obj):
            try:
                sig = inspect.signature(obj)
                sig = sig.replace(parameters=[p.replace(annotation=inspect.Parameter.empty)
                                              for p in sig.parameters.values()],
                                  return_annotation=inspect.Signature.empty)
            except (TypeError, ValueError):
                sig = "(...)"
            head, role = f".. py:function:: {attr}{sig}", "func"
        else:
            continue
        entries.append(f"{head}\n   :module: {name}\n\n"
                       f"   Alias of :py:{role}:`{home}.{qual}`. {doc}\n")
    return entries


def _public_objects(name: str) -> list[str]:
    """The functions and classes a module defines and documents (its ``__all__`` when it has
    one), for the section page's summary table; a package's re-exports are listed under the
    module that defines them."""
    import importlib
    import inspect

    try:
        module = importlib.import_module(name)
    except Exception:  # noqa: BLE001 - autodoc reports the failed import as a warning
        return []
    names = getattr(module, "__all__", None) or [a for a in vars(module) if a[0] != "_"]
    out = []
    for attr in names:
        try:
            obj = getattr(module, attr)
        except Exception:  # noqa: BLE001 - a lazy export that fails to import
            continue
        if not (inspect.isclass(obj) or inspect.isfunction(obj)):
            continue
        doc = inspect.getdoc(obj)
        if getattr(obj, "__module__", None) != name or not doc:
            continue
        # autosummary cuts the summary at the first ". ": skip (from the table only) an
        # object whose first sentence would be cut inside an inline literal
        first = re.split(r"\.\s", doc.split("\n\n")[0], maxsplit=1)[0]
        if first.count("``") % 2:
            continue
        out.append(attr)
    return out


def _write_api_pages() -> None:
    modules = _discover()
    placed: dict[str, list[str]] = {key: [] for key, *_ in API_SECTIONS}
    other: list[str] = []
    for name in modules:
        for key, _title, _intro, patterns in API_SECTIONS:
            if any(fnmatch.fnmatchcase(name, p) for p in patterns):
                placed[key].append(name)
                break
        else:
            other.append(name)
    sections = [(key, title, intro, placed[key]) for key, title, intro, _ in API_SECTIONS]
    if other:
        sections.append(("other", "Other modules",
                         "Modules not yet placed in a section of ``API_SECTIONS`` "
                         "(docs/conf.py).", other))
    API_DIR.mkdir(parents=True, exist_ok=True)
    index = [".. This page is generated by docs/conf.py at build time; do not edit.\n",
             _underline("API reference", "="),
             "The modules follow the physics chain of the lidar, from the laser's code to the "
             "depth map. Each section's page has a table of its modules and of their public "
             "functions and classes; each module's page documents them in full from their "
             "(numpydoc) docstrings. Start with :doc:`top`: ``run``, ``Config`` (every key) "
             "and ``Result``.\n",
             ".. list-table::\n   :header-rows: 1\n   :widths: 25 75\n",
             "   * - section\n     - what it holds"]
    index += [f"   * - :doc:`{key}`\n     - {intro}" for key, _t, intro, mods in sections
              if mods]
    index += ["", ".. toctree::\n   :hidden:\n   :maxdepth: 2\n"]
    index += [f"   {key}" for key, *_, mods in sections if mods]
    _write(API_DIR / "index.rst", "\n".join(index) + "\n")
    wanted = {"index.rst"}
    for key, title, intro, mods in sections:
        if not mods:
            continue
        lines = [".. This page is generated by docs/conf.py at build time; do not edit.\n",
                 _underline(title, "="), intro + "\n", SECTION_HEAD.get(key, "")]
        lines += [_underline("Modules", "-"), ".. autosummary::\n   :nosignatures:\n"]
        lines += [f"   {m}" for m in mods]
        lines.append("")
        for m in mods:
            objs = _public_objects(m)
            if not objs:
                continue
            lines += [_underline(f":mod:`{m}`", "-"), ".. autosummary::\n   :nosignatures:\n"]
            lines += [f"   {m}.{o}" for o in objs]
            lines.append("")
        lines += ["", ".. toctree::\n   :hidden:\n"]
        lines += [f"   {m}" for m in mods]
        _write(API_DIR / f"{key}.rst", "\n".join(lines) + "\n")
        wanted.add(f"{key}.rst")
        for m in mods:
            _write(API_DIR / f"{m}.rst", _module_page(m))
            wanted.add(f"{m}.rst")
    for stale in API_DIR.glob("*.rst"):  # modules removed since the last build
        if stale.name not in wanted:
            stale.unlink()


_write_api_pages()
