"""``tbha-graph``: inspect nodes and pipelines, run studies, manage the cache.

    tbha-graph nodes [TYPE]          list node types, or one type's ports, params and docstring
    tbha-graph validate FILE...      check pipelines without running (all problems at once)
    tbha-graph show FILE [--format text|mermaid|dot] [--png OUT.png]
    tbha-graph show TYPE             one node type's full documentation (ports, params, docstring)
    tbha-graph schema                JSON Schema of pipeline files for editors
    tbha-graph run FILE ...          same as tbha-run
    tbha-graph study STUDY.yaml      run an ablation study, write results.csv / results.md
    tbha-graph batch FILE TAKES      run one pipeline over many takes (locally or on Dask)
    tbha-graph cache info|clear|gc   the content-addressed cache
"""
from __future__ import annotations

import argparse
import json
import sys
import textwrap
from pathlib import Path

# the framework is imported inside the commands, so that `tbha-graph --help` starts fast
from .common import EXIT_FAILED, EXIT_OK, JOBS_HELP, add_run_arguments, guarded, parse_assignments, positive_int


def _registry(args):
    from ..core.registry import default_registry, load_plugin_modules

    reg = default_registry()
    if getattr(args, "plugin", None):
        load_plugin_modules(args.plugin, reg)
    return reg


def cmd_nodes(args) -> int:
    reg = _registry(args)
    if args.type:
        print(describe_node(reg.get(args.type)))
        return EXIT_OK
    for spec in reg.specs():
        print(f"{spec.type:<32} {spec.summary}")
        fields = spec.params.model_fields
        if fields:
            text = "; ".join(param_brief(n, f) for n, f in fields.items())
            print(textwrap.fill(text, width=110, initial_indent="    params: ", subsequent_indent="            "))
    print("\n`tbha-graph show TYPE` (or `tbha-graph nodes TYPE`) prints a node's full documentation", file=sys.stderr)
    for f in reg.failures:
        print(f, file=sys.stderr)
    return EXIT_OK


def type_name(ann) -> str:
    """A param's annotation as a reader would write it: int, float | null, one of 'a', 'b', list of str."""
    import types
    import typing

    from pydantic import BaseModel

    origin, args = typing.get_origin(ann), typing.get_args(ann)
    if origin is typing.Annotated:
        return type_name(args[0])
    if origin in (typing.Union, types.UnionType):
        names = [type_name(a) for a in args if a is not type(None)]
        return " | ".join(names) + (" | null" if type(None) in args else "")
    if origin is typing.Literal:
        return "one of " + ", ".join(json.dumps(a) for a in args)
    if origin in (list, tuple, set, frozenset):
        inner = [type_name(a) for a in args if a is not Ellipsis]
        return f"{origin.__name__} of {', '.join(inner)}" if inner else origin.__name__
    if origin is dict:
        return f"mapping {type_name(args[0])} -> {type_name(args[1])}" if len(args) == 2 else "mapping"
    if isinstance(ann, type):
        if issubclass(ann, BaseModel):
            return f"{ann.__name__} (mapping)"
        if ann.__module__ == "pathlib" or ann.__name__.endswith("Path"):
            return "path"
        return ann.__name__
    return str(ann).replace("typing.", "")


_BOUNDS = {"Ge": ">=", "Gt": ">", "Le": "<=", "Lt": "<", "MultipleOf": "multiple of", "MinLen": "at least", "MaxLen": "at most"}


def constraints(f) -> str:
    out = []
    for m in f.metadata:
        kind = type(m).__name__
        if kind in _BOUNDS:
            value = next(iter(vars(m).values()), None) if hasattr(m, "__dict__") else getattr(m, next(iter(m.__dataclass_fields__)))
            out.append(f"{_BOUNDS[kind]} {value}" + (" items" if kind in ("MinLen", "MaxLen") else ""))
    return ", ".join(out)


def _default_text(f) -> str:
    if f.is_required():
        return "required"
    from pydantic import BaseModel

    d = f.get_default(call_default_factory=True)
    if isinstance(d, BaseModel):
        d = d.model_dump(mode="json")
    return json.dumps(d, default=str)


def _unit(f) -> str:
    extra = f.json_schema_extra if isinstance(f.json_schema_extra, dict) else {}
    return str(extra.get("unit") or "")


def param_brief(name: str, f) -> str:
    unit = _unit(f)
    d = _default_text(f)
    return f"{name}: {type_name(f.annotation)}" + (" (required)" if d == "required" else f" = {d}") + (f" {unit}" if unit else "")


