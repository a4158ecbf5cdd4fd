"""Studies (ablations): one base pipeline, named variants, optional several inputs, one table.

A study file::

    description: compare segmenters
    base: ../pipelines/default.yaml
    metrics: metrics.json          # the pipeline output holding the figures (default: metrics.json)
    outputs: [metrics.json]        # optional: produce only these outputs (skip videos and plots)
    columns: [mpjpe_mm, lag_ms]    # optional: the metrics shown (default: every top-level figure)
    inputs:                        # optional; each is a set of vars / --set overrides (relative
                                   # paths in them start from the study file's folder)
      sample: {vars: {video: ../data/sample/sample.mp4}}
    variants:
      seed: {}                     # the base as it is
      threshold:
        nodes: {segment: {type: segment.chroma_threshold}}   # merged like `extends`
        set: {track.gate_px: 40}                           # like --set

Every (variant, input) runs on the shared cache, so what variants have in common is computed once.
A failing variant is recorded with its error and the others still run. Results: ``results.csv`` and
``results.md`` (variant, input, status, wall time, every metric), ``results.png`` (the figures charted, a panel
each: :mod:`.study_chart`), plus a run directory per pair.
"""
from __future__ import annotations

import csv
import io
import time
from pathlib import Path
from typing import Any

from .cache import Cache
from .errors import Location, PipelineError, PipelineErrors, TbhaError
from .progress import Reporter
from .registry import Registry
from .runner import load_graph, run_graph
from .spec import merge_node_override, read_pipeline
from .study_chart import write_chart
from .yamlfile import LocatedDict, load_yaml

STUDY_KEYS = ("description", "base", "metrics", "outputs", "columns", "inputs", "variants")


def _flatten(d: Any, prefix: str = "") -> dict[str, Any]:
    """``{"a": {"b": 1}}`` -> ``{"a.b": 1}`` (metrics may be nested)."""
    if isinstance(d, dict):
        out: dict[str, Any] = {}
        for k, v in d.items():
            out.update(_flatten(v, f"{prefix}{k}."))
        return out
    return {prefix[:-1]: d}


def metric_columns(metrics: Any, columns: list[str] | None) -> dict[str, Any]:
    """The table cells of a metrics dict: the named ``columns`` (dotted paths into nested dicts), or
    every top-level scalar when none are named."""
    if not isinstance(metrics, dict):
        return {}
    flat = _flatten(metrics)
    if columns:
        return {c: flat.get(c) for c in columns}
    return {k: v for k, v in metrics.items() if not isinstance(v, (dict, list))}


def read_study(path: Path) -> dict[str, Any]:
    data, problems = load_yaml(path)
    if problems:
        raise PipelineErrors(problems)
    errors: list[PipelineError] = []
    if not isinstance(data, LocatedDict):
        raise PipelineErrors([PipelineError("a study file must be a mapping with 'base' and 'variants'", location=Location(str(path), 1))])
    for k in data:
        if k not in STUDY_KEYS:
            from .errors import did_you_mean

            errors.append(PipelineError(f"unknown key '{k}' in the study{did_you_mean(k, STUDY_KEYS)}", location=data.loc_of(k)))
    if "base" not in data:
        errors.append(PipelineError("the study has no 'base' pipeline", location=data.loc))
    if not isinstance(data.get("variants"), dict) or not data.get("variants"):
        errors.append(PipelineError("the study needs 'variants': a mapping of name -> overrides", location=data.loc))
    if errors:
        raise PipelineErrors(errors)
    return data


