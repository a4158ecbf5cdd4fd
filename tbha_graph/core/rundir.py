"""Writing a run directory: the named outputs plus ``manifest.json``, all or nothing.

Everything is written into ``<out>.partial-<pid>/`` first; only when every output and the manifest
are complete is that folder renamed to ``<out>``. A failed run therefore never leaves an output folder
that looks complete.

Nothing the project did not write is ever deleted or overwritten:

* ``<out>`` missing or empty: the staging folder is renamed into place.
* ``<out>`` an earlier run (it holds a ``manifest.json`` written here, which lists the run's files):
  only that run's files are replaced or removed; anything else in the folder stays untouched.
* ``<out>`` anything else that is not empty: refused with an error before anything is written.
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


def manifest(run: RunResult, executor: str, files: list[str] | None = None) -> dict[str, Any]:
    g = run.graph
    nodes = {}
    for nid, res in run.results.items():
        b = g.nodes[nid]
        try:
            params = canonical_params(b.params, effective=False)
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
            "warnings": list(res.node_warnings),
        }
    return {
        "written_by": "tbha-graph",
        "pipeline": g.path,
        "pipeline_files": {f: _file_sha(f) for f in (g.files or [])},
        "description": g.description,
        "created": time.strftime("%Y-%m-%dT%H:%M:%S%z"),
        "executor": executor,
        "seconds": round(run.seconds, 3),
        "outputs": {name: f"{n}.{p}" for name, (n, p) in g.outputs.items()},
        "files": sorted(files) if files is not None else None,
        "nodes": nodes,
        "warnings": run.node_warnings(),
        "packages": package_versions(),
    }


MANIFEST = "manifest.json"


def _safe_rel(name: Any) -> str | None:
    """A manifest's file entry as a relative path inside the run folder, or None if it is not one."""
    if not isinstance(name, str) or not name or "\\" in name:
        return None
    parts = Path(name).parts
    if Path(name).is_absolute() or ".." in parts or not parts:
        return None
    return Path(name).as_posix()


def run_files(folder: Path) -> set[str] | None:
    """The files an earlier run wrote into ``folder`` (relative paths, ``manifest.json`` included), read
    from its manifest; None when ``folder`` holds no manifest written by this project."""
    try:
        data = json.loads((Path(folder) / MANIFEST).read_text())
    except FileNotFoundError:
        if not Path(folder).is_dir():
            raise  # the folder itself went away (another run replacing it): the caller looks again
        return None
    except (OSError, ValueError, UnicodeDecodeError):
        return None
    if not isinstance(data, dict) or not isinstance(data.get("outputs"), dict) or not isinstance(data.get("nodes"), dict):
        return None
    listed = data.get("files")
    names = listed if isinstance(listed, list) else list(data["outputs"])
    out = {MANIFEST}
    for n in names:
        r = _safe_rel(n)
        if r is not None:
            out.add(r)
    return out


def _files_under(folder: Path) -> set[str]:
    """Every file and folder under ``folder`` (relative paths; symbolic links are not followed)."""
    return {p.relative_to(folder).as_posix() for p in folder.rglob("*")}


def _remove_run(folder: Path, own: set[str]) -> None:
    """Delete ``own`` files in ``folder``, then the folders they leave empty (``folder`` included).
    Anything else stays where it is."""
    for rel in own:
        p = folder / rel
        try:
            if p.is_symlink() or p.is_file():
                p.unlink()
        except FileNotFoundError:
            pass
    dirs = sorted({(folder / rel).parent for rel in own} | {folder}, key=lambda d: len(d.parts), reverse=True)
    for d in dirs:
        while True:
            try:
                d.rmdir()  # only succeeds when empty
            except OSError:
                break
            if d == folder or folder not in d.parents:
                break
            d = d.parent


def _swap_in(staging: Path, out_dir: Path, parent: Path, attempts: int = 20) -> None:
    """Rename ``staging`` to ``out_dir``; a previous ``out_dir`` (empty, or an earlier run holding only its
    own files) is moved aside first and then only its own files are removed. Another run writing the same
    folder at the same moment can move it, or put its own in place, between the two renames: then try
    again (the last complete run wins; no run fails because of another)."""
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
                _remove_run(old, run_files(old) or set())
                if old.exists():  # something not ours appeared meanwhile: keep it, under a visible name
                    try:
                        os.replace(old, parent / f"{out_dir.name}.kept-{old.name.rsplit('-', 1)[-1]}")
                    except OSError:
                        pass


def _merge_in(staging: Path, out_dir: Path, old_own: set[str], new_files: list[str]) -> None:
    """Put a new run into ``out_dir``, which holds an earlier run plus files that are not the project's:
    replace the earlier run's files one by one (each rename is atomic), remove those the new run does not
    write, and write the manifest last. Files that are not the earlier run's are never touched."""
    for rel in new_files:
        target = out_dir / rel
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(staging / rel, target)
    _remove_run(out_dir, old_own - set(new_files) - {MANIFEST})
    out_dir.mkdir(exist_ok=True)
    os.replace(staging / MANIFEST, out_dir / MANIFEST)
    shutil.rmtree(staging, ignore_errors=True)


