"""Batches: one pipeline over many inputs (takes), one run directory and one table row per take.

Inputs are given as a glob (``takes/*.mp4``), a folder (every file in it), or a YAML list file::

    takes:
      - path: takes/monday_01.mp4           # bound to the pipeline variable named by --var-name
      - {name: tuesday, path: takes/t.mp4, set: {calibrate.focal_px: 900}}

Each take runs the whole pipeline with ``${<var-name>}`` bound to its path, on the shared cache (so a
re-run after adding takes only processes the new ones). Locally the takes run one after another; with
Dask each take is one task (a take is seconds of work, far above Dask's per-task cost), so takes run in
parallel on the cluster's workers. A failing take is a row with its error; the others still run.
Results: ``<out>/<take>/`` per take plus ``summary.csv`` and ``summary.md``.
"""
from __future__ import annotations

import glob
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .cache import Cache
from .errors import PipelineError, PipelineErrors, TbhaError
from .progress import QUIET, Reporter
from .study import metric_columns, write_tables
from .yamlfile import load_yaml


@dataclass
class Take:
    name: str
    path: str
    sets: dict[str, Any] = field(default_factory=dict)


def _name_for(path: Path, used: set[str]) -> str:
    base = path.stem or "take"
    name, i = base, 2
    while name in used:
        name, i = f"{base}_{i}", i + 1
    used.add(name)
    return name


def collect_takes(spec: str) -> list[Take]:
    """Takes from a glob, a folder, or a YAML list file (see module docstring)."""
    p = Path(spec)
    used: set[str] = set()
    if p.is_file() and p.suffix in (".yaml", ".yml"):
        data, problems = load_yaml(p)  # safe loading; bad bytes, syntax errors, duplicate keys with their line
        if problems:
            raise PipelineErrors([PipelineError(f"{p}: {e.message}", location=e.location, hint=e.hint) for e in problems])
        items = data.get("takes") if isinstance(data, dict) else data
        if not isinstance(items, list) or not items:
            raise PipelineErrors([PipelineError(f"{p}: expected 'takes:' with a list of paths or {{path: ...}} entries")])
        takes = []
        for i, item in enumerate(items):
            if isinstance(item, str):
                item = {"path": item}
            if not isinstance(item, dict) or "path" not in item:
                raise PipelineErrors([PipelineError(f"{p}: take {i + 1} needs a 'path'")])
            if not isinstance(item.get("set") or {}, dict):
                raise PipelineErrors([PipelineError(f"{p}: take {i + 1}: 'set' must map NODE.PARAM to values")])
            path = Path(str(item["path"]))
            path = path if path.is_absolute() else (p.parent / path)
            name = str(item.get("name") or _name_for(path, used))
            used.add(name)
            takes.append(Take(name, str(path.resolve()), dict(item.get("set") or {})))
        return takes
    if p.is_dir():
        files = sorted(f for f in p.iterdir() if f.is_file() and not f.name.startswith("."))
    else:
        files = sorted(Path(f) for f in glob.glob(spec))
    if not files:
        raise TbhaError(f"no takes found for '{spec}'", hint="give a glob such as 'takes/*.mp4', a folder, or a YAML list")
    return [Take(_name_for(f, used), str(f.resolve())) for f in files]


def _with_plugins(plugins: tuple[str, ...]) -> None:
    from .registry import default_registry, load_plugin_modules

    reg = default_registry()
    missing = [m for m in plugins if not any(s.module.startswith(m) for s in reg.specs())]
    if missing:
        load_plugin_modules(missing, reg)


def _warm(pipeline: str, take: Take, var_name: str, plugins: tuple[str, ...], vars: dict[str, Any] | None,
          sets: dict[str, Any] | None, base_dir: str | None) -> float:
    """In a worker: register the plugins and check the pipeline for one take (imports its node modules
    through the registry), so a take's time is its own work. Returns the seconds spent."""
    from .runner import load_graph

    t0 = time.perf_counter()
    _with_plugins(plugins)
    try:
        load_graph(pipeline, vars={**(vars or {}), var_name: take.path}, sets={**(sets or {}), **take.sets},
                   base_dir=Path(base_dir) if base_dir else None)
    except TbhaError:
        pass  # the take itself reports it
    return time.perf_counter() - t0


def warm_workers(client: Any, pipeline: str, take: Take, var_name: str = "video", plugins: tuple[str, ...] = (),
                 vars: dict[str, Any] | None = None, sets: dict[str, Any] | None = None, base_dir: str | None = None) -> dict[str, float]:
    """Make every worker of ``client`` ready to run ``pipeline``: registry loaded, node modules imported
    (once per worker process; again is a no-op). Returns seconds spent per worker address."""
    return client.run(_warm, pipeline, take, var_name, tuple(plugins), vars, sets, base_dir)


