"""On-disk cache of built property tables: one ``.npz`` file per fluid, resolution and CoolProp.

Several processes may build the same tables at once; each writes a private temporary file and
renames it into place (``os.replace`` is atomic), so a reader sees either no file or a whole one.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
import zipfile
from dataclasses import astuple
from importlib.metadata import version
from pathlib import Path
from typing import Any

import numpy as np

from pymc_vcc.physics.refrigerant.tables import FluidSpec, PropertyTables, TableResolution

CACHE_ENV = "PYMC_VCC_CACHE"
"""Environment variable naming the cache directory (default ``~/.cache/pymc_vcc``)."""

TABLE_FORMAT = 1
"""Version of the table layout and construction; bump it when either changes."""


def cache_directory(explicit: str | os.PathLike[str] | None = None) -> Path:
    """The cache directory: ``explicit``, else ``$PYMC_VCC_CACHE``, else ``~/.cache/pymc_vcc``."""
    if explicit is not None:
        return Path(explicit)
    from_env = os.environ.get(CACHE_ENV)
    if from_env:
        return Path(from_env)
    return Path.home() / ".cache" / "pymc_vcc"


def cache_path(directory: Path, spec: FluidSpec, resolution: TableResolution) -> Path:
    """The cache file of ``spec`` at ``resolution`` built with the installed CoolProp."""
    coolprop = version("coolprop")
    key = repr((astuple(spec), astuple(resolution), TABLE_FORMAT, coolprop))
    digest = hashlib.sha256(key.encode()).hexdigest()[:12]
    sizes = f"{resolution.n_sat}-{resolution.n_p}-{resolution.n_liquid}-{resolution.n_vapour}"
    return directory / f"{spec.name}_{sizes}_CoolProp-{coolprop}_{digest}.npz"


def save_tables(path: Path, tables: PropertyTables) -> None:
    """Write ``tables`` to ``path`` atomically (a temporary file beside it, then a rename)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temporary = tempfile.mkstemp(dir=path.parent, prefix=path.stem, suffix=".tmp")
    try:
        with os.fdopen(handle, "wb") as file:
            np.savez(file, **tables._asdict())
        os.chmod(temporary, 0o644)
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise


def load_tables(path: Path) -> PropertyTables | None:
    """The tables stored at ``path``, or None if there is no readable, complete file."""
    try:
        with np.load(path, allow_pickle=False) as data:
            fields = {name: data[name] for name in PropertyTables._fields}
    except (FileNotFoundError, KeyError, ValueError, OSError, zipfile.BadZipFile):
        return None
    values: dict[str, Any] = {
        name: float(value) if value.ndim == 0 else np.ascontiguousarray(value, dtype=np.float64)
        for name, value in fields.items()
    }
    return PropertyTables(**values)
