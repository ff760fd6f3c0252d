"""The documentation: a strict build, every public name documented, the README a user guide."""

from __future__ import annotations

import importlib
import re
import subprocess
import sys
from pathlib import Path

import nbformat
import pytest

import pymc_vcc

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
sys.path.insert(0, str(DOCS))

import _apicheck  # noqa: E402

PUBLIC = sorted(set(pymc_vcc.__all__) - {"__version__"})


def test_the_site_builds_in_strict_mode(tmp_path):
    """What ``make docs`` runs: any warning (a broken link, a reference to nothing, a public
    name without docstring or API entry) fails it."""
    build = subprocess.run(
        [
            sys.executable,
            "-m",
            "sphinx",
            "-W",
            "--keep-going",
            "-n",
            "-q",
            "-b",
            "html",
            "-d",
            str(tmp_path / "doctrees"),
            str(DOCS),
            str(tmp_path / "site"),
        ],
        capture_output=True,
        text=True,
        cwd=ROOT,
    )
    assert build.returncode == 0, build.stderr[-5000:]
    assert "WARNING" not in build.stderr and "ERROR" not in build.stderr, build.stderr[-5000:]
    site = tmp_path / "site"
    for page in [
        "index.html",
        "getting-started.html",
        "api/units.html",
        "guide/methods.html",
        "results/leak.html",
        *(f"notebooks/{path.stem}.html" for path in sorted((ROOT / "notebooks").glob("*.ipynb"))),
    ]:
        assert (site / page).is_file(), page
    api = "".join(path.read_text() for path in (site / "api").glob("*.html"))
    entries = {_resolve(anchor) for anchor in re.findall(r'id="(pymc_vcc\.[\w.]+)"', api)}
    assert [name for name in PUBLIC if id(getattr(pymc_vcc, name)) not in entries] == []


def _resolve(dotted: str) -> int:
    """id() of the object a documented dotted path names (0 if none)."""
    module, _, name = dotted.rpartition(".")
    try:
        return id(getattr(importlib.import_module(module), name))
    except (ImportError, AttributeError):
        return 0


@pytest.mark.parametrize("name", PUBLIC)
def test_every_public_name_has_a_docstring_describing_its_parameters(name):
    assert list(_apicheck.problems(name, getattr(pymc_vcc, name))) == []


def test_the_check_finds_a_missing_docstring_or_parameter():
    def documented(path, dt):
        """Load it.

        Parameters
        ----------
        path
            The file.
        dt
            Grid spacing, s.
        """

    def google(path, dt):
        """Load it.

        Args:
            path: the file.
            dt: grid spacing, s.
        """

    def undocumented(path):
        return path

    def half(path, dt):
        """Load it.

        Args:
            path: the file.
        """

    assert list(_apicheck.problems("documented", documented)) == []
    assert list(_apicheck.problems("google", google)) == []
    assert list(_apicheck.problems("undocumented", undocumented)) == ["undocumented: no docstring"]
    assert "['dt']" in next(iter(_apicheck.problems("half", half)))


def test_every_public_name_has_an_api_entry():
    entries = set()
    for page in (DOCS / "api").glob("*.rst"):
        entries |= set(re.findall(r"^\.\. auto\w+:: (\S+)", page.read_text(), re.MULTILINE))
    listed = {_resolve(dotted) for dotted in entries}
    missing = [name for name in PUBLIC if id(getattr(pymc_vcc, name)) not in listed]
    assert missing == []


@pytest.mark.parametrize(
    "path", sorted((ROOT / "notebooks").glob("*.ipynb")), ids=lambda path: path.stem
)
def test_the_rendered_notebooks_are_the_tutorials_with_outputs(path):
    """docs/notebooks/ holds the tutorials executed (scripts/render_notebooks.py): the same
    cells, with outputs. A changed tutorial fails here until it is rendered again."""
    source = nbformat.read(path, as_version=4)
    rendered = nbformat.read(DOCS / "notebooks" / path.name, as_version=4)
    assert [(c.cell_type, c.source) for c in rendered.cells] == [
        (c.cell_type, c.source) for c in source.cells
    ], f"run: .venv/bin/python scripts/render_notebooks.py {path.stem}"
    code = [cell for cell in rendered.cells if cell.cell_type == "code"]
    assert all(cell.execution_count for cell in code)
    assert not [o for c in code for o in c.outputs if o.output_type == "error"]
    assert rendered.metadata["pymc_vcc_render"]["budget"] in ("smoke", "small", "paper")


def test_the_readme_is_a_short_user_guide_starting_with_the_two_commands():
    lines = (ROOT / "README.md").read_text().splitlines()
    assert len(lines) <= 200
    commands = [line for line in lines[:10] if line.startswith("make ")]
    assert [line.split("#")[0].strip() for line in commands] == ["make demo", "make test"]
    makefile = (ROOT / "Makefile").read_text()
    for target in ("demo", "test", "docs"):
        assert re.search(rf"^{target}:", makefile, re.MULTILINE), target


def test_the_readme_links_point_at_files_that_exist():
    text = (ROOT / "README.md").read_text()
    links = re.findall(r"\]\(((?!https?://|#)[^)\s]+)\)", text)
    assert links
    for link in links:
        assert (ROOT / link.split("#")[0]).exists(), link
