"""Safe YAML loading that remembers where every key was written (file, line, column).

Mappings load as :class:`LocatedDict`, a plain ``dict`` plus ``locs[key] -> Location`` and ``loc`` (the
mapping itself). Duplicate keys are reported (PyYAML silently keeps the last). Only YAML's safe types
are constructed: nothing in a pipeline file is ever evaluated as code.
"""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import yaml

from .errors import Location, PipelineError, TbhaError


class LocatedDict(dict):
    """A dict that knows the location of each key (``locs``) and of itself (``loc``)."""

    loc: Location
    locs: dict[Any, Location]

    def loc_of(self, key: Any) -> Location:
        return self.locs.get(key, self.loc)


def _make_loader(filename: str, errors: list[PipelineError]) -> type[yaml.SafeLoader]:
    class Loader(yaml.SafeLoader):
        pass

    def construct_mapping(loader: yaml.SafeLoader, node: yaml.MappingNode) -> LocatedDict:
        loader.flatten_mapping(node)
        out = LocatedDict()
        out.loc = Location(filename, node.start_mark.line + 1, node.start_mark.column + 1)
        out.locs = {}
        for key_node, value_node in node.value:
            key = loader.construct_object(key_node, deep=True)
            loc = Location(filename, key_node.start_mark.line + 1, key_node.start_mark.column + 1)
            if isinstance(key, (dict, list)):  # '? [a, b]' or '? {a: 1}': valid YAML, unhashable in Python
                errors.append(PipelineError(f"a key must be a name, not a {'mapping' if isinstance(key, dict) else 'list'}", location=loc))
                continue
            if key in out:
                errors.append(
                    PipelineError(
                        f"duplicate key '{key}' (first written at line {out.locs[key].line})",
                        location=loc,
                        hint="each node id and each key may appear once per mapping; rename or merge them",
                    )
                )
                continue
            out[key] = loader.construct_object(value_node, deep=True)
            out.locs[key] = loc
        return out

    Loader.add_constructor(yaml.resolver.BaseResolver.DEFAULT_MAPPING_TAG, construct_mapping)
    return Loader


def load_yaml(path: str | Path, text: str | None = None) -> tuple[Any, list[PipelineError]]:
    """Load a YAML file; returns ``(data, problems)``. A syntax error is returned as one problem with
    its line and column; ``data`` is then ``None``."""
    path = Path(path)
    errors: list[PipelineError] = []
    if text is None:
        try:
            text = path.read_text(encoding="utf-8")
        except FileNotFoundError:
            return None, [PipelineError(f"file not found: {path}", hint="check the path (relative paths start from the current folder)")]
        except UnicodeDecodeError as e:
            line = path.read_bytes()[: e.start].count(b"\n") + 1
            return None, [PipelineError(f"not UTF-8 text: byte {e.object[e.start]:#04x} cannot be decoded", location=Location(str(path), line),
                                        hint="save the file as UTF-8")]
        except OSError as e:
            return None, [PipelineError(f"cannot read {path}: {e}")]
    try:
        data = yaml.load(text, Loader=_make_loader(str(path), errors))  # noqa: S506 - SafeLoader subclass
    except yaml.MarkedYAMLError as e:
        mark = e.problem_mark or e.context_mark
        loc = Location(str(path), mark.line + 1, mark.column + 1) if mark else Location(str(path))
        snippet = ""
        if mark is not None:
            lines = text.splitlines()
            if 0 <= mark.line < len(lines):
                snippet = f"\n    {lines[mark.line]}\n    {' ' * mark.column}^"
        return None, [PipelineError(f"YAML syntax error: {e.problem or e}{snippet}", location=loc)]
    except yaml.reader.ReaderError as e:  # a control character: no mark, only a character position
        line = text.count("\n", 0, e.position) + 1
        return None, [PipelineError(f"YAML error: character {e.character!r} is not allowed in a YAML file", location=Location(str(path), line))]
    except yaml.YAMLError as e:
        return None, [PipelineError(f"YAML error: {e}", location=Location(str(path)))]
    except RecursionError:
        return None, [_too_deep(path)]
    if nesting_depth(data) > MAX_DEPTH:
        return None, [_too_deep(path)]
    return data, errors


def read_data_file(path: str | Path, what: str, error: type[TbhaError] = TbhaError) -> Any:
    """The content of a small data file (camera, bone lengths, suit, mapping): JSON when the suffix is
    ``.json``, else YAML loaded safely by :func:`load_yaml` (duplicate keys and bad bytes are errors).

    Raises ``error`` (a :class:`TbhaError` class, e.g. ``NodeError``) naming ``what``, the file and the
    line (and column) of the first problem: not UTF-8, a syntax error, a duplicate key.
    """
    path = Path(path)
    if path.suffix.lower() != ".json":
        data, problems = load_yaml(path)
        if problems:
            p = problems[0]
            raise error(f"{what}: {p.message}", location=p.location or Location(str(path)), hint=p.hint)
        return data
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise error(f"{what}: not UTF-8 text (byte {e.start}: {e.object[e.start]:#04x})", location=Location(str(path)),
                    hint="save the file as UTF-8") from None
    except OSError as e:
        raise error(f"{what}: cannot be read: {e.strerror or e}", location=Location(str(path))) from None
    try:
        return json.loads(text)
    except json.JSONDecodeError as e:
        raise error(f"invalid JSON ({what}): {e.msg}", location=Location(str(path), e.lineno, e.colno)) from None


MAX_DEPTH = 64  # nesting levels of lists/mappings; deeper files are refused (no real file comes close)


def _too_deep(path: Path) -> PipelineError:
    return PipelineError(f"the YAML is nested too deeply (more than {MAX_DEPTH} levels of lists or mappings)",
                         location=Location(str(path)), hint="flatten the file; no pipeline, suit or body file needs this depth")


def nesting_depth(obj: Any, limit: int = MAX_DEPTH + 1) -> int:
    """Depth of nested lists/dicts, counted without recursion and stopping at ``limit``."""
    depth, level = 0, [obj]
    while level and depth < limit:
        nxt = []
        for x in level:
            if isinstance(x, dict):
                nxt.extend(x.values())
            elif isinstance(x, list):
                nxt.extend(x)
        if not nxt and not any(isinstance(x, (dict, list)) for x in level):
            break
        depth += 1
        level = nxt
    return depth