def describe_node(spec) -> str:
    lines = [f"{spec.type}  (version {spec.version}, from {spec.source or '?'}, {spec.module})", ""]
    lines += ["  " + ln for ln in (spec.doc or "(no description)").splitlines()]
    lines += ["", "inputs:"]
    for name, i in spec.inputs.items():
        lines.append(f"  {name:<18} {i.type.describe()}{'' if i.required else '  (optional)'}{('  ' + i.type.doc) if getattr(i.type, 'doc', '') else ''}")
    if not spec.inputs:
        lines.append("  (none)")
    lines.append("outputs:")
    for name, t in spec.outputs.items():
        lines.append(f"  {name:<18} {t.describe()}{('  ' + t.doc) if getattr(t, 'doc', '') else ''}")
    lines.append("params:  name  type  default  [unit]  (allowed values)")
    fields = spec.params.model_fields
    if not fields:
        lines.append("  (none)")
    for name, f in fields.items():
        d = _default_text(f)
        default = "required" if d == "required" else f"default {d}"
        unit = f" [{_unit(f)}]" if _unit(f) else ""
        cons = constraints(f)
        lines.append(f"  {name:<18} {type_name(f.annotation)}  {default}{unit}{('  (' + cons + ')') if cons else ''}")
        if f.description:
            lines.append(textwrap.fill(f.description, width=110, initial_indent=f"  {'':<18}   ", subsequent_indent=f"  {'':<18}   "))
    return "\n".join(lines)


def cmd_validate(args) -> int:
    from ..core.runner import load_graph

    reg = _registry(args)
    status = EXIT_OK
    for path in args.files:
        try:
            g = load_graph(path, sets=parse_assignments(args.set, "--set"), vars=parse_assignments(args.var, "--var"), registry=reg)
            print(f"{path}: ok ({len(g.nodes)} nodes, {len(g.outputs)} outputs)")
        except Exception as e:  # noqa: BLE001 - report each file and go on
            from ..core.errors import TbhaError

            if not isinstance(e, TbhaError):
                raise
            print(f"{path}: {e.format()}", file=sys.stderr)
            status = 2
    return status


def cmd_show(args) -> int:
    from ..core import show
    from ..core.runner import load_graph

    if not Path(args.file).exists():
        reg = _registry(args)
        if args.file in reg.types():  # `tbha-graph show TYPE`: the node's full documentation
            print(describe_node(reg.get(args.file)))
            return EXIT_OK
        from ..core.errors import TbhaError, did_you_mean

        raise TbhaError(f"'{args.file}' is neither a pipeline file nor a node type{did_you_mean(args.file, [*reg.types()])}",
                        hint="give a pipeline file (pipelines/default.yaml) or a node type (`tbha-graph nodes` lists them)")
    g = load_graph(args.file, sets=parse_assignments(args.set, "--set"), vars=parse_assignments(args.var, "--var"), registry=_registry(args))
    text = {"text": show.as_text, "mermaid": show.as_mermaid, "dot": show.as_dot}[args.format](g)
    print(text)
    if args.png:
        show.save_png(g, Path(args.png))
        print(f"wrote {args.png}", file=sys.stderr)
    return EXIT_OK


def cmd_schema(args) -> int:
    from ..core.schema import pipeline_schema

    text = json.dumps(pipeline_schema(_registry(args)), indent=2)
    if args.out:
        Path(args.out).write_text(text)
    else:
        print(text)
    return EXIT_OK


def cmd_study(args) -> int:
    from ..core.cache import Cache
    from ..core.progress import Reporter
    from ..core.study import run_study, to_markdown

    _registry(args)
    out = Path(args.out) if args.out else Path("runs") / "studies" / Path(args.study).stem
    cache = Cache(args.cache_dir) if args.cache_dir else Cache()
    rows = run_study(args.study, out, cache=cache, reporter=Reporter(quiet=args.quiet), executor=args.executor,
                     sets=parse_assignments(args.set, "--set"), jobs=args.jobs)
    print(to_markdown(rows))
    print(f"tables: {out / 'results.csv'}, {out / 'results.md'}; chart: {out / 'results.png'}")
    return EXIT_OK if all(r["status"] == "ok" for r in rows) else EXIT_FAILED


def cmd_batch(args) -> int:
    from ..core.batch import collect_takes, run_batch
    from ..core.cache import Cache
    from ..core.progress import Reporter
    from ..core.study import to_markdown

    _registry(args)
    takes = collect_takes(args.inputs)
    out = Path(args.out) if args.out else Path("runs") / "batch" / Path(args.pipeline).stem
    cache = None if args.no_cache else (Cache(args.cache_dir) if args.cache_dir else Cache())
    executor = "dask" if args.scheduler else args.executor
    print(f"batch: {len(takes)} take(s) of {args.pipeline}, executor {executor}", file=sys.stderr)
    rows = run_batch(args.pipeline, takes, out, var_name=args.var_name, cache=cache, executor=executor,
                     scheduler=args.scheduler, workers=args.workers, reporter=Reporter(quiet=args.quiet),
                     plugins=tuple(args.plugin or ()), vars=parse_assignments(args.var, "--var"),
                     sets=parse_assignments(args.set, "--set"), jobs=args.jobs)
    print(to_markdown(rows, ("take", "status", "frames", "wall_s")))
    print(f"summary: {out / 'summary.csv'}, {out / 'summary.md'}")
    return EXIT_OK if all(r["status"] == "ok" for r in rows) else EXIT_FAILED


