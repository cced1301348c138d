"""The lock of a sweep folder: one sweep at a time may run in it (:func:`sweep_lock`).

A running sweep holds ``<folder>/.sweep.lock`` (:data:`LOCK`), naming its process and
host; a lock left by a dead process on this host, or an empty one older than
:data:`STALE_EMPTY_S`, is stale and taken over.
"""

from __future__ import annotations

import contextlib
import os
import socket
import time
from collections.abc import Iterator
from pathlib import Path

from brdffit.errors import SweepError

LOCK = ".sweep.lock"
"""The lock file a running sweep holds in its folder: ``<pid> <host>``."""
STALE_EMPTY_S = 10.0
"""An empty or garbled lock file older than this is a crash between its creation and
its first write: stale."""


def _pid_alive(pid: int) -> bool:
    """True when a process ``pid`` exists on this machine (signal 0 probes it)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # exists, owned by another user
        return True
    except (OSError, OverflowError):
        return False
    return True


def _lock_holder(path: Path) -> str | None:
    """Who holds the lock at ``path`` (``"process <pid> on <host>"``), or ``None`` when the
    lock is stale: its process is dead on this host, or the file is empty or garbled and
    older than :data:`STALE_EMPTY_S`."""
    try:
        text, age = path.read_text(), time.time() - path.stat().st_mtime
    except OSError:
        return None  # gone meanwhile
    fields = text.split()
    if not fields or not fields[0].isdigit():
        return None if age > STALE_EMPTY_S else "a sweep that is starting"
    pid, host = int(fields[0]), fields[1] if len(fields) > 1 else socket.gethostname()
    if host == socket.gethostname():
        return f"process {pid}" if _pid_alive(pid) else None
    return f"process {pid} on {host}"  # another machine's process: cannot be probed


@contextlib.contextmanager
def sweep_lock(out: str | os.PathLike[str]) -> Iterator[Path]:
    """Hold the lock of sweep folder ``out`` (:data:`LOCK`) while the block runs.

    Two sweeps in one folder would both fit every task; the second raises
    :class:`SweepError` naming the process that holds the folder. A lock left by a dead
    process (a kill, a crash) is taken over. The lock file is removed on leaving.
    """
    path = Path(out) / LOCK
    for _ in range(3):  # a stale lock is removed, then the creation is tried again
        try:
            fd = os.open(path, os.O_CREAT | os.O_EXCL | os.O_WRONLY, 0o644)
        except FileExistsError:
            holder = _lock_holder(path)
            if holder is not None:
                raise SweepError(
                    f"{out}: another sweep is running in this folder ({holder}; lock file "
                    f"{path}); wait for it, or delete the lock file if that sweep is gone"
                ) from None
            path.unlink(missing_ok=True)
            continue
        with os.fdopen(fd, "w") as f:
            f.write(f"{os.getpid()} {socket.gethostname()}\n")
        break
    else:
        raise SweepError(f"{out}: cannot take the lock file {path}; another sweep keeps taking it")
    try:
        yield path
    finally:
        path.unlink(missing_ok=True)