def check_out_dir(out_dir: Path, new_files: list[str] | None = None) -> tuple[str, set[str]]:
    """Decide how a run may be written to ``out_dir``: ("new", {}), ("swap", old files) or
    ("merge", old files). Raises TbhaError (before anything is written) when the folder is not empty and
    not an earlier run, or when a new output would overwrite a file the earlier run did not write.
    Another run replacing the same folder meanwhile (moving it aside while it is looked at) is waited out."""
    refusals = 0
    for attempt in range(60):
        try:
            return _check_out_dir(Path(out_dir), new_files)
        except FileNotFoundError:
            if attempt == 59:
                raise
        except TbhaError:
            # a refusal is only believed when it holds on a second and third look: a folder caught in the
            # middle of another run's replacement can look like anything for an instant
            refusals += 1
            if refusals >= 3:
                raise
        time.sleep(0.002 * (attempt % 10 + 1))
    raise AssertionError("unreachable")


def _check_out_dir(out_dir: Path, new_files: list[str] | None) -> tuple[str, set[str]]:
    if not out_dir.exists() and not out_dir.is_symlink():
        return "new", set()
    if not out_dir.is_dir():
        if not out_dir.exists() and not out_dir.is_symlink():
            raise FileNotFoundError(str(out_dir))  # moved away meanwhile by another run: look again
        raise TbhaError(f"the output folder {out_dir} exists and is not a folder; nothing was written",
                        hint="choose a new or empty folder with --out")
    present = _files_under(out_dir)
    if not present:
        return "new", set()
    own = run_files(out_dir)
    if own is None and not out_dir.is_dir():
        raise FileNotFoundError(str(out_dir))
    if own is None:
        shown = ", ".join(sorted(p.name for p in out_dir.iterdir())[:5])
        raise TbhaError(
            f"refusing to write into {out_dir}: the folder is not empty ({shown}{', ...' if len(present) > 5 else ''}) "
            f"and is not an earlier run (it has no manifest.json written by tbha-graph); nothing was written or deleted",
            hint="choose a new or empty folder with --out, e.g. --out runs/my_take",
        )
    own_dirs = {Path(r).parents[i].as_posix() for r in own for i in range(len(Path(r).parents) - 1)}
    foreign = present - own - own_dirs
    if not foreign:
        return "swap", own
    clash = sorted(set(new_files or ()) & foreign)
    if clash:
        raise TbhaError(
            f"refusing to write into {out_dir}: {', '.join(clash)} would overwrite file(s) the earlier run there did not write; nothing was written",
            hint="move those files away or choose another folder with --out",
        )
    return "merge", own


def write_run_dir(run: RunResult, out_dir: Path, executor: str = "local") -> list[Path]:
    """Write every named output and ``manifest.json`` to ``out_dir`` atomically; returns the files.
    Never deletes or overwrites a file this project did not write (see the module docstring)."""
    out_dir = Path(out_dir)
    names = [name for name, (nid, _) in run.graph.outputs.items() if nid in run.results]
    rels = [r for r in (_safe_rel(n) for n in names) if r is not None]
    check_out_dir(out_dir, rels)  # refuse early, before any output is saved
    parent = out_dir.resolve().parent
    try:
        parent.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise TbhaError(f"cannot create the output folder {parent}: {e.strerror}", hint="choose another folder with --out") from None
    staging = parent / f".{out_dir.resolve().name}.partial-{os.getpid()}-{uuid.uuid4().hex[:6]}"
    written: list[Path] = []
    try:
        staging.mkdir()
        files: list[str] = []
        for name, (nid, port) in run.graph.outputs.items():
            if nid not in run.results:
                continue
            bound = run.graph.nodes[nid]
            value = run.with_warnings(run.results[nid].value(port, bound))  # a report carries every node's warnings
            t = concrete_type_of(bound.spec.outputs[port], value)
            target = staging / name
            target.parent.mkdir(parents=True, exist_ok=True)
            t.save(value, target)
            written.append(out_dir / name)
            files += [p.relative_to(staging).as_posix() for p in ([target] if not target.is_dir() else target.rglob("*")) if not p.is_dir()]
        with open(staging / MANIFEST, "w") as f:
            json.dump(manifest(run, executor, files), f, indent=2, sort_keys=False)
            f.flush()
            os.fsync(f.fileno())
        mode, own = check_out_dir(out_dir, files)  # again: the folder may have changed while outputs were saved
        if mode == "merge":
            _merge_in(staging, out_dir, own, files)
        else:
            _swap_in(staging, out_dir.resolve(), parent)
    except OSError as e:
        shutil.rmtree(staging, ignore_errors=True)
        raise TbhaError(
            f"cannot write the run directory {out_dir}: {e.strerror or e}",
            hint="check free disk space and permissions, or choose another folder with --out",
        ) from None
    except BaseException:
        shutil.rmtree(staging, ignore_errors=True)
        raise
    return written + [out_dir / MANIFEST]
