"""The Dask executor (extra ``dask``): independent nodes run in parallel on a Dask cluster.

Each node is one Dask task running :func:`execute_node`, submitted by the driver once its upstream nodes are
done (with their light results as arguments, not futures, so Dask spreads independent tasks). Values travel
through the shared cache, not through Dask: a task returns only fingerprints and the entry path, so a
worker process loads what it needs from the cache folder (which must be visible to every worker —
true for a LocalCluster; for a remote cluster, point ``TBHA_CACHE_DIR`` at a shared file system).

A task whose upstream value fails its checksum while loading returns a marker naming the corrupt node
(the driver submits nothing after it); the driver then removes that entry and
submits the graph again: what is intact is a cache hit, the corrupt node and what depends on it run
again. Each task's private work folder is removed when the task ends (its files are in the cache).
"""
from __future__ import annotations

import shutil

from ..cache import Cache, CorruptEntry
from ..errors import TbhaError
from ..graph import Graph
from ..progress import Reporter
from ..scratch import scratch_folder
from ..scheduler import NodeResult, execute_node

CORRUPT = "corrupt-upstream"


def _task(node_id: str, graph: Graph, cache_root: str, *upstream: NodeResult) -> NodeResult:
    cache = Cache(cache_root)
    inputs = {r.node_id: r for r in upstream}
    work = scratch_folder(f"tbha-dask-{node_id}-")  # removed below: the cache holds the results
    try:
        res = execute_node(graph.nodes[node_id], graph, inputs, cache, work_root=work)
    except CorruptEntry as e:
        bad = e.node or ""
        key = inputs[bad].key if bad in inputs else None
        return NodeResult(bad, CORRUPT, key, 0.0, {}, warnings=[e.message])
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return res.light()


def client_for(scheduler: str | None = None, workers: int | None = None):
    """A ``distributed.Client``: connected to ``scheduler`` (``tcp://host:port``) or a new LocalCluster."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise TbhaError("the dask executor needs the 'dask' extra", hint="pip install 'tbha-graph[dask]'") from None
    if scheduler:
        try:
            return Client(scheduler, timeout="10s"), None
        except OSError as e:
            raise TbhaError(f"cannot connect to the Dask scheduler at {scheduler}: {e}", hint="start it with `dask scheduler` or drop --scheduler to use a local cluster") from None
    cluster = LocalCluster(n_workers=workers or 2, threads_per_worker=1, processes=True, dashboard_address=":0")
    return Client(cluster), cluster


def _run_attempt(client, graph: Graph, order: list[str], cache: Cache, reporter: Reporter, attempt: int):
    """Submit each node once its upstream nodes are done; return (results, corrupt markers).

    The driver dispatches: a task receives its upstream results as plain (light) values, never as Dask
    futures, so Dask sees independent tasks and spreads them over idle workers instead of pulling them
    onto the worker that holds an upstream result (values travel through the cache, not through Dask).
    A node whose upstream is corrupt is not submitted.
    """
    from distributed import as_completed

    ups = {nid: sorted({src for src, _ in graph.nodes[nid].inputs.values()}) for nid in order}
    waiting = {nid: len(ups[nid]) for nid in order}  # upstream nodes not yet done
    below: dict[str, list[str]] = {nid: [] for nid in order}
    for nid in order:
        for u in ups[nid]:
            below[u].append(nid)
    results: dict[str, NodeResult] = {}
    corrupt: dict[str, NodeResult] = {}
    by_key: dict[str, str] = {}
    pending = as_completed(loop=client.loop)
    futures = []

    def submit(nid: str) -> None:
        fut = client.submit(_task, nid, graph, str(cache.root), *[results[u] for u in ups[nid]],
                            key=f"tbha-{nid}-{id(graph)}-{attempt}", pure=False)
        by_key[fut.key] = nid
        futures.append(fut)
        pending.add(fut)

    for nid in order:
        if not waiting[nid]:
            submit(nid)
    for fut in pending:
        nid = by_key[fut.key]
        try:
            res = fut.result()
        except TbhaError:
            client.cancel(futures)
            raise
        if res.status == CORRUPT:
            corrupt.setdefault(res.node_id, res)
            continue
        for w in res.warnings:
            reporter.warn(w)
        for w in res.node_warnings:
            reporter.warn(f"{nid}: {w}")
        reporter.node_done(nid, graph.nodes[nid].spec.type, res.status, res.seconds)
        results[nid] = res
        for child in below[nid]:
            waiting[child] -= 1
            if not waiting[child]:
                submit(child)
    return results, corrupt


def run_dask(graph: Graph, node_ids: list[str], cache: Cache, reporter: Reporter, scheduler: str | None = None, workers: int | None = None, client=None) -> dict[str, NodeResult]:
    """Run the needed nodes as Dask tasks through ``cache``; results equal the local executor's."""
    own = client is None
    cluster = None
    if own:
        client, cluster = client_for(scheduler, workers)
    try:
        order = graph.needed_for(node_ids)
        for attempt in range(len(order) + 2):
            results, corrupt = _run_attempt(client, graph, order, cache, reporter, attempt)
            if not corrupt:
                return {nid: results[nid] for nid in order}
            for bad, marker in corrupt.items():  # remove the corrupt entries, then run again (the rest are hits)
                reporter.warn(f"{marker.warnings[0] if marker.warnings else 'corrupt cache entry'}; recomputing node '{bad}'")
                cache.remove(marker.key or "")
        raise TbhaError("cache entries kept failing their checksums after recomputing them",
                        hint=f"check the cache folder's disk ({cache.root}); `tbha-graph cache clear` empties it")
    finally:
        if own:
            client.close()
            if cluster is not None:
                cluster.close()
