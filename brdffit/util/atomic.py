"""Atomic file writes (bytes, text, JSON, figures): a temporary file in the target's folder,
fsync, then ``os.replace``.

A reader never sees a half-written file, and an interrupted write leaves the old
file (or none) in place.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import tempfile
from pathlib import Path

import numpy as np


def _default_mode() -> int:
    umask = os.umask(0o022)
    os.umask(umask)
    return 0o666 & ~umask


def _fsync_folder(folder: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(folder, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def write_atomic(path: str | os.PathLike[str], chunks: list[bytes | np.ndarray]) -> None:
    """Write ``chunks`` (bytes or contiguous arrays) to ``path`` atomically.

    Raises ``OSError`` when the folder is not writable; the target is then untouched.
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    tmp = None
    try:
        mode = path.stat().st_mode & 0o777 if path.is_file() else _default_mode()
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
        with os.fdopen(fd, "wb") as f:
            for chunk in chunks:
                f.write(chunk if isinstance(chunk, bytes) else memoryview(chunk).cast("B"))
            f.flush()
            os.fchmod(f.fileno(), mode)
            os.fsync(f.fileno())
        os.replace(tmp, path)
        tmp = None
        _fsync_folder(folder)
    finally:
        if tmp is not None:
            with contextlib.suppress(OSError):
                os.unlink(tmp)


def write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write UTF-8 ``text`` to ``path`` atomically."""
    write_atomic(path, [text.encode("utf-8")])


def save_figure(fig: object, path: str | os.PathLike[str], **kwargs: object) -> None:
    """Save a matplotlib figure atomically (format from the suffix)."""
    buf = io.BytesIO()
    fmt = Path(path).suffix.lstrip(".") or "png"
    fig.savefig(buf, format=fmt, **kwargs)
    write_atomic(path, [buf.getvalue()])


def remove_temporaries(folder: str | os.PathLike[str]) -> None:
    """Delete, below ``folder``, the temporary files a killed :func:`write_atomic` left."""
    for p in Path(folder).rglob(".*.tmp"):
        p.unlink(missing_ok=True)


def write_json(path: str | Path, payload: dict) -> None:
    """Write ``payload`` as indented JSON to ``path`` atomically, making its folder."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_text(path, json.dumps(payload, indent=1))


def has_key(path: str | Path, key: str) -> bool:
    """True when ``path`` is a JSON object file that parses and holds ``key``."""
    try:
        d = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return False
    return isinstance(d, dict) and key in d
