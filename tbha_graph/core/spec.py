"""Pipeline declarations: what a pipeline file (or the Python API) says, before any checking.

A pipeline file::

    description: what it does
    jobs: 2                       # optional; nodes run at once by default (tbha-run --jobs overrides)
    extends: base.yaml            # optional; nodes are overridden by id
    vars: {video: clip.mp4}       # ${video} is substituted in strings; --var video=... overrides
    nodes:
      <id>: {type: stage.name, params: {...}, inputs: {port: <node id>.<port>}}
    outputs:
      <file name>: <node id>.<port>

Merging with ``extends`` (and study variants): a child node with a new id is added; one with an
existing id overrides fields: ``params`` and ``inputs`` are merged key by key, and a changed ``type``
drops the parent's params (they belonged to the old type) but keeps its wiring; ``inputs: {port: null}``
disconnects an inherited input. ``remove: true`` deletes a node. ``outputs`` and ``vars`` merge by key.
"""
from __future__ import annotations

import copy
import re
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from .errors import Location, PipelineError, PipelineErrors, did_you_mean
from .node import NodeSpec
from .yamlfile import LocatedDict, load_yaml

_VAR = re.compile(r"\$\{([A-Za-z_][A-Za-z0-9_]*)\}")
TOP_KEYS = ("description", "jobs", "extends", "vars", "nodes", "outputs")
NODE_KEYS = ("type", "params", "inputs", "remove")


@dataclass
class Value:
    """A param value with where it was written (``base_dir`` resolves relative input paths)."""

    value: Any
    loc: Location
    base_dir: Path


@dataclass
class NodeDecl:
    id: str
    type: str | NodeSpec
    loc: Location
    type_loc: Location
    params: dict[str, Value] = field(default_factory=dict)
    inputs: dict[str, Value] = field(default_factory=dict)


@dataclass
class PipelineDecl:
    """A pipeline as declared: nodes by id, outputs (file name -> ``node.port``), vars."""

    path: str = "<python>"
    description: str = ""
    jobs: int | None = None  # nodes the local executor runs at once unless told otherwise; None: 1
    nodes: dict[str, NodeDecl] = field(default_factory=dict)
    outputs: dict[str, Value] = field(default_factory=dict)
    vars: dict[str, Value] = field(default_factory=dict)
    files: list[str] = field(default_factory=list)

    def copy(self) -> "PipelineDecl":
        """An independent copy (what checking and overriding change); node types are shared, values
        that are lists or dicts are copied deeply, the rest (str, numbers, locations) is immutable."""
        return PipelineDecl(
            path=self.path,
            description=self.description,
            jobs=self.jobs,
            nodes={k: NodeDecl(n.id, n.type, n.loc, n.type_loc, _copy_values(n.params), _copy_values(n.inputs))
                   for k, n in self.nodes.items()},
            outputs=_copy_values(self.outputs),
            vars=_copy_values(self.vars),
            files=list(self.files),
        )


def _copy_values(values: dict[str, Value]) -> dict[str, Value]:
    return {k: Value(copy.deepcopy(v.value) if isinstance(v.value, (list, dict)) else v.value, v.loc, v.base_dir)
            for k, v in values.items()}


# ---------------------------------------------------------------------------------------------
# reading files
# ---------------------------------------------------------------------------------------------
def _loc(d: Any, key: Any, default: Location) -> Location:
    return d.loc_of(key) if isinstance(d, LocatedDict) else default


def _check_keys(d: LocatedDict, allowed: tuple[str, ...], what: str, errors: list[PipelineError]) -> None:
    for k in d:
        if k not in allowed:
            errors.append(
                PipelineError(
                    f"unknown key '{k}' in {what}{did_you_mean(str(k), allowed)}",
                    location=d.loc_of(k),
                    hint=f"allowed keys: {', '.join(allowed)}",
                )
            )


def merge_node_override(decl: PipelineDecl, node_id: str, body: Any, loc: Location, base_dir: Path, errors: list[PipelineError]) -> None:
    """Apply one ``nodes: {id: body}`` entry (new node or override of an existing one) to ``decl``."""
    if not isinstance(body, dict):
        errors.append(PipelineError(f"node '{node_id}' must be a mapping with 'type', 'params', 'inputs'", location=loc))
        return
    if isinstance(body, LocatedDict):
        _check_keys(body, NODE_KEYS, f"node '{node_id}'", errors)
    if body.get("remove"):
        decl.nodes.pop(node_id, None)
        return
    existing = decl.nodes.get(node_id)
    new_type = body.get("type")
    if existing is None:
        if new_type is None:
            errors.append(PipelineError(f"node '{node_id}' has no 'type'", location=loc, hint="add `type: stage.name` (see `tbha-graph nodes`)"))
            return
        existing = NodeDecl(id=node_id, type=new_type, loc=loc, type_loc=_loc(body, "type", loc))
        decl.nodes[node_id] = existing
    elif new_type is not None and new_type != existing.type:
        existing.type = new_type
        existing.type_loc = _loc(body, "type", loc)
        existing.params = {}
    for section in ("params", "inputs"):
        sub = body.get(section)
        if sub is None:
            continue
        if not isinstance(sub, dict):
            errors.append(PipelineError(f"node '{node_id}': '{section}' must be a mapping", location=_loc(body, section, loc)))
            continue
        target = getattr(existing, section)
        for k, v in sub.items():
            if v is None and section == "inputs":  # `inputs: {port: null}` disconnects an inherited input
                target.pop(str(k), None)
                continue
            target[str(k)] = Value(v, _loc(sub, k, loc), base_dir)


