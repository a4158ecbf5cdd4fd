"""The content-addressed cache: one folder per node evaluation, never pickle, never half-written.

Layout under the cache root (``TBHA_CACHE_DIR`` or the platform's user cache folder)::

    entries/<k[:2]>/<key>/meta.json         what the entry holds, with a SHA-256 of every file
    entries/<k[:2]>/<key>/<port><suffix>    one file per output port (.npz, .json or the file itself)
    tmp/<random>/                           entries being written

An entry is written completely into ``tmp/`` and then renamed into place (atomic on one file system):
a killed writer leaves only a ``tmp/`` folder (removed by ``gc``), never a half entry. Two writers of
the same key: the first rename wins, the second discards its copy. A file whose checksum no longer
matches ``meta.json`` is reported as corrupt, the entry is removed and the node runs again.
"""
from __future__ import annotations

import json
import os
import shutil
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from .errors import CacheError
from .filehash import StatMemo, file_content_hash, memo_for
from .paths import default_cache_dir
from .types import AnyOf, AnyType, File, Model, PortType, concrete_type_of, hash_file, storage_type

__all__ = ["Cache", "CorruptEntry", "Entry", "default_cache_dir"]


_O_READ = os.O_RDONLY | getattr(os, "O_BINARY", 0)
#: reading an entry must not write its inode (an access-time update per hit): usage is marked by touch()
_O_NOATIME = getattr(os, "O_NOATIME", 0)


class CorruptEntry(CacheError):
    """A cache entry failed its checksum or could not be parsed."""


@dataclass
class Entry:
    """A complete cache entry: its folder and parsed ``meta.json``."""

    key: str
    path: str | Path
    meta: dict
    #: when meta.json was last modified (the entry last used), seconds since the epoch
    used: float = 0.0

    def fingerprint(self, port: str) -> str:
        return self.meta["outputs"][port]["fingerprint"]

    def load(self, port: str, declared: PortType) -> Any:
        """Load one output, verifying its checksum first."""
        info = self.meta["outputs"][port]
        f = Path(self.path) / info["file"]
        try:
            digest = hash_file(f)
        except OSError as e:
            raise CorruptEntry(f"cache entry {self.key[:12]}: cannot read {f.name}: {e}") from None
        if digest != info["sha256"]:
            raise CorruptEntry(f"cache entry {self.key[:12]}: checksum mismatch in {f.name}")
        t = declared
        if isinstance(declared, (AnyOf, AnyType)):
            t = _stored_type(declared, info, self.key)
        try:
            return t.load(f)
        except Exception as e:  # noqa: BLE001 - any parse failure of stored data is corruption
            raise CorruptEntry(f"cache entry {self.key[:12]}: cannot load {f.name}: {e}") from None


def _model_ref(cls: type) -> str:
    return f"{cls.__module__}:{cls.__qualname__}"


def _model_class(ref: str, key: str) -> type:
    """The pydantic model class named ``module:qualname`` in an entry (a Model stored under Any)."""
    import importlib

    from pydantic import BaseModel

    module, _, qual = str(ref).partition(":")
    try:
        obj: Any = importlib.import_module(module)
        for part in qual.split("."):
            obj = getattr(obj, part)
    except Exception as e:  # noqa: BLE001 - the class is gone or renamed: the entry cannot be read back
        raise CorruptEntry(f"cache entry {key[:12]}: its model class {ref} cannot be found: {e}") from None
    if not (isinstance(obj, type) and issubclass(obj, BaseModel)):
        raise CorruptEntry(f"cache entry {key[:12]}: {ref} is not a pydantic model class")
    return obj


def _stored_type(declared: PortType, info: dict, key: str) -> PortType:
    storage = info.get("storage")
    if isinstance(declared, AnyOf):
        for o in declared.options:
            if type(o).__name__ == storage and (not isinstance(o, Model) or _model_ref(o.model) == info.get("model")):
                return o
    if storage == "Model":
        return Model(_model_class(info.get("model", ""), key))
    try:
        return storage_type(str(storage))
    except KeyError:
        raise CorruptEntry(f"cache entry {key[:12]}: unknown storage type {storage!r}") from None


