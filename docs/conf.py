"""Sphinx configuration of leoc's documentation site.

Build: ``sphinx-build -W --keep-going -b html docs docs/_build/html`` (README). Warnings are errors:
a broken cross-reference (nitpicky mode) or a public name without a docstring fails the build.
No step needs the network. Environment variables:

- ``LEOC_DOCS_GALLERY=0`` skips running the gallery scripts (their pages keep the code only);
- ``LEOC_DOCS_MATHJAX``: a local MathJax to use instead of the CDN (offline viewing), e.g.
  ``file:///usr/share/javascript/mathjax/MathJax.js?config=TeX-AMS_CHTML`` (Debian's
  libjs-mathjax).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS / "_ext"))
sys.path.insert(0, str(DOCS / "examples"))

import leoc_api  # noqa: E402 - docs/_ext, just put on the path

project = "leoc"
author = "the leoc authors"
copyright = "2026, the leoc authors"  # noqa: A001 - Sphinx's name
try:
    from importlib.metadata import version as _version

    release = _version("leoc")
except Exception:  # noqa: BLE001 - the site also builds from a source tree not installed
    release = "0.1.0"

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
    "leoc_api",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = ["_build", "examples", "gallery/README.txt", "**/GALLERY_HEADER.rst"]
root_doc = "index"

# --- strictness ----------------------------------------------------------------------------------
nitpicky = True
# Names outside leoc: no inventory is fetched (the build needs no network), so references to
# Python, NumPy, torch, gymnasium, SB3, ... are left as text instead of failing.
EXTERNAL_PREFIXES = (
    "torch",
    "numpy",
    "np",
    "scipy",
    "gymnasium",
    "gym",
    "stable_baselines3",
    "sb3",
    "matplotlib",
    "ray",
    "control",
    "pathlib",
    "collections",
    "typing",
    "types",
    "dataclasses",
    "enum",
    "abc",
    "concurrent",
    "argparse",
    "json",
    "os",
    "io",
    "random",
    "multiprocessing",
    "tqdm",
    "optimizer",
)
BUILTIN_NAMES = (
    "int|float|str|bool|bytes|complex|list|tuple|dict|set|frozenset|object|type|None|"
    "Any|Callable|Iterable|Iterator|Mapping|MutableMapping|Sequence|Literal|Optional|Union|"
    "ClassVar|NamedTuple|TypeVar|Generator|Path|PathLike|Exception|ValueError|TypeError|"
    "RuntimeError|KeyError|OSError|FileNotFoundError|ArithmeticError|callable|optional|"
    "array_like|array-like|default|Tensor|ndarray|Module|Figure|Axes|Env|Generic|Self|Protocol|"
    "Future|SupportsFloat|TextIO|Enum|function|iterable|sequence|mapping"
)
nitpick_ignore_regex = [
    # private names (a base class shown by show-inheritance, a helper named in a docstring)
    ("py:.*", r"leoc(\..*)?\._.*|_.*"),
    ("py:.*", rf"({'|'.join(EXTERNAL_PREFIXES)})(\..*)?"),
    ("py:.*", rf"({BUILTIN_NAMES})"),
    # pieces of a builtin generic where Sphinx cannot parse a dataclass signature as a whole
    ("py:.*", r"(tuple|dict|list|set|frozenset|type)\[.*"),
]

# --- API reference -------------------------------------------------------------------------------
leoc_api_packages = list(leoc_api.PUBLIC_PACKAGES)  # the packages of the library
# referenced from the packages' docstrings; documented, not held to the docstring check
leoc_api_extra_modules = [
    "leoc.learners",
    "leoc.names",
    "leoc.training",
    "leoc.linalg",
    "leoc.io",
    "leoc.gym_adapter",
]
autodoc_default_options = {"member-order": "bysource"}
autodoc_typehints = "signature"
autodoc_inherit_docstrings = True
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False
numpydoc_validation_checks: set[str] = set()

# --- markdown ------------------------------------------------------------------------------------
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist"]
myst_heading_anchors = 3

# --- gallery -------------------------------------------------------------------------------------
RUN_GALLERY = os.environ.get("LEOC_DOCS_GALLERY", "1") != "0"
sphinx_gallery_conf = {
    "examples_dirs": "gallery",
    "gallery_dirs": "auto_examples",
    "filename_pattern": r"/plot_" if RUN_GALLERY else r"^$",
    "plot_gallery": RUN_GALLERY,
    "download_all_examples": False,
    "remove_config_comments": True,
    "within_subsection_order": "FileNameSortKey",
    "matplotlib_animations": False,
    "show_memory": False,
    "min_reported_time": 1,
}

# --- HTML ----------------------------------------------------------------------------------------
html_theme = "furo"
html_title = f"leoc {release}"
html_static_path: list[str] = []
if os.environ.get("LEOC_DOCS_MATHJAX"):
    mathjax_path = os.environ["LEOC_DOCS_MATHJAX"]
    # MyST marks its pages tex2jax_ignore and re-enables math by class; MathJax 2 (Debian's)
    # needs that said in its own configuration, MathJax 3 (the CDN default) reads Sphinx's.
    mathjax2_config = {
        "tex2jax": {"processClass": "tex2jax_process|mathjax_process|math|output_area"}
    }
