"""The Dask executor (extra ``dask``): independent nodes run in parallel on a Dask cluster.

Each node is one Dask task running :func:`execute_node`, depending on its upstream tasks. Values travel
through the shared cache, not through Dask: a task returns only fingerprints and the entry path, so a
worker process loads what it needs from the cache folder (which must be visible to every worker —
true for a LocalCluster; for a remote cluster, point ``TBHA_CACHE_DIR`` at a shared file system).
"""
from __future__ import annotations

import tempfile
from pathlib import Path

from ..cache import Cache
from ..errors import TbhaError
from ..graph import Graph
from ..progress import Reporter
from ..scheduler import NodeResult, execute_node


def _task(node_id: str, graph: Graph, cache_root: str, *upstream: NodeResult) -> NodeResult:
    cache = Cache(cache_root)
    inputs = {r.node_id: r for r in upstream}
    work = Path(tempfile.mkdtemp(prefix=f"tbha-dask-{node_id}-"))
    res = execute_node(graph.nodes[node_id], graph, inputs, cache, work_root=work)
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


def run_dask(graph: Graph, node_ids: list[str], cache: Cache | None, reporter: Reporter, scheduler: str | None = None, workers: int | None = None, client=None) -> dict[str, NodeResult]:
    """Run the needed nodes as Dask tasks; results equal the local executor's."""
    from distributed import as_completed

    own = client is None
    cluster = None
    if own:
        client, cluster = client_for(scheduler, workers)
    tmp = None
    if cache is None:  # values travel through a cache: use a private one
        tmp = tempfile.mkdtemp(prefix="tbha-dask-cache-")
        cache = Cache(tmp)
    try:
        order = graph.needed_for(node_ids)
        futures = {}
        for nid in order:
            ups = sorted({src for src, _ in graph.nodes[nid].inputs.values()})
            futures[nid] = client.submit(_task, nid, graph, str(cache.root), *[futures[u] for u in ups], key=f"tbha-{nid}-{id(graph)}", pure=False)
        results: dict[str, NodeResult] = {}
        by_key = {f.key: nid for nid, f in futures.items()}
        for fut in as_completed(list(futures.values())):
            nid = by_key[fut.key]
            try:
                res = fut.result()
            except TbhaError:
                for f in futures.values():
                    f.cancel()
                raise
            for w in res.warnings:
                reporter.warn(w)
            for w in res.node_warnings:
                reporter.warn(f"{nid}: {w}")
            reporter.node_done(nid, graph.nodes[nid].spec.type, res.status, res.seconds)
            results[nid] = res
        return {nid: results[nid] for nid in order}
    finally:
        if own:
            client.close()
            if cluster is not None:
                cluster.close()
