"""Atomic file output: nothing a user made is left half-written, and others can read it.

Files are written to a temporary file beside the target and renamed into place, with the
permissions an ordinary ``open()`` would give (0666 less the process umask), not the 0600 of
:func:`tempfile.mkstemp`. JSON is strict: NaN and infinities become ``null``.
"""

from __future__ import annotations

import json
import os
import stat
import tempfile
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def file_mode() -> int:
    """The permissions an ordinary ``open()`` gives a new file: 0666 less the process umask."""
    return 0o666 & ~_umask()


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Writes data to a temporary file beside ``path`` and renames it into place.

    A symbolic link is kept and the file it names is written (renaming onto the link would
    replace the link itself); a device, FIFO or socket is refused, never replaced. A file
    replaced keeps its permissions, and a read-only one is refused (a fuzz trial's 0444 model
    was replaced and a 0600 one became 0644); a new one gets :func:`file_mode`.

    Raises:
        ValueError: ``path`` is a directory, not a regular file or read-only, or its folder
            cannot be created or written.
    """
    given = Path(path)
    path = Path(os.path.realpath(given)) if given.is_symlink() else given
    if path.is_dir():
        raise ValueError(f"{given} is a directory; give a file name")
    if path.exists() and not path.is_file():
        raise ValueError(
            f"{given} is not a regular file (a device, FIFO or socket); give a file name"
        )
    mode = file_mode()
    if path.is_file():
        mode = stat.S_IMODE(path.stat().st_mode)
        if not mode & stat.S_IWUSR:
            raise ValueError(f"{given} is read-only: give another file name, or make it "
                             "writable to replace it")  # fmt: skip
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    except OSError as exc:
        raise ValueError(f"cannot write {given}: {exc.strerror}") from None
    try:
        os.fchmod(fd, mode)
        with os.fdopen(fd, "wb") as handle:
            handle.write(data)
            handle.flush()
            os.fsync(handle.fileno())
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return given


def atomic_write_text(path: str | Path, text: str) -> Path:
    """Atomic text write (UTF-8)."""
    return atomic_write_bytes(path, text.encode("utf-8"))


def jsonable(obj: Any) -> Any:
    """``obj`` with numpy scalars and arrays as Python values and NaN or inf as None."""
    if isinstance(obj, dict):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [jsonable(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return jsonable(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not np.isfinite(obj):
        return None
    return obj


def write_json(path: str | Path, obj: Any) -> Path:
    """Atomic, indented, strict JSON write (NaN and infinities are written as null)."""
    text = json.dumps(jsonable(obj), indent=2, sort_keys=False, allow_nan=False)
    return atomic_write_text(path, text + "\n")


def write_csv(path: str | Path, header: Sequence[str], rows: np.ndarray) -> Path:
    """Atomic CSV write with a header line and full float precision."""
    lines = [",".join(header)]
    lines += [",".join(f"{v:.17g}" for v in row) for row in np.asarray(rows, dtype=np.float64)]
    return atomic_write_text(path, "\n".join(lines) + "\n")
