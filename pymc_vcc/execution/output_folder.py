"""The output folder of a run: one run at a time, writable, and files that are whole or absent.

:func:`claim_output_folder` takes an exclusive lock on a folder for the life of a run: a lock
file ``.pymc-vcc.lock`` holding the owner's pid, host and start time, locked with ``flock`` so
that the operating system releases it when its process dies, however it dies. A second run on
the same folder is refused at once, naming the run that holds it; a lock file left by a run
that died is taken over with a message. Creating the lock file also proves, before any
simulation, that the folder is writable. A folder the claim created is removed again if the run
wrote no file into it (it stopped at a bad option or input): a failed command leaves nothing.

:func:`atomic_path` gives a temporary name in the destination's folder and renames it over the
destination only once the file is complete, so a kill while writing never leaves a truncated
file where a good one stood.
"""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import socket
import sys
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import UTC, datetime
from pathlib import Path

LOCK_NAME = ".pymc-vcc.lock"

_HELD: dict[Path, int] = {}  # folders this process holds, with how many claims are open


class OutputFolderError(RuntimeError):
    """The output folder cannot be used: it is not writable, or another run holds it."""


def _owner_text(owner: dict) -> str:
    return (
        f"pid {owner.get('pid', '?')} on {owner.get('host', '?')}, "
        f"started {owner.get('started', '?')}"
    )


def _read_owner(handle) -> dict:
    handle.seek(0)
    try:
        return json.loads(handle.read() or "{}")
    except json.JSONDecodeError:
        return {}


@contextmanager
def claim_output_folder(folder: str | Path) -> Iterator[Path]:
    """Hold ``folder`` (created if missing, removed again if the run wrote no file into it)
    for this run; reentrant within a process.

    Raises:
        OutputFolderError: the folder cannot be created or written, or another live run holds it.
    """
    folder = Path(folder).resolve()
    if folder in _HELD:
        _HELD[folder] += 1
        try:
            yield folder
        finally:
            _HELD[folder] -= 1
        return
    created = [path for path in (folder, *folder.parents) if not path.exists()]
    try:
        folder.mkdir(parents=True, exist_ok=True)
        handle = open(folder / LOCK_NAME, "a+")  # noqa: SIM115 -- held open for the whole run
    except OSError as error:
        raise OutputFolderError(
            f"output folder {folder} is not writable ({error.strerror or error}); "
            "choose another --out"
        ) from None
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            owner = _owner_text(_read_owner(handle))
            raise OutputFolderError(
                f"output folder {folder} is in use by another run ({owner}); "
                "wait for it to finish, or choose another --out"
            ) from None
        stale = _read_owner(handle)
        if stale:
            print(
                f"taking over output folder {folder} from a run that is no longer running "
                f"({_owner_text(stale)})",
                file=sys.stderr,
            )
        owner = {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "started": datetime.now(UTC).isoformat(timespec="seconds"),
            "command": " ".join(sys.argv),
        }
        handle.seek(0)
        handle.truncate()
        handle.write(json.dumps(owner) + "\n")
        handle.flush()
        _HELD[folder] = 1
        try:
            yield folder
        finally:
            del _HELD[folder]
            handle.seek(0)
            handle.truncate()  # empty, not removed: a waiting opener must not lock a stale inode
            handle.flush()
            if created and _holds_no_file(folder):  # made by this run, and left unused
                shutil.rmtree(folder)
                for path in created[1:]:  # the parents it made, while nothing else is in them
                    if any(path.iterdir()):
                        break
                    path.rmdir()
    finally:
        handle.close()  # releases the flock


def _holds_no_file(folder: Path) -> bool:
    """Whether ``folder`` holds no file but its lock (empty folders aside)."""
    files = (path for path in folder.rglob("*") if not path.is_dir())
    return all(path == folder / LOCK_NAME for path in files)


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """A temporary path beside ``path`` (same suffix) that replaces ``path`` on success.

    Write the file to the yielded path; when the block ends without an exception it is renamed
    over ``path`` in one step, else removed.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    partial = path.with_name(f".{path.stem}.{uuid.uuid4().hex[:8]}.partial{path.suffix}")
    try:
        yield partial
        os.replace(partial, path)
    finally:
        partial.unlink(missing_ok=True)
