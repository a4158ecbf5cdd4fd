"""Content hashes of files, memoised by (path, size, mtime) so a big video is not re-hashed every run.

The memo lives in ``<cache dir>/filehash.json`` (written atomically); a changed size or mtime
invalidates the entry. The hash itself is always of the content, so moving or copying a file keeps it.
"""
from __future__ import annotations

import json
import threading
from pathlib import Path

from .atomic import atomic_write_bytes
from .types import hash_file

_lock = threading.Lock()
_memo: dict[str, list] = {}
_memo_path: Path | None = None


def _memo_file() -> Path | None:
    from .cache import default_cache_dir

    try:
        d = default_cache_dir()
        return d / "filehash.json"
    except Exception:
        return None


def _load() -> None:
    global _memo_path, _memo
    path = _memo_file()
    if path == _memo_path:
        return
    _memo_path = path
    _memo = {}
    if path is not None and path.is_file():
        try:
            _memo = json.loads(path.read_text())
        except (OSError, ValueError):
            _memo = {}


def file_content_hash(path: Path) -> str:
    """SHA-256 of the file's bytes, memoised by absolute path, size and mtime (nanoseconds)."""
    path = Path(path).resolve()
    st = path.stat()
    key = str(path)
    with _lock:
        _load()
        hit = _memo.get(key)
        if hit and hit[0] == st.st_size and hit[1] == st.st_mtime_ns:
            return hit[2]
    digest = hash_file(path)
    with _lock:
        _memo[key] = [st.st_size, st.st_mtime_ns, digest]
        if _memo_path is not None:
            try:
                _memo_path.parent.mkdir(parents=True, exist_ok=True)
                atomic_write_bytes(_memo_path, json.dumps(_memo).encode())
            except OSError:
                pass  # the memo is an optimisation only
    return digest