def cmd_cache(args) -> int:
    from ..core.cache import Cache

    cache = Cache(args.cache_dir) if args.cache_dir else Cache()
    if args.action == "info":
        info = cache.info()
        print(f"cache folder: {info['root']}\nentries: {info['entries']}\nsize: {info['bytes'] / 1e6:.1f} MB\nunfinished writes: {info['tmp_folders']}")
    elif args.action == "clear":
        print(f"removed {cache.clear()} entries from {cache.root}")
    else:
        max_bytes = int(float(args.max_size_mb) * 1e6) if args.max_size_mb else None
        print(json.dumps(cache.gc(older_than_days=args.older_than_days, max_bytes=max_bytes)))
    return EXIT_OK


def cmd_run(args) -> int:
    from .run import run_command

    return run_command(args)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(allow_abbrev=False, prog="tbha-graph", description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("nodes", allow_abbrev=False, help="list node types or describe one")
    s.add_argument("type", nargs="?")
    s.add_argument("--plugin", action="append")
    s.set_defaults(fn=cmd_nodes)

    s = sub.add_parser("validate", allow_abbrev=False, help="check pipeline files without running them")
    s.add_argument("files", nargs="+")
    s.add_argument("--set", action="append")
    s.add_argument("--var", action="append")
    s.add_argument("--plugin", action="append")
    s.set_defaults(fn=cmd_validate)

    s = sub.add_parser("show", allow_abbrev=False, help="print a pipeline's DAG (text, Mermaid, DOT; optionally a PNG), or a node type's documentation")
    s.add_argument("file", help="pipeline file, or a node type such as segment.hierarchical")
    s.add_argument("--format", choices=["text", "mermaid", "dot"], default="text")
    s.add_argument("--png", help="also draw the DAG into this PNG")
    s.add_argument("--set", action="append")
    s.add_argument("--var", action="append")
    s.add_argument("--plugin", action="append")
    s.set_defaults(fn=cmd_show)

    s = sub.add_parser("schema", allow_abbrev=False, help="JSON Schema of pipeline files (for editors)")
    s.add_argument("--out", help="write to this file instead of stdout")
    s.add_argument("--plugin", action="append")
    s.set_defaults(fn=cmd_schema)

    s = sub.add_parser("run", allow_abbrev=False, help="run a pipeline (same as tbha-run)")
    add_run_arguments(s)
    s.set_defaults(fn=cmd_run)

    s = sub.add_parser("study", allow_abbrev=False, help="run an ablation study")
    s.add_argument("study")
    s.add_argument("--set", "-s", action="append", metavar="NODE.PARAM=VALUE", help="override a param in every run (repeatable), e.g. a shorter frame range")
    s.add_argument("--out", "-o")
    s.add_argument("--cache-dir")
    s.add_argument("--executor", choices=["local", "dask"], default="local")
    s.add_argument("--jobs", "-j", type=positive_int, metavar="N", help=JOBS_HELP)
    s.add_argument("--plugin", action="append")
    s.add_argument("--quiet", "-q", action="store_true")
    s.set_defaults(fn=cmd_study)

    s = sub.add_parser("batch", allow_abbrev=False, help="run one pipeline over many takes (a glob, a folder or a YAML list)")
    s.add_argument("pipeline")
    s.add_argument("inputs", help="glob ('takes/*.mp4'), folder, or YAML file with 'takes:'")
    s.add_argument("--var-name", default="video", help="pipeline variable bound to each take's path (default: video)")
    s.add_argument("--set", "-s", action="append", metavar="NODE.PARAM=VALUE", help="override a param for every take (repeatable)")
    s.add_argument("--var", "-v", action="append", metavar="NAME=VALUE", help="set a pipeline variable for every take (repeatable)")
    s.add_argument("--out", "-o")
    s.add_argument("--executor", choices=["local", "dask"], default="local")
    s.add_argument("--scheduler", metavar="tcp://HOST:PORT")
    s.add_argument("--workers", type=int)
    s.add_argument("--jobs", "-j", type=positive_int, metavar="N", help=JOBS_HELP + " (local executor)")
    s.add_argument("--cache-dir")
    s.add_argument("--no-cache", action="store_true")
    s.add_argument("--plugin", action="append")
    s.add_argument("--quiet", "-q", action="store_true")
    s.set_defaults(fn=cmd_batch)

    s = sub.add_parser("cache", allow_abbrev=False, help="inspect or clean the cache")
    s.add_argument("action", choices=["info", "clear", "gc"])
    s.add_argument("--cache-dir")
    s.add_argument("--older-than-days", type=float, help="gc: remove entries unused for this long")
    s.add_argument("--max-size-mb", type=float, help="gc: remove least recently used entries beyond this size")
    s.set_defaults(fn=cmd_cache)
    return p


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return guarded(lambda: args.fn(args))


if __name__ == "__main__":
    sys.exit(main())
