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
import sys
from pathlib import Path

import spslidar

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent

# -- project --------------------------------------------------------------------------------
project = "spslidar"
author = "the spslidar authors"
copyright = "the spslidar authors, BSD-3-Clause"  # noqa: A001 - Sphinx's name
release = spslidar.__version__
version = ".".join(release.split(".")[:2])

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "sphinx.ext.intersphinx",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
# only pages are sources: build output, the gallery's inputs, the reproduction run's own
# files (its report.md is the source of docs/reproduction.md, its section.md files are
# fragments of it) and the gallery's generated .ipynb/.py/.zip are not
exclude_patterns = [
    "_build",
    "reproduction/**",
    "auto_examples/*.ipynb",
    "auto_examples/*.py",
    "auto_examples/*.zip",
    "auto_examples/*.md5",
    "auto_examples/*.json",
    "**/.ipynb_checkpoints",
    "Thumbs.db",
    ".DS_Store",
]
templates_path: list[str] = []

# -- HTML -----------------------------------------------------------------------------------
html_theme = "alabaster"
html_title = f"spslidar {release}"
html_theme_options = {
    "description": "Single-pixel photon-counting spread-spectrum ToF lidar: simulate and "
                   "reconstruct",
    "fixed_sidebar": True,
    "page_width": "1100px",
    "sidebar_width": "240px",
}
html_static_path: list[str] = []
html_show_sourcelink = False

# -- MyST (the Markdown pages) --------------------------------------------------------------
myst_enable_extensions = ["dollarmath", "amsmath"]
myst_heading_anchors = 3

# -- autodoc / numpydoc ---------------------------------------------------------------------
autodoc_default_options = {
    "members": True,
    "show-inheritance": True,
}
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_preserve_defaults = True
autosummary_generate = False  # module pages are written by _write_api_pages() below
numpydoc_show_class_members = False  # autodoc's :members: lists them once
numpydoc_class_members_toctree = False
numpydoc_attributes_as_param_list = False
numpydoc_xref_param_type = False

intersphinx_mapping: dict[str, tuple[str, None]] = {}  # no network at build time

# -- sphinx-gallery -------------------------------------------------------------------------
os.environ.setdefault("MPLBACKEND", "Agg")
sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples"),
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_",
    "ignore_pattern": r"__init__\.py",
    "backreferences_dir": "gen_modules/backreferences",
    "doc_module": ("spslidar",),
    "reference_url": {"spslidar": None},
    "within_subsection_order": "FileNameSortKey",
    "image_scrapers": ("matplotlib",),
    "remove_config_comments": True,
    "abort_on_example_error": False,
    "only_warn_on_example_error": False,
    "show_memory": False,
    "min_reported_time": 0,
    "download_all_examples": False,
    "plot_gallery": "True",
}

# -- API reference --------------------------------------------------------------------------
#: (page, title, introduction, module-name patterns), in the order of the physics chain.
#: A module goes to the first section with a matching pattern (fnmatch); a new module is
#: placed by adding its name (or a pattern) to one list.
API_SECTIONS: list[tuple[str, str, str, list[str]]] = [
    ("top", "Package and scenes",
     "The top-level entry points (``spslidar.run``, ``measure``, ``reconstruct``, "
     "``Config``) and the scenes the lidar looks at.",
     ["spslidar", "spslidar.scenes", "spslidar.constants", "spslidar.errors",
      "spslidar.registry"]),
    ("codes", "Codes",
     "Temporal pseudo-random codes that modulate the laser: m-sequences, Gold codes, "
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
     "Expected photon counts per TDC bin (eq. 4 of the paper).",
     ["spslidar.forward"]),
    ("detectors", "Detectors",
     "Detector models: noise terms, photon counting, dead time and pile-up, time tags.",
     ["spslidar.detector", "spslidar.detectors", "spslidar.detectors.*"]),
    ("correlate", "Correlation and QCR",
     "The matched filter (eq. 5-6) and quadratic correlation reconstruction (eq. 11-17).",
     ["spslidar.correlate", "spslidar.qcr", "spslidar.snr"]),
    ("solvers", "Solvers",
     "Sparse/TV reconstruction solvers (FISTA, TwIST, TVAL3, GPSR) and regularisers.",
     ["spslidar.solvers", "spslidar.solvers.*"]),
    ("depth", "Depth estimators",
     "Depth from the reconstructed range slices: ML argmax (eq. 2-3), censoring, MRF.",
     ["spslidar.depth", "spslidar.depth.*"]),
    ("metrics", "Metrics and figures",
     "Depth RMSE (eq. 19), coverage, edges, and the library's figures.",
     ["spslidar.metrics", "spslidar.figures"]),
    ("pipeline", "Pipeline",
     "One acquisition and reconstruction end to end: ``run(config) -> Result``.",
     ["spslidar.pipeline", "spslidar.pipeline.*", "spslidar.outdir"]),
    ("backends", "Backends",
     "Where the numeric core runs (NumPy, array-API libraries, GPU).",
     ["spslidar.backends", "spslidar.backends.*"]),
    ("io", "Input and output",
     "Real time-tag data: PicoQuant PTU files read into per-pattern histograms.",
     ["spslidar.io", "spslidar.io.*"]),
    ("experiments", "Experiments",
     "Parameter sweeps and the reproduction of the paper's experiments.",
     ["spslidar.experiments", "spslidar.experiments.*"]),
    ("config", "Configuration and command line",
     "The run configuration (the same keys on the command line and in TOML files) and the "
     "``spslidar`` command.",
     ["spslidar.config", "spslidar.cli"]),
]

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
             "depth map. Each section lists its modules; each module's page documents its "
             "public functions and classes from their (numpydoc) docstrings.\n",
             ".. toctree::\n   :maxdepth: 2\n"]
    index += [f"   {key}" for key, *_, mods in sections if mods]
    _write(API_DIR / "index.rst", "\n".join(index) + "\n")
    wanted = {"index.rst"}
    for key, title, intro, mods in sections:
        if not mods:
            continue
        lines = [".. This page is generated by docs/conf.py at build time; do not edit.\n",
                 _underline(title, "="), intro + "\n",
                 ".. autosummary::\n"]
        lines += [f"   {m}" for m in mods]
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