class Cache:
    """A cache rooted at ``root`` (created on first write)."""

    #: test seam: called after payload files are written and before meta/rename (simulates a crash)
    after_payload_hook: Callable[[Path], None] | None = None

    def __init__(self, root: Path | str | None = None):
        self.root = Path(root) if root is not None else default_cache_dir()
        self.entries = self.root / "entries"
        self._entries_str = str(self.entries)
        self.tmp = self.root / "tmp"
        self._noatime = _O_NOATIME
        # parsed meta.json by key, valid while the file is the same (inode, size, mtime): a study or batch
        # looks the same entries up again and again (the file is still opened and checked every time)
        self._metas: dict[str, tuple[tuple[int, int, int], dict]] = {}
        self.file_memo: StatMemo = memo_for(self.root, "filehash")  # per cache folder, shared in the process
        self.code_memo: StatMemo = memo_for(self.root, "codehash")

    def file_hash(self, path: Path) -> str:
        """SHA-256 of a file's content, memoised in this cache folder's memo."""
        return file_content_hash(path, self.root)

    def key(self, spec: Any, params: Any, input_fingerprints: dict[str, str | None]) -> str:
        """The cache key of one node evaluation (:func:`.keys.node_key` with this cache's memos)."""
        from .keys import node_key

        return node_key(spec, params, input_fingerprints, file_hash=self.file_hash, code_memo=self.code_memo)

    #: at most this many parsed meta.json kept per cache object
    META_MEMO_MAX = 100_000

    def _entry_dir(self, key: str) -> Path:
        return self.entries / key[:2] / key

    # --- reading ------------------------------------------------------------------------------
    def lookup(self, key: str) -> Entry | None:
        """The complete entry for ``key``, or None. An unreadable meta.json counts as corrupt."""
        d = f"{self._entries_str}{os.sep}{key[:2]}{os.sep}{key}"  # plain strings and fds: the cache-hit hot path
        meta_path = f"{d}{os.sep}meta.json"
        try:
            fd = os.open(meta_path, _O_READ | self._noatime)
        except FileNotFoundError:
            return None
        except PermissionError:  # O_NOATIME needs the file's owner: read it the ordinary way
            if not self._noatime:
                raise CorruptEntry(f"cache entry {key[:12]}: cannot open meta.json: permission denied") from None
            self._noatime = 0
            return self.lookup(key)
        except OSError as e:
            raise CorruptEntry(f"cache entry {key[:12]}: cannot open meta.json: {e}") from None
        try:
            st = os.fstat(fd)
            known = self._metas.get(key)
            if known is not None and known[0] == (st.st_ino, st.st_size, st.st_mtime_ns):
                return Entry(key, d, known[1], st.st_mtime)  # the same meta.json, read before in this process
            raw = os.read(fd, st.st_size + 1)
            while len(raw) < st.st_size:  # a short read (never for a small local file): read the rest
                more = os.read(fd, st.st_size + 1 - len(raw))
                if not more:
                    break
                raw += more
            used = st.st_mtime
        except OSError as e:
            raise CorruptEntry(f"cache entry {key[:12]}: cannot read meta.json: {e}") from None
        finally:
            os.close(fd)
        try:
            meta = json.loads(raw)
        except ValueError:
            raise CorruptEntry(f"cache entry {key[:12]}: meta.json is not valid JSON") from None
        if len(self._metas) < self.META_MEMO_MAX:
            self._metas[key] = ((st.st_ino, st.st_size, st.st_mtime_ns), meta)
        return Entry(key, d, meta, used)

    def remove(self, key: str) -> None:
        """Remove an entry (rename away first, so readers never see it half-deleted)."""
        self._metas.pop(key, None)
        d = self._entry_dir(key)
        if not d.exists():
            return
        self.tmp.mkdir(parents=True, exist_ok=True)
        trash = self.tmp / f"trash-{uuid.uuid4().hex}"
        try:
            os.replace(d, trash)
        except OSError:
            return
        shutil.rmtree(trash, ignore_errors=True)

    # --- writing ------------------------------------------------------------------------------
    def store(self, key: str, outputs: dict[str, tuple[PortType, Any]], info: dict) -> tuple[Entry, dict[str, Any]]:
        """Write a complete entry for ``key`` atomically. ``outputs``: port -> (declared type, value).

        Returns the entry and the stored values (File outputs become paths inside the entry)."""
        self.tmp.mkdir(parents=True, exist_ok=True)
        work = self.tmp / f"{key[:16]}-{os.getpid()}-{uuid.uuid4().hex[:8]}"
        work.mkdir()
        try:
            meta_out: dict[str, dict] = {}
            for port, (declared, value) in outputs.items():
                t = concrete_type_of(declared, value)
                fname = port + (t.suffix or (Path(str(value)).suffix if isinstance(t, File) else ".dat"))
                f = work / fname
                t.save(value, f)
                digest = hash_file(f)
                meta_out[port] = {
                    "file": fname,
                    "storage": type(t).__name__,
                    # a stored file's fingerprint is its content hash, which was just computed
                    "fingerprint": digest if isinstance(t, File) else t.fingerprint(value),
                    "sha256": digest,
                    "bytes": f.stat().st_size,
                }
                if isinstance(t, Model):
                    meta_out[port]["model"] = _model_ref(t.model)
            if self.after_payload_hook is not None:
                self.after_payload_hook(work)
            meta = {"key": key, "created": time.time(), "outputs": meta_out, **info}
            with open(work / "meta.json", "w") as fh:
                json.dump(meta, fh, sort_keys=True, separators=(",", ":"))
                fh.flush()
                os.fsync(fh.fileno())
            final = self._entry_dir(key)
            final.parent.mkdir(parents=True, exist_ok=True)
            try:
                os.rename(work, final)
            except OSError:
                if not (final / "meta.json").exists():
                    raise
                shutil.rmtree(work, ignore_errors=True)  # another run stored the same key first
        except BaseException:
            shutil.rmtree(work, ignore_errors=True)
            raise
        entry = self.lookup(key)
        assert entry is not None
        values = {}
        for port, (declared, value) in outputs.items():
            t = concrete_type_of(declared, value)
            values[port] = t.load(Path(entry.path) / entry.meta["outputs"][port]["file"]) if isinstance(t, File) else value
        return entry, values

    # --- maintenance --------------------------------------------------------------------------
    def iter_entries(self):
        if not self.entries.exists():
            return
        for sub in self.entries.iterdir():
            if sub.is_dir():
                yield from (d for d in sub.iterdir() if d.is_dir())

    def info(self) -> dict:
        n, size = 0, 0
        for d in self.iter_entries():
            n += 1
            size += sum(f.stat().st_size for f in d.iterdir() if f.is_file())
        tmp = len(list(self.tmp.iterdir())) if self.tmp.exists() else 0
        return {"root": str(self.root), "entries": n, "bytes": size, "tmp_folders": tmp}

    def clear(self) -> int:
        n = sum(1 for _ in self.iter_entries())
        for sub in (self.entries, self.tmp):
            if sub.exists():
                shutil.rmtree(sub, ignore_errors=True)
        return n

    def gc(self, older_than_days: float | None = None, max_bytes: int | None = None, tmp_age_s: float = 3600) -> dict:
        """Remove stale tmp folders (older than ``tmp_age_s``), entries not used for ``older_than_days``,
        and the least recently used entries beyond ``max_bytes``."""
        now = time.time()
        removed_tmp = 0
        if self.tmp.exists():
            for d in self.tmp.iterdir():
                try:
                    if now - d.stat().st_mtime > tmp_age_s or d.name.startswith("trash-"):
                        shutil.rmtree(d, ignore_errors=True) if d.is_dir() else d.unlink()
                        removed_tmp += 1
                except FileNotFoundError:
                    pass
        entries = []
        for d in self.iter_entries():
            try:
                used = (d / "meta.json").stat().st_mtime
            except FileNotFoundError:
                shutil.rmtree(d, ignore_errors=True)
                continue
            entries.append((used, sum(f.stat().st_size for f in d.iterdir() if f.is_file()), d))
        entries.sort()
        removed = 0
        total = sum(s for _, s, _ in entries)
        for used, size, d in entries:
            old = older_than_days is not None and now - used > older_than_days * 86400
            big = max_bytes is not None and total > max_bytes
            if old or big:
                self.remove(d.name)
                total -= size
                removed += 1
        return {"removed_entries": removed, "removed_tmp": removed_tmp, "bytes_left": total}

    #: a hit re-marks an entry only when its mark is older than this (gc's granularity), seconds
    TOUCH_AFTER_S = 60.0

    def touch(self, entry: Entry, now: float | None = None) -> None:
        """Mark an entry as used (for ``gc``'s least-recently-used order): its meta.json's mtime (left
        alone when it is younger than :attr:`TOUCH_AFTER_S`, to keep a cache hit cheap)."""
        if entry.used and (now if now is not None else time.time()) - entry.used < self.TOUCH_AFTER_S:
            return
        try:
            os.utime(os.path.join(entry.path, "meta.json"))
        except OSError:
            pass
