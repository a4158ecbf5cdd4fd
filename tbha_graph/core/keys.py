"""Cache keys: a pure function of everything that can change a node's result, and nothing else.

key = sha256(canonical JSON of {
    cache format,
    node type, declared version,
    code fingerprint: the node's module, its parent packages and every module of the same top-level
                      package it imports, transitively, at module level or inside a function; each
                      module fingerprinted from its syntax tree with docstrings removed (comments,
                      docstrings and formatting do not count; constants, code and imports do),
    effective params: after presets resolve (a params model may define ``effective()``, see
                      :func:`canonical_params`); input-file params by path and content hash,
    each input port's content fingerprint (arrays by dtype + shape + bytes, files by content),
})

Nothing here imports a node's modules or runs its code: module files are found from the top-level
package's folder and read. ``file_hash`` and the code memo are passed in by the caller (the cache), so
the function stays pure; anything that cannot be hashed raises, nothing falls back to a constant.
"""
from __future__ import annotations

import ast
import hashlib
import importlib.util
import inspect
import json
import os
import sys
from pathlib import Path
from typing import Any, Callable, Protocol

from pydantic import BaseModel

from .errors import CacheError
from .node import NodeSpec, input_path_fields
from .types import hash_json

CACHE_FORMAT = 2


class Memo(Protocol):
    """What :func:`code_fingerprint` needs of a memo (``filehash.StatMemo`` is one)."""

    def get(self, path: str, st: os.stat_result) -> Any: ...

    def put(self, path: str, st: os.stat_result, value: Any, save: bool = True) -> None: ...

    def save(self) -> None: ...


# ---------------------------------------------------------------------------------------------
# one module: syntax-tree fingerprint and the modules it imports
# ---------------------------------------------------------------------------------------------
def _strip_docstrings(tree: ast.AST) -> ast.AST:
    for n in ast.walk(tree):
        if isinstance(n, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)):
            body = n.body
            if body and isinstance(body[0], ast.Expr) and isinstance(body[0].value, ast.Constant) and isinstance(body[0].value.value, str):
                n.body = body[1:] or [ast.Pass()]
    return tree


def _is_type_checking(test: ast.expr) -> bool:
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _walk_run(tree: ast.AST):
    """Every node of the tree except the bodies of ``if TYPE_CHECKING:`` (imports that never run)."""
    todo = [tree]
    while todo:
        n = todo.pop()
        yield n
        if isinstance(n, ast.If) and _is_type_checking(n.test):
            todo.extend(n.orelse)
            continue
        todo.extend(ast.iter_child_nodes(n))


def _imports(tree: ast.AST, module: str, is_package: bool) -> list[str]:
    """Absolute names of everything ``import``-ed anywhere in the module (functions included, ``if
    TYPE_CHECKING:`` blocks not: they never run); for
    ``from a import b`` both ``a`` and ``a.b`` (``b`` may be a submodule; non-modules are dropped later)."""
    package = module if is_package else module.rpartition(".")[0]
    found: set[str] = set()
    for n in _walk_run(tree):
        if isinstance(n, ast.Import):
            found.update(a.name for a in n.names)
        elif isinstance(n, ast.ImportFrom):
            if n.level:
                parts = package.split(".") if package else []
                if n.level - 1 > len(parts):
                    continue
                base_parts = parts[: len(parts) - (n.level - 1)]
                base = ".".join(base_parts + ([n.module] if n.module else []))
            else:
                base = n.module or ""
            if not base:
                continue
            found.add(base)
            found.update(f"{base}.{a.name}" for a in n.names if a.name != "*")
    return sorted(found)


def source_fingerprint(source: str | bytes, module: str = "<module>", is_package: bool = False) -> tuple[str, list[str]]:
    """``(fingerprint, imported names)`` of one module's source: SHA-256 of its syntax tree without
    docstrings, positions or comments."""
    try:
        tree = ast.parse(source)
    except SyntaxError as e:
        raise CacheError(f"module {module}: cannot parse its source to fingerprint it: {e}") from None
    imports = _imports(tree, module, is_package)
    dump = ast.dump(_strip_docstrings(tree), annotate_fields=False, include_attributes=False)
    return hashlib.sha256(dump.encode()).hexdigest(), imports


# ---------------------------------------------------------------------------------------------
# a module's closure
# ---------------------------------------------------------------------------------------------
def _top_dirs(top: str) -> list[str]:
    mod = sys.modules.get(top)
    paths = list(getattr(mod, "__path__", []) or []) if mod is not None else []
    if not paths and mod is None:
        spec = importlib.util.find_spec(top)  # a top-level name: imports nothing
        if spec is not None and spec.submodule_search_locations:
            paths = list(spec.submodule_search_locations)
    return [str(p) for p in paths]


def module_file(name: str) -> tuple[str, bool] | None:
    """``(source file, is a package)`` of module ``name``, found without importing it; None when it has
    no source file (a builtin, an extension, a name that is not a module)."""
    mod = sys.modules.get(name)
    f = getattr(mod, "__file__", None) if mod is not None else None
    if f:
        return (f, os.path.basename(f) == "__init__.py") if f.endswith(".py") else None
    top, _, rest = name.partition(".")
    if not rest:
        if name == "__main__":
            return None
        spec = importlib.util.find_spec(name) if mod is None else None
        if spec is None or not spec.origin or not spec.origin.endswith(".py"):
            return None
        return spec.origin, spec.submodule_search_locations is not None
    for d in _top_dirs(top):
        base = os.path.join(d, *rest.split("."))
        init = os.path.join(base, "__init__.py")
        if os.path.isfile(init):
            return init, True
        if os.path.isfile(base + ".py"):
            return base + ".py", False
    return None


