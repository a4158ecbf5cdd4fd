"""Memos of values derived from a file's content (its SHA-256, a module's code fingerprint), keyed by
the file's absolute path, size and mtime, so a big video is not re-hashed and a module not re-parsed
every run.

One memo per cache folder and kind (``<cache dir>/filehash.json``, ``<cache dir>/codehash.json``),
written atomically; a changed size or mtime invalidates an entry. The value is always derived from the
content, so moving or copying a file keeps it. The memo in use follows the cache the scheduler runs
with (``--cache-dir``): :func:`using_cache_dir` sets it for the node being run, so a node calling
:func:`file_content_hash` uses its run's memo, not the default folder's.
"""
from __future__ import annotations

import contextlib
import contextvars
import json
import os
import threading
from pathlib import Path
from typing import Any, Iterator

from .atomic import atomic_write_bytes
from .paths import default_cache_dir
from .types import hash_file


class StatMemo:
    """``path -> (size, mtime_ns, value)``, persisted as JSON in ``file`` (None: in memory only)."""

    def __init__(self, file: Path | None):
        self.file = file
        self._lock = threading.Lock()
        self._data: dict[str, list] | None = None
        self._dirty = False

    def _load(self) -> dict[str, list]:
        if self._data is None:
            data: Any = {}
            if self.file is not None and self.file.is_file():
                try:
                    data = json.loads(self.file.read_text())
                except (OSError, ValueError):
                    data = {}
            self._data = data if isinstance(data, dict) else {}
        return self._data

    def get(self, path: str, st: os.stat_result) -> Any:
        with self._lock:
            hit = self._load().get(path)
        if isinstance(hit, list) and len(hit) == 3 and hit[0] == st.st_size and hit[1] == st.st_mtime_ns:
            return hit[2]
        return None

    def put(self, path: str, st: os.stat_result, value: Any, save: bool = True) -> None:
        with self._lock:
            self._load()[path] = [st.st_size, st.st_mtime_ns, value]
            self._dirty = True
        if save:
            self.save()

    def save(self) -> None:
        """Write the memo if it changed (atomically; the memo is an optimisation, errors are ignored)."""
        with self._lock:
            if not self._dirty or self.file is None or self._data is None:
                return
            try:
                self.file.parent.mkdir(parents=True, exist_ok=True)
                atomic_write_bytes(self.file, json.dumps(self._data).encode())
                self._dirty = False
            except OSError:
                pass


_memos: dict[tuple[str, str], StatMemo] = {}
_memos_lock = threading.Lock()
_current_root: contextvars.ContextVar[Path | None] = contextvars.ContextVar("tbha_cache_root", default=None)


def memo_for(root: Path | str | None, kind: str = "filehash") -> StatMemo:
    """The process's memo of ``kind`` for the cache folder ``root`` (default: the default cache folder)."""
    root = Path(root) if root is not None else (_current_root.get() or default_cache_dir())
    k = (str(root), kind)
    with _memos_lock:
        m = _memos.get(k)
        if m is None:
            m = _memos[k] = StatMemo(root / f"{kind}.json")
        return m


@contextlib.contextmanager
def using_cache_dir(root: Path | str | None) -> Iterator[None]:
    """Within this block :func:`file_content_hash` (without ``root``) uses the memo of ``root``."""
    token = _current_root.set(Path(root) if root is not None else None)
    try:
        yield
    finally:
        _current_root.reset(token)


def file_content_hash(path: Path, root: Path | str | None = None) -> str:
    """SHA-256 of the file's bytes, memoised by absolute path, size and mtime (nanoseconds) in the memo
    of cache folder ``root`` (default: the cache of the running node, else the default cache folder)."""
    path = Path(path).resolve()
    st = path.stat()
    memo = memo_for(root)
    key = str(path)
    hit = memo.get(key, st)
    if isinstance(hit, str):
        return hit
    digest = hash_file(path)
    memo.put(key, st, digest)
    return digest