def run_take(pipeline: str, take: Take, var_name: str, out_dir: str, cache_root: str | None, metrics_name: str, plugins: tuple[str, ...] = (),
             vars: dict[str, Any] | None = None, sets: dict[str, Any] | None = None, base_dir: str | None = None,
             jobs: int | None = None) -> dict[str, Any]:
    """Run one take locally (``jobs`` nodes at once; None: the pipeline's ``jobs:``); returns its summary row
    (never raises for the take's own failures).
    ``vars``/``sets`` (the command line's ``--var``/``--set``, relative paths from ``base_dir``) apply to
    every take; a take's own ``set:`` entries win over ``sets``."""
    from .runner import load_graph, run_graph

    _with_plugins(plugins)
    row: dict[str, Any] = {"take": take.name, "input": take.path}
    t0 = time.perf_counter()
    try:
        graph = load_graph(pipeline, vars={**(vars or {}), var_name: take.path}, sets={**(sets or {}), **take.sets},
                           base_dir=Path(base_dir) if base_dir else None)
        run = run_graph(graph, out_dir=Path(out_dir) / take.name, cache=Cache(cache_root) if cache_root else False, reporter=QUIET,
                        jobs=jobs)
        row["status"] = "ok"
        row["ran"] = sum(r.status == "ran" for r in run.results.values())
        row["cached"] = sum(r.status == "cached" for r in run.results.values())
        if metrics_name in graph.outputs:
            metrics = run.output(metrics_name)
            if isinstance(metrics, dict):
                row.update(metric_columns(metrics, None))
    except TbhaError as e:
        row["status"] = "failed"
        row["error"] = e.format().replace("\n", " ")[:400]
    row["wall_s"] = round(time.perf_counter() - t0, 3)
    return row


def run_batch(
    pipeline: str | Path,
    takes: list[Take],
    out_dir: str | Path,
    *,
    var_name: str = "video",
    cache: Cache | None = None,
    executor: str = "local",
    scheduler: str | None = None,
    workers: int | None = None,
    reporter: Reporter | None = None,
    metrics_name: str = "metrics.json",
    plugins: tuple[str, ...] = (),
    vars: dict[str, Any] | None = None,
    sets: dict[str, Any] | None = None,
    client: Any = None,
    jobs: int | None = None,
) -> list[dict[str, Any]]:
    """Run ``pipeline`` once per take; write ``summary.csv``/``summary.md`` under ``out_dir``.
    ``client``: a ``distributed.Client`` to run the takes on (executor "dask"), kept open afterwards, so
    batch after batch reuses one warm cluster (:func:`warm_workers`); without it a LocalCluster (or
    ``scheduler``) is started for this batch and closed after it.
    ``vars``/``sets`` apply to every take, like tbha-run's ``--var``/``--set`` (relative paths from the
    current folder); ``var_name`` is bound to each take and cannot also be given in ``vars``. ``jobs``: nodes a
    take runs at once with the local executor (None: the pipeline's ``jobs:``); on Dask the takes run side by side
    and each take as its pipeline says."""
    if vars and var_name in vars:
        raise TbhaError(f"--var {var_name}=... conflicts with the takes: each take is bound to '{var_name}'",
                        hint="drop that --var, or bind the takes to another variable with --var-name")
    base_dir = str(Path.cwd())
    common = (dict(vars or {}), dict(sets or {}), base_dir)
    if takes:  # a misspelt --var/--set is one error up front, not one failed row per take
        from .runner import load_graph

        _with_plugins(tuple(plugins))
        try:
            load_graph(str(pipeline), vars={**common[0], var_name: takes[0].path}, sets=common[1], base_dir=Path(base_dir))
        except PipelineErrors as e:
            mine = [x for x in e.errors if x.location is not None and x.location.file == "<command line>"]
            if mine:
                raise PipelineErrors(mine) from None
    reporter = reporter or Reporter()
    out_dir = Path(out_dir)
    cache_root = str(cache.root) if cache is not None else None
    rows: list[dict[str, Any]] = []
    if executor == "dask":
        own = client is None
        cluster = None
        if own:
            from .executors.dask_executor import client_for

            client, cluster = client_for(scheduler, workers)
        try:
            from distributed import as_completed

            if takes:  # every worker loads the registry and the pipeline's nodes before its first take
                warm_workers(client, str(pipeline), takes[0], var_name, tuple(plugins), *common)
            futs = [client.submit(run_take, str(pipeline), t, var_name, str(out_dir), cache_root, metrics_name, tuple(plugins), *common, pure=False) for t in takes]
            by_future = {f.key: t.name for f, t in zip(futs, takes)}
            done: dict[str, dict] = {}
            for f in as_completed(futs):
                row = f.result()
                done[by_future[f.key]] = row
                reporter._print(f"  {row['status']:<7} {row['take']:<28} {row['wall_s']:8.2f} s")
            rows = [done[t.name] for t in takes]
        finally:
            if own:
                client.close()
                if cluster is not None:
                    cluster.close()
    else:
        for t in takes:
            row = run_take(str(pipeline), t, var_name, str(out_dir), cache_root, metrics_name, tuple(plugins), *common, jobs)
            reporter._print(f"  {row['status']:<7} {row['take']:<28} {row['wall_s']:8.2f} s" + (f"  {row.get('error', '')[:120]}" if row["status"] != "ok" else ""))
            rows.append(row)
    write_tables(rows, out_dir, stem="summary", first=("take", "status", "frames", "wall_s"))
    return rows
