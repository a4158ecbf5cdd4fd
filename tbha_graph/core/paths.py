"""Where the framework keeps its files by default (imports nothing of the framework: the bottom layer)."""
from __future__ import annotations

import os
import sys
from pathlib import Path


def default_cache_dir() -> Path:
    """``$TBHA_CACHE_DIR``, else ``$XDG_CACHE_HOME/tbha-graph`` (``~/.cache``), ``~/Library/Caches`` on
    macOS, ``%LOCALAPPDATA%`` on Windows."""
    env = os.environ.get("TBHA_CACHE_DIR")
    if env:
        return Path(env).expanduser()
    if sys.platform == "darwin":
        return Path.home() / "Library" / "Caches" / "tbha-graph"
    if os.name == "nt":
        return Path(os.environ.get("LOCALAPPDATA", Path.home())) / "tbha-graph" / "Cache"
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "tbha-graph"
