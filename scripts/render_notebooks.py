"""Execute the tutorials in ``notebooks/`` and store them, with outputs, in ``docs/notebooks/``.

The notebooks in ``notebooks/`` are committed without outputs (``tests/test_notebooks.py``
executes them). The documentation shows these executed copies instead of running the
notebooks while it builds; ``tests/test_docs.py`` checks that their code is the tutorials'
code, so a changed tutorial asks for this script to be run again:

    .venv/bin/python scripts/render_notebooks.py                 # every notebook, smoke budget
    .venv/bin/python scripts/render_notebooks.py 04_leak_detection --budget small

Each copy records the budget and the commit it was executed at in its metadata
(``pymc_vcc_render``), which the rendered page shows.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import tempfile
import time
from pathlib import Path

import nbformat
from nbclient import NotebookClient

ROOT = Path(__file__).resolve().parents[1]
SOURCE = ROOT / "notebooks"
TARGET = ROOT / "docs" / "notebooks"


def _commit() -> str:
    result = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True
    )
    return result.stdout.strip() or "unknown"


def render(path: Path, budget: str, timeout: float) -> Path:
    """Execute notebook ``path`` at ``budget`` and write it, outputs included, to docs/."""
    notebook = nbformat.read(path, as_version=4)
    os.environ["PYMC_VCC_BUDGET"] = budget
    os.environ["MPLBACKEND"] = "module://matplotlib_inline.backend_inline"
    started = time.perf_counter()
    with tempfile.TemporaryDirectory() as scratch:
        client = NotebookClient(
            notebook,
            timeout=timeout,
            kernel_name="python3",
            resources={"metadata": {"path": scratch}},
        )
        client.execute()
    seconds = time.perf_counter() - started
    notebook.metadata["pymc_vcc_render"] = {
        "budget": budget,
        "commit": _commit(),
        "seconds": round(seconds),
    }
    TARGET.mkdir(parents=True, exist_ok=True)
    out = TARGET / path.name
    nbformat.write(notebook, out)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("names", nargs="*", help="notebook stems (default: all)")
    parser.add_argument("--budget", default="smoke", choices=["smoke", "small", "paper"])
    parser.add_argument("--timeout", type=float, default=1800.0, help="seconds per cell")
    args = parser.parse_args()
    paths = sorted(SOURCE.glob("*.ipynb"))
    if args.names:
        paths = [path for path in paths if path.stem in args.names]
        if not paths:
            parser.error(f"no notebook named {args.names} in {SOURCE}")
    for path in paths:
        out = render(path, args.budget, args.timeout)
        print(f"{out.relative_to(ROOT)}: executed at budget {args.budget}")


if __name__ == "__main__":
    main()
