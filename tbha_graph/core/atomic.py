"""Atomic file writes: the one implementation every writer in the project uses.

A file is written completely to a hidden temporary file in the destination folder, flushed to disk
(``fsync``) and renamed onto its destination (``os.replace``: atomic on one file system). A reader
therefore sees the old file or the whole new one, never a part; a failure leaves the destination as
it was and removes the temporary file.

* :func:`atomic_write_bytes` / :func:`atomic_write_text`: data already in memory.
* :func:`atomic_path`: a context manager yielding the temporary path, for writers that want a path
  (``np.savez``, ``Figure.savefig``, ``cv2.VideoWriter``); the body may also check the written file
  before it is committed (raise to abandon it).
* :func:`temp_path` / :func:`commit`: the two halves, for writers whose life is not one ``with`` block
  (a streaming video writer).
"""
from __future__ import annotations

import os
import uuid
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator


def temp_path(path: str | Path) -> Path:
    """A unique hidden temporary path beside ``path`` that keeps its suffix last (``.x.mp4`` ->
    ``..x.tmp-PID-HEX.mp4``: OpenCV, numpy and matplotlib choose the format from the suffix)."""
    path = Path(path)
    return path.with_name(f".{path.stem}.tmp-{os.getpid()}-{uuid.uuid4().hex[:8]}{path.suffix}")


def _fsync(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def commit(tmp: str | Path, path: str | Path) -> Path:
    """Flush ``tmp`` to disk and rename it onto ``path`` (atomic); returns ``path``."""
    _fsync(Path(tmp))
    os.replace(tmp, path)
    return Path(path)


def discard(tmp: str | Path) -> None:
    """Remove a temporary file if it is there (after a failed write)."""
    try:
        Path(tmp).unlink()
    except FileNotFoundError:
        pass


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path (see :func:`temp_path`) to write ``path``'s new content to; on a normal
    exit it is committed onto ``path``, on an exception removed (``path`` unchanged). The body must
    have closed the file it wrote."""
    path = Path(path)
    tmp = temp_path(path)
    try:
        yield tmp
        commit(tmp, path)
    finally:
        discard(tmp)


def atomic_write_bytes(path: str | Path, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically; returns ``path``."""
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            f.write(data)
    return Path(path)


def atomic_write_text(path: str | Path, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (``encoding``, newlines as given); returns ``path``."""
    return atomic_write_bytes(path, text.encode(encoding))
