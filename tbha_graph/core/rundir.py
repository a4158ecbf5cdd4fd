"""Writing a run directory: the named outputs plus ``manifest.json``, all or nothing.

Everything is written into ``<out>.partial-<pid>/`` first; only when every output and the manifest
are complete is that folder renamed to ``<out>`` (a previous ``<out>`` is moved aside and deleted).
A failed run therefore never leaves an output folder that looks complete.
"""
from __future__ import annotations

import errno
import hashlib
import importlib.metadata as md
import json
import os
import platform
import shutil
import time
import uuid
from pathlib import Path
from typing import Any

from .errors import TbhaError
from .keys import canonical_params
from .scheduler import RunResult
from .types import concrete_type_of

_PACKAGES = ("tbha-graph", "numpy", "opencv-contrib-python-headless", "networkx", "pydantic", "pyyaml", "scipy", "dask", "distributed")


def package_versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for p in _PACKAGES:
        try:
            out[p] = md.version(p)
        except md.PackageNotFoundError:
            pass
    return out


def _file_sha(path: str) -> str | None:
    try:
        return hashlib.sha256(Path(path).read_bytes()).hexdigest()
    except OSError:
        return None


def manifest(run: RunResult, executor: str) -> dict[str, Any]:
    g = run.graph
    nodes = {}
    for nid, res in run.results.items():
        b = g.nodes[nid]
        try:
            params = canonical_params(b.params)
        except TbhaError:
            params = b.params.model_dump(mode="json")
        nodes[nid] = {
            "type": b.spec.type,
            "version": b.spec.version,
            "source": b.spec.source,
            "params": params,
            "cache_key": res.key,
            "status": res.status,
            "seconds": round(res.seconds, 6),
        }
    return {
        "pipeline": g.path,
        "pipeline_files": {f: _file_sha(f) for f in (g.files or [])},
        "description": g.description,
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "executor": executor,
        "seconds": round(run.seconds, 3),
        "outputs": {name: f"{n}.{p}" for name, (n, p) in g.outputs.items()},
        "nodes": nodes,
        "packages": package_versions(),
    }


def _swap_in(staging: Path, out_dir: Path, parent: Path, attempts: int = 20) -> None:
    """Rename ``staging`` to ``out_dir``, moving a previous ``out_dir`` aside first. Another run writing
    the same folder at the same moment can move it, or put its own in place, between the two renames:
    then try again (the last complete run wins; no run fails because of another)."""
    for attempt in range(attempts):
        old = parent / f".{out_dir.name}.old-{uuid.uuid4().hex[:6]}"
        try:
            os.replace(out_dir, old)
        except FileNotFoundError:
            old = None
        try:
            os.replace(staging, out_dir)
            return
        except OSError as e:
            if e.errno not in (errno.ENOTEMPTY, errno.EEXIST) or attempt == attempts - 1:
                raise
        finally:
            if old is not None:
                shutil.rmtree(old, ignore_errors=True)


def write_run_dir(run: RunResult, out_dir: Path, executor: str = "local") -> list[Path]:
    """Write every named output and ``manifest.json`` to ``out_dir`` atomically; returns the files."""
    out_dir = Path(out_dir)
    parent = out_dir.resolve().parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise TbhaError(f"cannot create the output folder {parent}: {e.strerror}", hint="choose another folder with --out") from None
    staging = parent / f".{out_dir.name}.partial-{os.getpid()}-{uuid.uuid4().hex[:6]}"
    written: list[Path] = []
    try:
        staging.mkdir()
        for name, (nid, port) in run.graph.outputs.items():
            if nid not in run.results:
                continue
            bound = run.graph.nodes[nid]
            value = run.results[nid].value(port, bound)
            t = concrete_type_of(bound.spec.outputs[port], value)
            target = staging / name
            target.parent.mkdir(parents=True, exist_ok=True)
            t.save(value, target)
            written.append(out_dir / name)
        with open(staging / "manifest.json", "w") as f:
            json.dump(manifest(run, executor), f, indent=2, sort_keys=False)
            f.flush()
            os.fsync(f.fileno())
        _swap_in(staging, out_dir, parent)
    except OSError as e:
        shutil.rmtree(staging, ignore_errors=True)
        raise TbhaError(
            f"cannot write the run directory {out_dir}: {e.strerror or e}",
            hint="check free disk space and permissions, or choose another folder with --out; nothing was written",
        ) from None
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return written + [out_dir / "manifest.json"]
