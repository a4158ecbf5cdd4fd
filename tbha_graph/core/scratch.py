"""Scratch folders under the system's temporary folder, and their removal when the process ends.

A node writes its files into a work folder; a run with a cache moves them into the cache, a run directory
copies them out. When nothing takes them (a run without a cache, a node run on its own by
:func:`tbha_graph.core.testing.run_node`), the values the caller gets back are paths into that folder, so
it cannot be removed when the run returns: it is removed when the process exits, by the process that made
it (a forked child leaves its parent's folders alone).
"""
from __future__ import annotations

import atexit
import os
import shutil
import tempfile
import threading
from pathlib import Path

_LOCK = threading.Lock()
_AT_EXIT: dict[str, int] = {}  # folder -> the pid that made it
_REGISTERED = False


def scratch_folder(prefix: str) -> Path:
    """A new empty folder under the temporary folder (``$TMPDIR``), named ``<prefix><random>``."""
    return Path(tempfile.mkdtemp(prefix=prefix))


def remove_at_exit(folder: Path) -> None:
    """Remove ``folder`` (and everything in it) when this process exits."""
    global _REGISTERED
    with _LOCK:
        if not _REGISTERED:
            atexit.register(remove_pending)
            _REGISTERED = True
        _AT_EXIT[str(folder)] = os.getpid()


def pending() -> list[Path]:
    """The folders this process will remove when it exits."""
    with _LOCK:
        return [Path(f) for f, pid in _AT_EXIT.items() if pid == os.getpid()]


def remove_pending() -> None:
    """Remove, now, the folders :func:`remove_at_exit` was given by this process (run at exit)."""
    with _LOCK:
        mine = [f for f, pid in _AT_EXIT.items() if pid == os.getpid()]
        for f in mine:
            del _AT_EXIT[f]
    for f in mine:
        shutil.rmtree(f, ignore_errors=True)