def _read_file(path: Path, errors: list[PipelineError], chain: tuple[Path, ...]) -> PipelineDecl:
    data, problems = load_yaml(path)
    errors.extend(problems)
    decl = PipelineDecl(path=str(path))
    if data is None:
        return decl
    here = Location(str(path), 1, 1)
    if not isinstance(data, LocatedDict):
        errors.append(PipelineError("a pipeline file must be a mapping with 'nodes' and 'outputs'", location=here))
        return decl
    _check_keys(data, TOP_KEYS, "the pipeline file", errors)
    base_dir = path.parent
    if "extends" in data:
        parent = Path(str(data["extends"]))
        parent = parent if parent.is_absolute() else (base_dir / parent)
        try:
            parent = parent.resolve()
        except (OSError, ValueError):  # e.g. a NUL character in the name
            parent = Path(str(parent).replace("\0", "\\0"))
        if parent in chain:
            errors.append(PipelineError(f"'extends' forms a cycle: {' -> '.join(str(p) for p in chain + (parent,))}", location=data.loc_of("extends")))
        elif not parent.is_file():
            errors.append(PipelineError(f"'extends' names a file that does not exist: {parent}", location=data.loc_of("extends")))
        else:
            decl = _read_file(parent, errors, chain + (parent,))
            decl.path = str(path)
    decl.files.append(str(path))
    if data.get("description"):
        decl.description = str(data["description"])
    if "jobs" in data:
        j = data["jobs"]
        if isinstance(j, bool) or not isinstance(j, int) or j < 1:
            errors.append(PipelineError(f"'jobs' must be a whole number of at least 1, not {j!r}", location=data.loc_of("jobs"),
                                        hint="jobs: 2 runs independent nodes at the same time; leave it out for one after another"))
        else:
            decl.jobs = j
    for section in ("vars", "nodes", "outputs"):
        sub = data.get(section)
        if sub is None:
            continue
        if not isinstance(sub, dict):
            errors.append(PipelineError(f"'{section}' must be a mapping", location=data.loc_of(section)))
            continue
        for k, v in sub.items():
            loc = _loc(sub, k, here)
            if section == "nodes":
                merge_node_override(decl, str(k), v, loc, base_dir, errors)
            else:
                getattr(decl, section)[str(k)] = Value(v, loc, base_dir)
    return decl


def read_pipeline(path: str | Path) -> PipelineDecl:
    """Read a pipeline file (following ``extends``); raises :class:`PipelineErrors` with every problem."""
    path = Path(path)
    errors: list[PipelineError] = []
    if not path.is_file():
        raise PipelineErrors([PipelineError(f"pipeline file not found: {path}", hint="check the path; pipelines/ holds the bundled ones")])
    decl = _read_file(path.resolve(), errors, (path.resolve(),))
    decl.path = str(path)
    if not errors and not decl.nodes:  # an empty or truncated file must not "run" successfully doing nothing
        errors.append(PipelineError("the pipeline has no nodes", location=Location(str(path.resolve()), 1),
                                    hint="a pipeline file needs a 'nodes:' section (or 'extends:' a file that has one)"))
    if errors:
        raise PipelineErrors(errors)
    return decl


# ---------------------------------------------------------------------------------------------
# vars and command-line overrides
# ---------------------------------------------------------------------------------------------
def parse_assignment(text: str, what: str) -> tuple[str, Any]:
    """``"a.b=3"`` -> ``("a.b", 3)``; the value is parsed as a YAML scalar/flow value (safely)."""
    if "=" not in text:
        raise PipelineError(f"{what} '{text}' must look like name=value")
    name, raw = text.split("=", 1)
    try:
        value = yaml.safe_load(raw) if raw.strip() else ""
    except yaml.YAMLError:
        value = raw
    except RecursionError:
        value = None
    from .yamlfile import MAX_DEPTH, nesting_depth

    if value is None and raw.strip() and raw.strip() not in ("null", "~", "Null", "NULL") or nesting_depth(value) > MAX_DEPTH:
        raise PipelineError(f"{what} '{name.strip()}': the value is nested too deeply (more than {MAX_DEPTH} levels)")
    return name.strip(), value


