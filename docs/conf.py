"""Sphinx configuration of the pymc_vcc documentation (``make docs`` builds it into site/).

The build is strict (``-W --keep-going -n``): every warning fails it. Besides Sphinx's own
(a broken link between pages, a cross-reference that resolves to nothing, malformed reST in a
docstring), this file warns when a name of ``pymc_vcc.__all__`` has no API entry, no docstring
or a parameter its docstring does not describe (``_apicheck.py``). The notebooks are shown with
the outputs stored in ``docs/notebooks/`` (``scripts/render_notebooks.py``), never executed here.
"""

from __future__ import annotations

import sys
from pathlib import Path

from sphinx.util import logging

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

import _apicheck  # noqa: E402

import pymc_vcc  # noqa: E402

project = "pymc_vcc"
author = "the pymc_vcc developers"
copyright = "the pymc_vcc developers"  # noqa: A001
release = version = pymc_vcc.__version__

extensions = [
    "myst_nb",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
]
source_suffix = {".md": "myst-nb", ".ipynb": "myst-nb", ".rst": "restructuredtext"}
exclude_patterns = ["_build", "**/.ipynb_checkpoints"]
templates_path: list[str] = []

# Notebooks: the stored outputs, nothing executed.
nb_execution_mode = "off"
nb_merge_streams = True
myst_enable_extensions = ["colon_fence", "dollarmath", "deflist"]
myst_heading_anchors = 3

# API reference: Google- and numpy-style sections, type hints in the signatures.
autodoc_member_order = "bysource"
autodoc_typehints = "signature"
autodoc_preserve_defaults = True
autodoc_class_signature = "separated"
autodoc_default_options = {"members": True, "show-inheritance": False}
napoleon_use_rtype = False
napoleon_attr_annotations = True

# Every cross-reference must resolve. No inventory of other projects is fetched (the build
# is offline), so references into these libraries are left as text.
nitpicky = True
_EXTERNAL = (
    "numpy|np|xarray|xr|pandas|pd|pathlib|collections|typing|typing_extensions|enum|abc|os"
    "|concurrent|multiprocessing|datetime|types|numbers|pymc|pm|pytensor|arviz|az|scipy|dask"
    "|distributed|sklearn|matplotlib|pint|numba|rich|builtins|dataclasses|random|io"
    "|contextlib|threading|sqlite3|logging"
)
nitpick_ignore_regex = [
    (r"py:.*", rf"(?:{_EXTERNAL})(?:\..*)?"),
    # builtins and typing names as they appear in signatures
    (r"py:.*", r"(?:int|float|str|bool|bytes|dict|list|tuple|set|object|None|type|callable)"),
    (
        r"py:.*",
        r"(?:Any|Callable|Iterable|Iterator|Mapping|Sequence|Literal|Self|ClassVar|Path"
        r"|ArrayLike|NDArray|DataTree|Dataset|DataArray|Model|Generator|Protocol|TypeVar|T)",
    ),
]

html_theme = "pydata_sphinx_theme"
html_title = "pymc_vcc"
html_theme_options = {
    "navigation_with_keys": False,
    "show_toc_level": 2,
    "secondary_sidebar_items": ["page-toc"],
}
html_static_path: list[str] = []
html_show_sourcelink = False
html_copy_source = False

_documented: set[str] = set()


def _record(app, what, name, obj, options, lines) -> None:  # noqa: ARG001
    _documented.add(name)


def _check_public_api(app, env) -> None:  # noqa: ARG001
    """Warn for every public name without an API entry, a docstring or a parameter description."""
    log = logging.getLogger("pymc_vcc.apicheck")
    for name in pymc_vcc.__all__:
        if name == "__version__":
            continue
        module = pymc_vcc._MODULE_OF[name]
        full = f"{module}.{name}"
        if full not in _documented:
            log.warning("public name %s has no entry in the API reference (%s)", name, full)
        for problem in _apicheck.problems(name, getattr(pymc_vcc, name), module):
            log.warning("public API: %s", problem)


def setup(app):
    app.connect("autodoc-process-docstring", _record)
    app.connect("env-check-consistency", _check_public_api)
    return {"parallel_read_safe": False}
