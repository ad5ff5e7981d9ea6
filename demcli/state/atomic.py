"""Atomic file writes: write a temp file beside the target, fsync, then rename.

An interrupted or failing writer never leaves a half-written file under the final
name: either the old file is still there, or the new one is complete. The temp file
is ``.<name>.tmp-<pid>`` in the same folder (so ``os.replace`` stays on one
filesystem) and is removed on any exception, KeyboardInterrupt included.
"""

from __future__ import annotations

import contextlib
import os
from pathlib import Path

from demcli.errors import WriteError


def temp_path_for(path) -> Path:
    """The temp name used while ``path`` is being written."""
    path = Path(path)
    return path.with_name(f".{path.name}.tmp-{os.getpid()}")


def _fsync_path(path: Path, directory=False) -> None:
    flags = os.O_RDONLY | (getattr(os, "O_DIRECTORY", 0) if directory else 0)
    try:
        fd = os.open(path, flags)
    except OSError:
        if directory:  # some platforms cannot open folders; the rename is still atomic
            return
        raise
    try:
        os.fsync(fd)
    except OSError:
        if not directory:
            raise
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_path(path):
    """Yield a temp path to write; on normal exit it replaces ``path`` atomically.

    The parent folder is created if needed. If the body raises, the temp file is
    removed, ``path`` is left untouched, and the exception propagates; an OSError of the
    disk (full, read-only, forbidden) comes out as :class:`~demcli.errors.WriteError`
    naming ``path``::

        with atomic_path("out/state.h5") as tmp:
            write_something(tmp)
    """
    path = Path(path)
    tmp = temp_path_for(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        yield tmp
        if not tmp.exists():
            raise FileNotFoundError(f"atomic write of {path}: the writer created no file at {tmp}")
        _fsync_path(tmp)
        os.replace(tmp, path)
        _fsync_path(path.parent, directory=True)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            tmp.unlink()
        if WriteError.is_disk_error(exc):
            raise WriteError(path, exc) from None
        raise


def atomic_write_bytes(path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(data)
            fh.flush()


def atomic_write_text(path, text: str, encoding: str = "utf-8") -> None:
    """Write ``text`` to ``path`` atomically (newlines written as given)."""
    atomic_write_bytes(path, text.encode(encoding))