def apply_vars(decl: PipelineDecl, overrides: dict[str, Any] | None = None, base_dir: Path | None = None,
               source: str = "<command line>") -> list[PipelineError]:
    """Substitute ``${name}`` in every string of params and inputs; returns problems (unknown vars).

    ``overrides`` (``--var``) resolve relative input paths against ``base_dir`` (default: the current
    folder), since they were written there."""
    cwd = base_dir or Path.cwd()
    values: dict[str, Value] = dict(decl.vars)
    errors: list[PipelineError] = []
    known = set(decl.vars) | _referenced_vars(decl)
    for k, v in (overrides or {}).items():
        if k not in known:  # a misspelt --var must not silently leave the default (e.g. the sample video) in place
            errors.append(PipelineError(
                f"unknown variable '{k}'{did_you_mean(k, known)}: the pipeline neither declares nor uses it",
                location=Location(source),
                hint=f"the pipeline's variables: {', '.join(sorted(known)) or '(none)'}",
            ))
            continue
        values[k] = Value(v, Location(source), cwd)

    def subst(v: Value) -> Value:
        if isinstance(v.value, str):
            m = _VAR.fullmatch(v.value)
            if m and m.group(1) in values:  # a whole-string var keeps the var's type and its base dir
                src = values[m.group(1)]
                return Value(src.value, v.loc, src.base_dir)
            def repl(mm: re.Match) -> str:
                name = mm.group(1)
                if name not in values:
                    errors.append(PipelineError(f"unknown variable '${{{name}}}'{did_you_mean(name, values)}", location=v.loc, hint="define it under 'vars:' or pass --var NAME=VALUE"))
                    return mm.group(0)
                return str(values[name].value)
            return Value(_VAR.sub(repl, v.value), v.loc, v.base_dir)
        if isinstance(v.value, (list, dict)):
            return Value(_subst_deep(v.value, values, v.loc, errors), v.loc, v.base_dir)
        return v

    for n in decl.nodes.values():
        n.params = {k: subst(v) for k, v in n.params.items()}
        n.inputs = {k: subst(v) for k, v in n.inputs.items()}
    return errors


def _referenced_vars(decl: PipelineDecl) -> set[str]:
    """Names of every ``${name}`` the nodes' params and inputs use."""
    found: set[str] = set()

    def walk(obj: Any) -> None:
        if isinstance(obj, Value):
            walk(obj.value)
        elif isinstance(obj, str):
            found.update(m.group(1) for m in _VAR.finditer(obj))
        elif isinstance(obj, list):
            for x in obj:
                walk(x)
        elif isinstance(obj, dict):
            for x in obj.values():
                walk(x)

    for n in decl.nodes.values():
        walk(n.params)
        walk(n.inputs)
    return found


def _subst_deep(obj: Any, values: dict[str, Value], loc: Location, errors: list[PipelineError]) -> Any:
    if isinstance(obj, str):
        def repl(mm: re.Match) -> str:
            if mm.group(1) not in values:
                errors.append(PipelineError(f"unknown variable '${{{mm.group(1)}}}'{did_you_mean(mm.group(1), values)}", location=loc))
                return mm.group(0)
            return str(values[mm.group(1)].value)
        return _VAR.sub(repl, obj)
    if isinstance(obj, list):
        return [_subst_deep(x, values, loc, errors) for x in obj]
    if isinstance(obj, dict):
        return {k: _subst_deep(v, values, loc, errors) for k, v in obj.items()}
    return obj


def apply_sets(decl: PipelineDecl, sets: dict[str, Any], base_dir: Path | None = None,
               source: str = "<command line>") -> list[PipelineError]:
    """Apply ``--set node.param=value`` (``node.param.sub=value`` for nested params)."""
    errors: list[PipelineError] = []
    cwd = base_dir or Path.cwd()
    loc = Location(source)
    for name, value in sets.items():
        parts = name.split(".")
        if len(parts) < 2:
            errors.append(PipelineError(f"--set '{name}' must be NODE.PARAM=VALUE", location=loc))
            continue
        node_id, param = parts[0], parts[1]
        if node_id not in decl.nodes:
            errors.append(PipelineError(f"--set names unknown node '{node_id}'{did_you_mean(node_id, decl.nodes)}", location=loc, hint=f"nodes: {', '.join(decl.nodes)}"))
            continue
        params = decl.nodes[node_id].params
        if len(parts) == 2:
            params[param] = Value(value, loc, cwd)
        else:
            old = params.get(param)
            tree = copy.deepcopy(old.value) if old is not None and isinstance(old.value, dict) else {}
            cur = tree
            for p in parts[2:-1]:
                cur = cur.setdefault(p, {})
            cur[parts[-1]] = value
            params[param] = Value(tree, loc, cwd)
    return errors
