"""Checkpoints: finished simulations persisted as they complete, so a killed run resumes.

A checkpoint is one SQLite file (write-ahead log, one transaction per finished chunk), robust to
the process being killed at any instant: a transaction is either wholly there or not at all. It
holds the run's settings, which a resumed run must match exactly, and one row per finished
simulation (phase, index, distance, status, reason, elapsed time). Parameter draws are not
stored: they are recomputed from the seed, which the checkpoint keeps.

:class:`LikelihoodStore` is the same kind of file for SMC-ABC (:mod:`pymc_vcc.inference.pymc.smc`),
whose
simulations are not numbered in advance: each finished simulation is keyed by a digest of its
parameter vector and random stream, and holds its log-likelihood term (never the outputs).
"""

from __future__ import annotations

import json
import sqlite3
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any, ClassVar, NamedTuple, Self

import numpy as np

_META = "CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL);"
_SCHEMA = """
CREATE TABLE IF NOT EXISTS simulations (
    phase INTEGER NOT NULL,
    idx INTEGER NOT NULL,
    distance REAL,
    status TEXT NOT NULL,
    reason TEXT NOT NULL,
    elapsed REAL NOT NULL,
    PRIMARY KEY (phase, idx)
);
"""


class SimulationRecord(NamedTuple):
    """One finished simulation: where it belongs, its distance (NaN if failed) and status."""

    phase: int
    index: int
    distance: float
    status: str
    reason: str
    elapsed: float


class CheckpointMismatchError(ValueError):
    """A checkpoint written by a run with other settings than the one resuming it."""


class LikelihoodRecord(NamedTuple):
    """One finished SMC simulation: its key, log-likelihood term (NaN if failed) and status."""

    key: str
    loglik: float
    status: str
    reason: str
    elapsed: float


class _CheckpointFile:
    """An open checkpoint file whose stored run settings must match the run opening it.

    Args:
        path: the SQLite file (created with its parent folder if missing).
        settings: JSON-able description of the run; must equal the stored one when resuming.
        entropy: the run's seed entropy, or None to take the stored one (or draw a fresh one
            for a new checkpoint).
    """

    _schema: ClassVar[str]

    def __init__(
        self, path: str | Path, settings: Mapping[str, Any], entropy: int | None = None
    ) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._connection = sqlite3.connect(self.path)
        self._connection.execute("PRAGMA journal_mode=WAL")
        self._connection.execute("PRAGMA synchronous=NORMAL")
        self._connection.executescript(_META + self._schema)
        stored = dict(self._connection.execute("SELECT key, value FROM meta").fetchall())
        wanted = json.loads(json.dumps(dict(settings)))
        if stored:
            saved_settings = json.loads(stored["settings"])
            saved_entropy = int(stored["entropy"])
            if saved_settings != wanted or (entropy is not None and entropy != saved_entropy):
                self.close()
                differing = self._differences(saved_settings, wanted, saved_entropy, entropy)
                raise CheckpointMismatchError(
                    f"checkpoint {self.path} belongs to a run with other arguments "
                    f"(differing: {differing}); use the same arguments to resume, or another "
                    "checkpoint path"
                )
            self.entropy = saved_entropy
        else:
            self.entropy = np.random.SeedSequence().entropy if entropy is None else int(entropy)
            with self._connection:
                self._connection.executemany(
                    "INSERT INTO meta VALUES (?, ?)",
                    [("settings", json.dumps(wanted)), ("entropy", str(self.entropy))],
                )

    @staticmethod
    def _differences(
        saved: dict, wanted: dict, saved_entropy: int, entropy: int | None
    ) -> list[str]:
        keys = sorted(
            key for key in saved.keys() | wanted.keys() if saved.get(key) != wanted.get(key)
        )
        if entropy is not None and entropy != saved_entropy:
            keys.append("seed")
        return keys

    def close(self) -> None:
        """Close the file."""
        self._connection.close()

    def __enter__(self) -> Self:
        return self

    def __exit__(self, *exc_info: object) -> None:
        self.close()


class SimulationStore(_CheckpointFile):
    """The checkpoint of an ABC rejection run (:mod:`pymc_vcc.inference.rejection`), by phase and
    draw index."""

    _schema = _SCHEMA

    def load(self) -> list[SimulationRecord]:
        """Every finished simulation stored so far."""
        rows = self._connection.execute(
            "SELECT phase, idx, distance, status, reason, elapsed FROM simulations"
        ).fetchall()
        return [
            SimulationRecord(phase, index, np.nan if distance is None else distance, *rest)
            for phase, index, distance, *rest in rows
        ]

    def append(self, records: Iterable[SimulationRecord]) -> None:
        """Persist finished simulations in one transaction."""
        rows = [
            (
                int(r.phase),
                int(r.index),
                float(r.distance) if np.isfinite(r.distance) else None,
                r.status,
                r.reason,
                float(r.elapsed),
            )
            for r in records
        ]
        with self._connection:
            self._connection.executemany(
                "INSERT OR REPLACE INTO simulations VALUES (?, ?, ?, ?, ?, ?)", rows
            )


class LikelihoodStore(_CheckpointFile):
    """The checkpoint of an SMC-ABC run (:mod:`pymc_vcc.inference.pymc.smc`), by simulation key."""

    _schema = """
CREATE TABLE IF NOT EXISTS likelihoods (
    key TEXT PRIMARY KEY,
    loglik REAL,
    status TEXT NOT NULL,
    reason TEXT NOT NULL,
    elapsed REAL NOT NULL
);
"""

    def load(self) -> dict[str, LikelihoodRecord]:
        """Every finished simulation stored so far, by key."""
        rows = self._connection.execute(
            "SELECT key, loglik, status, reason, elapsed FROM likelihoods"
        ).fetchall()
        return {
            key: LikelihoodRecord(key, np.nan if loglik is None else loglik, *rest)
            for key, loglik, *rest in rows
        }

    def append(self, records: Iterable[LikelihoodRecord]) -> None:
        """Persist finished simulations in one transaction."""
        rows = [
            (
                r.key,
                None if np.isnan(r.loglik) else float(r.loglik),
                r.status,
                r.reason,
                float(r.elapsed),
            )
            for r in records
        ]
        with self._connection:
            self._connection.executemany(
                "INSERT OR REPLACE INTO likelihoods VALUES (?, ?, ?, ?, ?)", rows
            )
