"""One entry point for running a pipeline, used by the CLI, studies, batches and the Python API."""
from __future__ import annotations

import shutil
import time
from pathlib import Path
from typing import Any

from .cache import Cache
from .filehash import using_cache_dir
from .graph import Graph, build_graph
from .progress import QUIET, Reporter
from .registry import Registry
from .rundir import check_out_dir, write_run_dir
from .scratch import remove_at_exit, scratch_folder
from .scheduler import RunResult, run_local, targets_of
from .spec import PipelineDecl, apply_sets, apply_vars, read_pipeline
from .errors import PipelineErrors, TbhaError


def load_graph(
    path: str | Path,
    sets: dict[str, Any] | None = None,
    vars: dict[str, Any] | None = None,
    registry: Registry | None = None,
    decl: PipelineDecl | None = None,
    base_dir: Path | None = None,
    source: str = "<command line>",
) -> Graph:
    """Read, override and check a pipeline file (or an already read ``decl``). Relative input paths in
    ``sets``/``vars`` resolve against ``base_dir`` (default: the current folder)."""
    decl = decl if decl is not None else read_pipeline(path)
    problems = apply_vars(decl, vars, base_dir, source)
    problems += apply_sets(decl, sets or {}, base_dir, source)
    if problems:
        raise PipelineErrors(problems)
    return build_graph(decl, registry)


def effective_jobs(graph: Graph, jobs: int | None) -> int:
    """Nodes the local executor runs at once: ``jobs`` if given, else the pipeline file's ``jobs:``, else 1."""
    return jobs if jobs is not None else (graph.jobs or 1)


def run_graph(
    graph: Graph,
    *,
    out_dir: str | Path | None = None,
    outputs: list[str] | None = None,
    cache: Cache | None | bool = True,
    executor: str = "local",
    scheduler: str | None = None,
    reporter: Reporter = QUIET,
    workers: int | None = None,
    jobs: int | None = None,
) -> RunResult:
    """Run ``graph`` (the nodes the requested ``outputs`` need) and, with ``out_dir``, write them.

    ``cache``: True (default location), False/None (no caching) or a :class:`Cache`.
    ``executor``: "local" or "dask" (``scheduler`` = address of an existing cluster, else a LocalCluster).
    ``jobs``: nodes the local executor runs at once (independent branches on threads; 1: one after another);
    None: what the pipeline file says (``jobs:``), else 1. With the dask executor a ``jobs`` above 1 is an error
    (and the pipeline's is not used): its workers are its parallelism.
    """
    if executor != "local" and jobs is not None and jobs > 1:
        raise TbhaError(f"jobs is for the local executor, not {executor}",
                        hint="the dask executor runs independent nodes on its workers: give --workers instead")
    c: Cache | None = Cache() if cache is True else (cache or None)
    if out_dir is not None:
        check_out_dir(Path(out_dir))  # refuse a folder that is not ours before spending time on the run
    ids = targets_of(graph, outputs)
    t0 = time.perf_counter()
    work_root = scratch_folder("tbha-run-")
    private = None
    finished = False
    try:
        with using_cache_dir(c.root if c is not None else None):  # file-hash memo of this run's cache
            if executor == "local":
                results = run_local(graph, ids, c, reporter, work_root, materialise=list(graph.outputs.values()) if out_dir is not None else [],
                                    jobs=effective_jobs(graph, jobs))
            elif executor == "dask":
                from .executors.dask_executor import run_dask

                if c is None:  # values travel between workers through a cache: a private one, removed below
                    private = work_root / "cache"
                results = run_dask(graph, ids, c if c is not None else Cache(private), reporter, scheduler=scheduler, workers=workers)
            else:
                raise ValueError(f"unknown executor {executor!r} (local or dask)")
            run = RunResult(graph, results, time.perf_counter() - t0)
            if out_dir is not None:
                write_run_dir(run, Path(out_dir), executor)
            finished = True
            return run
    finally:
        # With a cache the file outputs were moved into it: the work folders can go now. Without one (or with
        # the dask executor's private cache, which lives in work_root) the returned values are paths into
        # work_root: it goes when the process exits; a failed run returned nothing, so it goes now.
        if c is not None or not finished:
            shutil.rmtree(work_root, ignore_errors=True)
        else:
            remove_at_exit(work_root)
