"""Cache keys: a pure function of everything that can change a node's result.

key = sha256(canonical JSON of {
    cache format,
    node type, declared version,
    code fingerprint  (source of the node's module and of every module of the same top-level package
                       it reaches through its globals: editing a helper invalidates the cache too),
    every param in canonical JSON (defaults included; input-file params by path and content hash),
    each input port's content fingerprint (arrays by dtype + shape + bytes, files by content),
})

Anything that cannot be hashed raises; nothing falls back to a constant.
"""
from __future__ import annotations

import hashlib
import inspect
import sys
import types
from pathlib import Path
from typing import Any

from pydantic import BaseModel

from .errors import CacheError
from .filehash import file_content_hash
from .node import NodeSpec, is_input_path_field
from .types import hash_json

CACHE_FORMAT = 1


def _module_closure(root_module: types.ModuleType) -> list[types.ModuleType]:
    """The module and every module of the same top-level package reachable through globals."""
    top = root_module.__name__.split(".")[0]
    seen: dict[str, types.ModuleType] = {}
    stack = [root_module]
    while stack:
        mod = stack.pop()
        if mod.__name__ in seen:
            continue
        seen[mod.__name__] = mod
        for value in list(vars(mod).values()):
            if isinstance(value, types.ModuleType):
                cand = value
            else:
                name = getattr(value, "__module__", None)
                if not isinstance(name, str):
                    continue
                cand = sys.modules.get(name)
            if cand is not None and cand.__name__.split(".")[0] == top and cand.__name__ not in seen:
                stack.append(cand)
    return [seen[k] for k in sorted(seen)]


def code_fingerprint(spec: NodeSpec) -> str:
    """SHA-256 over the source files of the node's module closure (memoised per process)."""
    fp = spec.__dict__.get("_code_fingerprint")  # memoised on the spec itself (an id() key could be reused)
    if fp is not None:
        return fp
    mod = sys.modules.get(spec.module)
    h = hashlib.sha256()
    if mod is None:
        src = inspect.getsource(spec.fn)
        h.update(src.encode())
    else:
        for m in _module_closure(mod):
            f = getattr(m, "__file__", None)
            h.update(m.__name__.encode())
            if f and Path(f).is_file():
                h.update(Path(f).read_bytes())
            else:
                try:
                    h.update(inspect.getsource(m).encode())
                except (OSError, TypeError):
                    h.update(b"<no source>")
    fp = h.hexdigest()
    spec.__dict__["_code_fingerprint"] = fp
    return fp


_file_fields: dict[type, tuple[str, ...]] = {}


def _input_path_fields(model: type[BaseModel]) -> tuple[str, ...]:
    names = _file_fields.get(model)
    if names is None:
        names = tuple(n for n, f in model.model_fields.items() if is_input_path_field(f.annotation, f.metadata))
        _file_fields[model] = names
    return names


def canonical_params(params: BaseModel) -> dict[str, Any]:
    """Every param (defaults included) as JSON; input-file params as {path, sha256 of content}."""
    data = params.model_dump(mode="json")
    for name in _input_path_fields(type(params)):
        value = getattr(params, name)
        if value is None:
            continue
        p = Path(value)
        if p.is_file():
            data[name] = {"path": str(p.resolve()), "sha256": file_content_hash(p)}
        elif p.is_dir():
            data[name] = {"path": str(p.resolve()), "sha256": _dir_hash(p)}
        else:
            raise CacheError(f"param '{name}': input file {p} does not exist, cannot compute the cache key")
    return data


def _dir_hash(p: Path) -> str:
    items = {str(f.relative_to(p)): file_content_hash(f) for f in sorted(p.rglob("*")) if f.is_file()}
    return hash_json(items)


def node_key(spec: NodeSpec, params: BaseModel, input_fingerprints: dict[str, str | None]) -> str:
    """The cache key of one node evaluation."""
    return hash_json(
        {
            "format": CACHE_FORMAT,
            "type": spec.type,
            "version": spec.version,
            "code": code_fingerprint(spec),
            "params": canonical_params(params),
            "inputs": input_fingerprints,
        }
    )