def run_study(
    path: str | Path,
    out_dir: str | Path,
    *,
    cache: Cache | None = None,
    registry: Registry | None = None,
    reporter: Reporter | None = None,
    executor: str = "local",
    sets: dict[str, Any] | None = None,
    jobs: int | None = None,
) -> list[dict[str, Any]]:
    """Run every variant on every input; write results.csv / results.md under ``out_dir``. ``jobs``: nodes each
    run runs at once (:func:`.runner.run_graph`; None: the pipeline's ``jobs:``, else 1). ``sets``
    (the command line's ``--set``, e.g. a shorter frame range for a quick look) apply to every run (a
    variant's own ``set:`` of the same param wins); their relative paths start from the current folder."""
    path = Path(path)
    out_dir = Path(out_dir)
    reporter = reporter or Reporter()
    study = read_study(path)
    base = Path(str(study["base"]))
    base = base if base.is_absolute() else (path.parent / base)
    metrics_name = str(study.get("metrics", "metrics.json"))
    inputs = study.get("inputs") or {"default": {}}
    rows: list[dict[str, Any]] = []
    cache = cache if cache is not None else Cache()
    sets_cli = dict(sets or {})
    for vname, variant in study["variants"].items():
        variant = variant or {}
        for iname, inp in inputs.items():
            inp = inp or {}
            row: dict[str, Any] = {"variant": vname, "input": iname}
            reporter._print(f"study: variant '{vname}', input '{iname}'")
            t0 = time.perf_counter()
            try:
                decl = read_pipeline(base)
                errs: list[PipelineError] = []
                vloc = study["variants"].loc_of(vname) if isinstance(study["variants"], LocatedDict) else Location(str(path))
                for nid, body in (variant.get("nodes") or {}).items():
                    merge_node_override(decl, str(nid), body, vloc, path.parent, errs)
                if errs:
                    raise PipelineErrors(errs)
                sets = {**(inp.get("set") or {}), **(variant.get("set") or {})}
                if study.get("outputs"):  # nodes no wanted output needs are not built (nor can they fail)
                    _prune(decl, [str(o) for o in study["outputs"]], keep={str(k).split(".")[0] for k in [*sets, *sets_cli]})
                vars_ = {**(inp.get("vars") or {}), **(variant.get("vars") or {})}
                if sets_cli:
                    from .spec import apply_sets

                    cli_errs = apply_sets(decl, sets_cli, None, "<command line>")
                    if cli_errs:
                        raise PipelineErrors(cli_errs)
                graph = load_graph(base, sets=sets, vars=vars_, registry=registry, decl=decl,
                                   base_dir=path.parent, source=str(path))
                wanted = study.get("outputs")
                if wanted:
                    graph.outputs = {k: v for k, v in graph.outputs.items() if k in wanted}
                run = run_graph(graph, out_dir=out_dir / vname / iname, cache=cache, reporter=reporter, executor=executor, jobs=jobs)
                row["status"] = "ok"
                row["ran"] = sum(r.status == "ran" for r in run.results.values())
                row["cached"] = sum(r.status == "cached" for r in run.results.values())
                if metrics_name in graph.outputs:
                    row.update(metric_columns(run.output(metrics_name), study.get("columns")))
            except TbhaError as e:
                row["status"] = "failed"
                row["error"] = " ".join(ln.strip() for ln in e.format().splitlines())[:400]
                reporter._print(f"  failed: {e.format()}")
            row["wall_s"] = round(time.perf_counter() - t0, 3)
            rows.append(row)
    write_tables(rows, out_dir)
    write_chart(rows, out_dir, study.get("columns"), title=str(study.get("description") or path.stem))
    return rows


def _prune(decl, wanted: list[str], keep: set[str]) -> None:
    """Drop the nodes and outputs of ``decl`` that the ``wanted`` outputs do not need (nodes in ``keep``
    stay). Does nothing when a wanted output is not declared (validation then reports it)."""
    if not wanted or any(w not in decl.outputs for w in wanted):
        return
    def node_of(v) -> str | None:
        ref = getattr(v, "value", v)
        return ref.split(".", 1)[0] if isinstance(ref, str) and "." in ref else None

    need = {n for n in (node_of(decl.outputs[w]) for w in wanted) if n} | (keep & set(decl.nodes))
    stack = list(need)
    while stack:
        nid = stack.pop()
        if nid not in decl.nodes:
            continue
        for v in decl.nodes[nid].inputs.values():
            src = node_of(v)
            if src and src not in need:
                need.add(src)
                stack.append(src)
    decl.nodes = {k: v for k, v in decl.nodes.items() if k in need}
    decl.outputs = {k: v for k, v in decl.outputs.items() if k in wanted}


STUDY_FIRST = ("variant", "input", "status", "wall_s", "ran", "cached")


def _columns(rows: list[dict[str, Any]], first: tuple[str, ...] = STUDY_FIRST) -> list[str]:
    first = [c for c in first if any(c in r for r in rows)]
    rest: list[str] = []
    for r in rows:
        for k in r:
            if k not in first and k not in rest and k != "error":
                rest.append(k)
    return first + rest + (["error"] if any("error" in r for r in rows) else [])


def _fmt(v: Any) -> str:
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.4g}"
    return str(v)


def to_markdown(rows: list[dict[str, Any]], first: tuple[str, ...] = STUDY_FIRST) -> str:
    cols = _columns(rows, first)
    out = io.StringIO()
    out.write("| " + " | ".join(cols) + " |\n")
    out.write("|" + "|".join("---" for _ in cols) + "|\n")
    for r in rows:
        out.write("| " + " | ".join(_fmt(r.get(c)).replace("|", "\\|") for c in cols) + " |\n")
    return out.getvalue()


def write_tables(rows: list[dict[str, Any]], out_dir: Path, stem: str = "results", first: tuple[str, ...] = STUDY_FIRST) -> None:
    """``<stem>.csv`` and ``<stem>.md`` (one row per dict; columns: ``first``, then every other key)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    cols = _columns(rows, first)
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols, extrasaction="ignore")
    w.writeheader()
    for r in rows:
        w.writerow({c: _fmt(r.get(c)) for c in cols})
    from .atomic import atomic_write_bytes

    atomic_write_bytes(out_dir / f"{stem}.csv", buf.getvalue().encode())
    atomic_write_bytes(out_dir / f"{stem}.md", to_markdown(rows, first).encode())
