"""The Dask executor (extra ``dask``): independent nodes run in parallel on a Dask cluster.

Each node is one Dask task running :func:`execute_node`, depending on its upstream tasks. Values travel
through the shared cache, not through Dask: a task returns only fingerprints and the entry path, so a
worker process loads what it needs from the cache folder (which must be visible to every worker —
true for a LocalCluster; for a remote cluster, point ``TBHA_CACHE_DIR`` at a shared file system).

A task whose upstream value fails its checksum while loading returns a marker naming the corrupt node
(and the tasks after it pass the marker on without running); the driver then removes that entry and
submits the graph again: what is intact is a cache hit, the corrupt node and what depends on it run
again. Each task's private work folder is removed when the task ends (its files are in the cache).
"""
from __future__ import annotations

import shutil
import tempfile
from pathlib import Path

from ..cache import Cache, CorruptEntry
from ..errors import TbhaError
from ..graph import Graph
from ..progress import Reporter
from ..scheduler import NodeResult, execute_node

CORRUPT = "corrupt-upstream"


def _task(node_id: str, graph: Graph, cache_root: str, *upstream: NodeResult) -> NodeResult:
    for r in upstream:  # an upstream task found a corrupt entry: pass the marker on, run nothing
        if r.status == CORRUPT:
            return r
    cache = Cache(cache_root)
    inputs = {r.node_id: r for r in upstream}
    work = Path(tempfile.mkdtemp(prefix=f"tbha-dask-{node_id}-"))
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


def _submit_all(client, graph: Graph, order: list[str], cache: Cache, attempt: int) -> dict:
    futures = {}
    for nid in order:
        ups = sorted({src for src, _ in graph.nodes[nid].inputs.values()})
        futures[nid] = client.submit(_task, nid, graph, str(cache.root), *[futures[u] for u in ups],
                                     key=f"tbha-{nid}-{id(graph)}-{attempt}", pure=False)
    return futures


def run_dask(graph: Graph, node_ids: list[str], cache: Cache, reporter: Reporter, scheduler: str | None = None, workers: int | None = None, client=None) -> dict[str, NodeResult]:
    """Run the needed nodes as Dask tasks through ``cache``; results equal the local executor's."""
    from distributed import as_completed

    own = client is None
    cluster = None
    if own:
        client, cluster = client_for(scheduler, workers)
    try:
        order = graph.needed_for(node_ids)
        for attempt in range(len(order) + 2):
            futures = _submit_all(client, graph, order, cache, attempt)
            results: dict[str, NodeResult] = {}
            corrupt: dict[str, NodeResult] = {}
            by_key = {f.key: nid for nid, f in futures.items()}
            for fut in as_completed(list(futures.values())):
                nid = by_key[fut.key]
                try:
                    res = fut.result()
                except TbhaError:
                    for f in futures.values():
                        f.cancel()
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
