"""Checkpoints: finished simulations persisted as they complete, so a killed run resumes.

A checkpoint is one SQLite file (write-ahead log, one transaction per finished chunk), robust to
the process being killed at any instant: a transaction is either wholly there or not at all. It
holds the run's settings, which a resumed run must match exactly, and one row per finished
simulation (phase, index, distance, status, reason, elapsed time). Parameter draws are not
stored: they are recomputed from the seed, which the checkpoint keeps.

Every row carries a checksum of its fields and of the run's seed (which fixes the row's
parameters and random stream), verified when the checkpoint is read: a damaged file or an
altered row stops the run with :class:`CheckpointDamagedError`, naming the file, rather than
change the result.

:class:`LikelihoodStore` is the same kind of file for SMC-ABC (:mod:`pymc_vcc.inference.pymc.smc`),
whose
simulations are not numbered in advance: each finished simulation is keyed by a digest of its
parameter vector and random stream, and holds its log-likelihood term (never the outputs).
:class:`ResultStore` holds a small vector of results per numbered simulation (the Sobol study's
output averages).
"""

from __future__ import annotations

import hashlib
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
    checksum TEXT NOT NULL,
    PRIMARY KEY (phase, idx)
);
"""


def describe_callable(obj: object) -> str:
    """``module.qualname`` of a simulator or distance (through ``functools.partial``), with its
    ``checkpoint_identity`` if it has one: what a checkpoint records of the code it ran."""
    target = getattr(obj, "func", obj)
    name = getattr(target, "__qualname__", type(target).__qualname__)
    described = f"{getattr(target, '__module__', '')}.{name}"
    identity = getattr(target, "checkpoint_identity", None)
    return f"{described} ({identity})" if identity else described


def array_digest(*arrays: np.ndarray) -> str:
    """SHA-256 of the arrays' bytes, in order."""
    digest = hashlib.sha256()
    for array in arrays:
        digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()


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


class CheckpointDamagedError(RuntimeError):
    """A checkpoint file that is not a readable checkpoint, or a row that fails its checksum."""


class ResultRecord(NamedTuple):
    """One finished simulation of a numbered set: its results (None if failed) and status."""

    index: int
    values: tuple[float, ...] | None
    status: str
    reason: str
    elapsed: float


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
    _table: ClassVar[str]
    _columns: ClassVar[str]  # the stored fields of a row, in order, without the checksum

    def __init__(
        self, path: str | Path, settings: Mapping[str, Any], entropy: int | None = None
    ) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        try:
            self._connection = sqlite3.connect(self.path)
            self._connection.execute("PRAGMA journal_mode=WAL")
            self._connection.execute("PRAGMA synchronous=NORMAL")
            self._connection.executescript(_META + self._schema)
            stored = dict(self._connection.execute("SELECT key, value FROM meta").fetchall())
        except sqlite3.DatabaseError as error:
            raise self._damaged(str(error)) from None
        wanted = json.loads(json.dumps(dict(settings)))
        if stored:
            try:
                saved_settings = json.loads(stored["settings"])
                saved_entropy = int(stored["entropy"])
            except (KeyError, ValueError) as error:
                self.close()
                raise self._damaged(f"its run settings are unreadable: {error}") from None
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

    def _damaged(self, detail: str) -> CheckpointDamagedError:
        return CheckpointDamagedError(
            f"checkpoint {self.path} is damaged ({detail}) and cannot be resumed; delete it to "
            "start afresh (pymc-vcc: run without --resume, or with a new --out)"
        )

    def _checksum(self, fields: tuple) -> str:
        """Digest of a row's stored fields and of the run's seed entropy."""
        text = json.dumps([str(self.entropy), *fields])
        return hashlib.blake2b(text.encode(), digest_size=16).hexdigest()

    def _insert(self, rows: list[tuple]) -> None:
        """Persist rows of stored fields, each with its checksum, in one transaction."""
        marks = ", ".join("?" * (len(self._columns.split(",")) + 1))
        with self._connection:
            self._connection.executemany(
                f"INSERT OR REPLACE INTO {self._table} VALUES ({marks})",
                [(*row, self._checksum(row)) for row in rows],
            )

    def _verified_rows(self) -> list[tuple]:
        """Every stored row (without its checksum), each checked against its checksum."""
        try:
            rows = self._connection.execute(
                f"SELECT {self._columns}, checksum FROM {self._table}"
            ).fetchall()
        except sqlite3.DatabaseError as error:
            raise self._damaged(str(error)) from None
        for *fields, checksum in rows:
            if self._checksum(tuple(fields)) != checksum:
                key = "/".join(map(str, fields[:-4]))  # the fields before the 4 of its result
                raise self._damaged(
                    f"the row of simulation {key} fails its checksum: altered or corrupted"
                )
        return [tuple(fields) for *fields, _ in rows]

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
    _table = "simulations"
    _columns = "phase, idx, distance, status, reason, elapsed"

    def load(self) -> list[SimulationRecord]:
        """Every finished simulation stored so far."""
        rows = self._verified_rows()
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
        self._insert(rows)


class LikelihoodStore(_CheckpointFile):
    """The checkpoint of an SMC-ABC run (:mod:`pymc_vcc.inference.pymc.smc`), by simulation key."""

    _schema = """
CREATE TABLE IF NOT EXISTS likelihoods (
    key TEXT PRIMARY KEY,
    loglik REAL,
    status TEXT NOT NULL,
    reason TEXT NOT NULL,
    elapsed REAL NOT NULL,
    checksum TEXT NOT NULL
);
"""
    _table = "likelihoods"
    _columns = "key, loglik, status, reason, elapsed"

    def load(self) -> dict[str, LikelihoodRecord]:
        """Every finished simulation stored so far, by key."""
        rows = self._verified_rows()
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
        self._insert(rows)


class ResultStore(_CheckpointFile):
    """The checkpoint of a set of numbered simulations that each give a few numbers."""

    _schema = """
CREATE TABLE IF NOT EXISTS results (
    idx INTEGER PRIMARY KEY,
    vals TEXT,
    status TEXT NOT NULL,
    reason TEXT NOT NULL,
    elapsed REAL NOT NULL,
    checksum TEXT NOT NULL
);
"""
    _table = "results"
    _columns = "idx, vals, status, reason, elapsed"

    def load(self) -> dict[int, ResultRecord]:
        """Every finished simulation stored so far, by index."""
        return {
            index: ResultRecord(index, None if values is None else tuple(json.loads(values)), *rest)
            for index, values, *rest in self._verified_rows()
        }

    def append(self, records: Iterable[ResultRecord]) -> None:
        """Persist finished simulations in one transaction."""
        self._insert(
            [
                (
                    int(r.index),
                    None if r.values is None else json.dumps([float(v) for v in r.values]),
                    r.status,
                    r.reason,
                    float(r.elapsed),
                )
                for r in records
            ]
        )