#: this process's records: (module, file) -> (size, mtime_ns, fingerprint, imports); checked by stat
_records: dict[tuple[str, str], tuple[int, int, str, list[str]]] = {}


def _module_record(name: str, memo: Memo | None) -> tuple[str, list[str]] | None:
    found = module_file(name)
    if found is None:
        return None
    path, is_package = found
    st = os.stat(path)
    mine = _records.get((name, path))
    if mine is not None and mine[0] == st.st_size and mine[1] == st.st_mtime_ns:
        return mine[2], mine[3]
    key = f"{path}::{name}"  # the same file can be two modules (__main__ and its import name)
    hit = memo.get(key, st) if memo is not None else None
    if isinstance(hit, list) and len(hit) == 2:
        fp, imports = hit[0], list(hit[1])
    else:
        with open(path, "rb") as fh:
            fp, imports = source_fingerprint(fh.read(), name, is_package)
        if memo is not None:
            memo.put(key, st, [fp, imports], save=False)
    _records[(name, path)] = (st.st_size, st.st_mtime_ns, fp, imports)
    return fp, imports


def module_closure(module: str, memo: Memo | None = None) -> dict[str, str]:
    """``{module name: fingerprint}`` of ``module``, its parent packages and every module of the same
    top-level package reached by imports (module or function level), transitively."""
    top = module.split(".")[0]
    out: dict[str, str] = {}
    stack = [module]
    seen: set[str] = set()
    while stack:
        name = stack.pop()
        if name in seen:
            continue
        seen.add(name)
        parts = name.split(".")
        stack.extend(".".join(parts[:i]) for i in range(1, len(parts)))  # parent packages run on import
        rec = _module_record(name, memo)
        if rec is None:
            continue
        out[name] = rec[0]
        stack.extend(m for m in rec[1] if m.split(".")[0] == top and m not in seen)
    if memo is not None:
        memo.save()
    return dict(sorted(out.items()))


def code_fingerprint(spec: NodeSpec, memo: Memo | None = None) -> str:
    """SHA-256 over the module closure of the node's function (memoised on the spec: once per process)."""
    fp = spec.__dict__.get("_code_fingerprint")
    if fp is not None:
        return fp
    closure = module_closure(spec.module, memo) if spec.module else {}
    if spec.module not in closure:  # no source file (defined interactively): the function's own source
        try:
            closure[f"<source of {spec.type}>"] = source_fingerprint(inspect.getsource(spec.fn).strip())[0]
        except (OSError, TypeError):
            raise CacheError(f"node type '{spec.type}': its code has no source to fingerprint",
                             hint="define the node in a module file, or run without a cache") from None
    fp = hash_json(closure)
    spec.__dict__["_code_fingerprint"] = fp
    return fp


# ---------------------------------------------------------------------------------------------
# params
# ---------------------------------------------------------------------------------------------
def _default_file_hash(p: Path) -> str:
    from .filehash import file_content_hash

    return file_content_hash(p)


_effective: dict[type, Callable[[BaseModel], dict] | None] = {}


def _effective_of(model: type) -> Callable[[BaseModel], dict] | None:
    """The model class's ``effective`` method or None (memoised: a failing getattr on a model is slow)."""
    if model not in _effective:
        fn = getattr(model, "effective", None)
        _effective[model] = fn if callable(fn) else None
    return _effective[model]


def canonical_params(params: BaseModel, file_hash: Callable[[Path], str] | None = None, effective: bool = True) -> dict[str, Any]:
    """The params as canonical JSON: every param, defaults included, input-file params as
    ``{path, sha256 of content}``.

    ``effective``: when the params model defines ``effective() -> dict`` (a node whose result depends on
    more than the plain values, e.g. a preset filled in unless a param is set explicitly), that dict,
    which must hold exactly what the node's result depends on, replaces the plain values."""
    fh = file_hash or _default_file_hash
    eff = _effective_of(type(params)) if effective else None
    data = eff(params) if eff is not None else params.model_dump(mode="json")
    for name in input_path_fields(type(params)):
        value = getattr(params, name)
        if value is None:
            continue
        p = Path(value)
        if p.is_file():
            data[name] = {"path": str(p.resolve()), "sha256": fh(p)}
        elif p.is_dir():
            items = {str(f.relative_to(p)): fh(f) for f in sorted(p.rglob("*")) if f.is_file()}
            data[name] = {"path": str(p.resolve()), "sha256": hash_json(items)}
        else:
            raise CacheError(f"param '{name}': input file {p} does not exist, cannot compute the cache key")
    return data


def node_key(spec: NodeSpec, params: BaseModel, input_fingerprints: dict[str, str | None],
             file_hash: Callable[[Path], str] | None = None, code_memo: Memo | None = None) -> str:
    """The cache key of one node evaluation: SHA-256 of the format line, the code fingerprint and the
    canonical JSON of ``[type, version, effective params, input fingerprints]``, one per line."""
    code = spec.__dict__.get("_code_fingerprint") or code_fingerprint(spec, code_memo)
    data = _dumps([spec.type, spec.version, canonical_params(params, file_hash), input_fingerprints])
    return hashlib.sha256(f"{_HEADER}\n{code}\n{data}".encode()).hexdigest()


_HEADER = f"tbha-graph cache key, format {CACHE_FORMAT}"
_dumps = json.JSONEncoder(sort_keys=True, separators=(",", ":"), ensure_ascii=False, allow_nan=True).encode
