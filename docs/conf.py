"""Sphinx configuration of the pymc_vcc documentation (``make docs`` builds it into site/).

The build is strict (``-W --keep-going -n``): every warning fails it. Besides Sphinx's own
(a broken link between pages, a cross-reference that resolves to nothing, malformed reST in a
docstring), this file warns when a name of ``pymc_vcc.__all__`` has no API entry, no docstring
or a parameter its docstring does not describe (``_apicheck.py``). The notebooks are shown with
the outputs stored in ``docs/notebooks/`` (``scripts/render_notebooks.py``), never executed here.
"""

from __future__ import annotations

import importlib
import sys
from pathlib import Path

from sphinx.ext.napoleon.docstring import GoogleDocstring
from sphinx.util import logging

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

import _apicheck  # noqa: E402

import pymc_vcc  # noqa: E402

project = "pymc_vcc"
author = "the pymc_vcc developers"
copyright = "the pymc_vcc developers"
release = version = pymc_vcc.__version__

extensions = [
    "myst_nb",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
]
source_suffix = {".md": "myst-nb", ".ipynb": "myst-nb", ".rst": "restructuredtext"}
exclude_patterns = ["_build", "**/.ipynb_checkpoints", "results/runs"]
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


def _attribute_docstring_as_written(self) -> list[str]:
    """An attribute's or constant's docstring as it is written: napoleon would read a first
    line with a colon ("Inputs a controller sets in steps: resampled ...") as ``type: text``."""
    return self.__class__(self._dedent(self._consume_to_end()), self._config).lines()


GoogleDocstring._parse_attribute_docstring = _attribute_docstring_as_written

_NOTHING = object()


def _record(app, what, name, obj, options, lines) -> None:
    """Note the entry, per page: an incremental build reads only the pages that changed."""
    documented = app.env.__dict__.setdefault("pymc_vcc_documented", {})
    documented.setdefault(app.env.docname, set()).add(name)


def _forget(app, env, docname) -> None:
    env.__dict__.setdefault("pymc_vcc_documented", {}).pop(docname, None)


def _resolve(dotted: str) -> object:
    """The object a dotted ``pymc_vcc`` path names, or ``_NOTHING``."""
    module, _, attribute = dotted.rpartition(".")
    while module:
        try:
            value: object = importlib.import_module(dotted)
        except ImportError:
            pass
        else:
            return value
        try:
            value = importlib.import_module(module)
        except ImportError:
            module, _, parent = module.rpartition(".")
            attribute = f"{parent}.{attribute}"
            continue
        for part in attribute.split("."):
            value = getattr(value, part, _NOTHING)
            if value is _NOTHING:
                return _NOTHING
        return value
    return _NOTHING


def _missing_reference(app, env, node, contnode):
    """A reference Sphinx did not resolve by its own rules, resolved as Python would.

    In a docstring of ``pymc_vcc.inference.pymc.model``, ``:class:`UniformPrior``` names the
    class that module imports: it links to that class's entry. A reference to an object that
    exists but has no entry of its own (a private helper, a module constant) is shown as code.
    A reference to nothing (a typo, a renamed object) is left to fail the build.
    """
    if node.get("refdomain") != "py":
        return None
    target = node["reftarget"].lstrip(".~")
    module, klass = node.get("py:module"), node.get("py:class")
    candidates = [target]
    if module:
        candidates[:0] = [f"{module}.{klass}.{target}"] if klass else []
        candidates.insert(len(candidates) - 1, f"{module}.{target}")
    domain = env.get_domain("py")
    for dotted in candidates:
        if not dotted.startswith("pymc_vcc"):
            continue
        obj = _resolve(dotted)
        if obj is _NOTHING:
            continue
        canonical = (
            f"{obj.__module__}.{obj.__qualname__}"
            if hasattr(obj, "__qualname__") and hasattr(obj, "__module__")
            else getattr(obj, "__name__", None)
        )
        for name in (canonical, dotted):
            if name and name in domain.objects:
                return domain.resolve_xref(
                    env, node["refdoc"], app.builder, "obj", name, node, contnode
                )
        return contnode
    return None


def _check_public_api(app, env) -> None:
    """Warn for every public name without an API entry, a docstring or a parameter description."""
    log = logging.getLogger("pymc_vcc.apicheck")
    documented = env.__dict__.get("pymc_vcc_documented", {})
    entries: dict[str, list[str]] = {}
    for names in documented.values():
        for dotted in names:
            entries.setdefault(dotted.rpartition(".")[2], []).append(dotted)
    for name in pymc_vcc.__all__:
        if name == "__version__":
            continue
        obj = getattr(pymc_vcc, name)
        if not any(_resolve(dotted) is obj for dotted in entries.get(name, [])):
            log.warning("public name %s has no entry in the API reference", name)
        for problem in _apicheck.problems(name, obj):
            log.warning("public API: %s", problem)


def _images_inside_the_build(app) -> None:
    """myst-nb writes notebook images to ``<outdir>/../jupyter_execute``, which for
    ``site/`` is the repository itself: keep them beside the doctrees instead."""
    config = getattr(app.env, "mystnb_config", None)
    if config is not None:
        folder = Path(app.doctreedir).joinpath("jupyter_execute").resolve()
        app.env.mystnb_config = config.copy(output_folder=str(folder))


def setup(app):
    app.connect("builder-inited", _images_inside_the_build, priority=900)
    app.connect("autodoc-process-docstring", _record)
    app.connect("env-purge-doc", _forget)
    app.connect("env-check-consistency", _check_public_api)
    app.connect("missing-reference", _missing_reference)
    return {"parallel_read_safe": False}
