"""Running a checked :class:`Graph`: only what the requested outputs need, in topological order,
each node looked up in the cache first.

The per-node step (:func:`execute_node`) is shared by every executor: compute the key from the
params and the inputs' content fingerprints, return the cached entry if there is one (a corrupt
entry is reported, removed and recomputed), else load the inputs, run the function, check its outputs
against the declared port types and store them atomically.
"""
from __future__ import annotations

import gc
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .cache import Cache, CorruptEntry, Entry
from .errors import NodeFailed, PortTypeError, TbhaError
from .graph import BoundNode, Graph
from .filehash import using_cache_dir
from .node import CANCEL, Context
from .progress import QUIET, Reporter


#: ``paused_by_scheduler``: run_local turned the garbage collector off for its own steps (per thread)
_gc = threading.local()


@dataclass
class NodeResult:
    """What one node produced: fingerprints always (when caching), values in memory or in the cache."""

    node_id: str
    status: str  # "ran" or "cached"
    key: str | None
    seconds: float
    fingerprints: dict[str, str | None]
    values: dict[str, Any] | None = None
    entry_path: str | None = None
    entry_meta: dict | None = None
    warnings: list[str] = field(default_factory=list)  # the framework's (cache trouble)
    node_warnings: list[str] = field(default_factory=list)  # the node's own (ctx.warn), also when cached

    def value(self, port: str, bound: BoundNode) -> Any:
        if self.values is not None and port in self.values:
            return self.values[port]
        if self.entry_path is None:
            raise TbhaError(f"output '{port}' of node '{self.node_id}' is not available")
        entry = Entry(self.key or "", Path(self.entry_path), self.entry_meta or {})
        try:
            v = entry.load(port, bound.spec.outputs[port])
        except CorruptEntry as e:
            e.node = self.node_id
            raise
        if self.values is None:
            self.values = {}
        self.values[port] = v
        return v

    def light(self) -> "NodeResult":
        """A copy without in-memory values (to send between processes when values live in the cache)."""
        return NodeResult(self.node_id, self.status, self.key, self.seconds, self.fingerprints, None, self.entry_path, self.entry_meta, self.warnings,
                          self.node_warnings)


def _normalise_outputs(bound: BoundNode, out: Any) -> dict[str, Any]:
    spec = bound.spec
    if len(spec.outputs) == 1 and not (isinstance(out, dict) and out.keys() == spec.outputs.keys()):
        out = {next(iter(spec.outputs)): out}
    if not isinstance(out, dict):
        raise PortTypeError(f"returned {type(out).__name__}, expected a dict with outputs {sorted(spec.outputs)}")
    if out.keys() != spec.outputs.keys():
        missing = set(spec.outputs) - set(out)
        extra = set(out) - set(spec.outputs)
        raise PortTypeError(
            f"returned outputs {sorted(out)}, declared {sorted(spec.outputs)}"
            + (f"; missing {sorted(missing)}" if missing else "")
            + (f"; undeclared {sorted(extra)}" if extra else "")
        )
    return {k: spec.outputs[k].validate(v, f"output '{k}'") for k, v in out.items()}


def execute_node(
    bound: BoundNode,
    graph: Graph,
    inputs: dict[str, NodeResult],
    cache: Cache | None,
    reporter: Reporter = QUIET,
    work_root: Path | None = None,
) -> NodeResult:
    """Evaluate one node given its upstream results (``inputs``: source node id -> result)."""
    t0 = time.perf_counter()
    spec = bound.spec
    warnings: list[str] = []
    key = None
    if cache is not None:
        fps = {port: inputs[src].fingerprints[sport] for port, (src, sport) in bound.inputs.items()}
        if len(fps) != len(spec.inputs):  # unconnected optional inputs: None
            for port in spec.inputs:
                fps.setdefault(port, None)
        key = cache.key(spec, bound.params, fps)
        try:
            entry = cache.lookup(key)
        except CorruptEntry as e:
            warnings.append(f"{e.message}; recomputing node '{bound.id}'")
            cache.remove(key)
            entry = None
        if entry is not None:
            outs = entry.meta.get("outputs", {})
            if outs.keys() == spec.outputs.keys():
                cache.touch(entry)  # gc removes the least recently *used* entries
                nw = entry.meta.get("node_warnings")
                nw = [str(w) for w in nw if isinstance(w, str)] if nw else []
                return NodeResult(bound.id, "cached", key, time.perf_counter() - t0,
                                  {p: o["fingerprint"] for p, o in outs.items()}, None, entry.path, entry.meta, warnings, nw)
            warnings.append(f"cache entry {key[:12]} of node '{bound.id}' has the wrong outputs; recomputing")
            cache.remove(key)

    args = {port: inputs[src].value(sport, graph.nodes[src]) for port, (src, sport) in bound.inputs.items()}
    for port in spec.inputs:
        args.setdefault(port, None)
    ctx = Context(bound.id, bound.params, reporter=reporter, work_root=work_root)  # the folder made only when used
    resume_gc = getattr(_gc, "paused_by_scheduler", False) and not gc.isenabled()
    try:
        if resume_gc:  # the node's own code runs with the garbage collector on (see run_local)
            gc.enable()
        if cache is None:
            out = _normalise_outputs(bound, spec.fn(ctx, **args))
        else:
            with using_cache_dir(cache.root):  # a node hashing a file uses this run's cache's memo
                out = _normalise_outputs(bound, spec.fn(ctx, **args))
    except TbhaError as e:
        raise NodeFailed(e.message, hint=e.hint, node=bound.id, location=e.location) from e
    except Exception as e:  # noqa: BLE001 - a bug in a node: keep the traceback for its author
        tb = "".join(traceback.format_exception(type(e), e, e.__traceback__)[-6:])
        raise NodeFailed(f"{type(e).__name__}: {e}", node=bound.id, hint=f"this looks like a bug in node type '{spec.type}'; traceback:\n{tb}") from e
    finally:
        if resume_gc:
            gc.disable()
    if cache is None:
        return NodeResult(bound.id, "ran", None, time.perf_counter() - t0, {p: None for p in out}, out, None, None, warnings, list(ctx.warnings))
    info = {"type": spec.type, "node_version": spec.version, "node_id": bound.id, "seconds": time.perf_counter() - t0,
            "node_warnings": list(ctx.warnings)}
    entry, values = cache.store(key, {p: (spec.outputs[p], v) for p, v in out.items()}, info)
    return NodeResult(bound.id, "ran", key, time.perf_counter() - t0,
                      {p: entry.meta["outputs"][p]["fingerprint"] for p in out}, values, str(entry.path), entry.meta, warnings, list(ctx.warnings))


@dataclass
class RunResult:
    """The results of the nodes that were evaluated, in order."""

    graph: Graph
    results: dict[str, NodeResult]
    seconds: float

    def output(self, name_or_ref: str) -> Any:
        """Value of a named pipeline output (``"motion.bvh"``) or of ``"node.port"``. A report (a mapping
        with a ``verdict``) carries every node's warnings: see :meth:`with_warnings`."""
        ref = self.graph.outputs.get(name_or_ref)
        if ref is None:
            node_id, port = name_or_ref.split(".", 1)
            ref = (node_id, port)
        return self.with_warnings(self.results[ref[0]].value(ref[1], self.graph.nodes[ref[0]]))

    def node_warnings(self) -> list[dict[str, str]]:
        """Every warning a node gave (``ctx.warn``), in run order, also for nodes that came from the cache."""
        return [{"node": nid, "message": w} for nid, r in self.results.items() for w in r.node_warnings]

    def with_warnings(self, value: Any) -> Any:
        """A report output — a mapping with a ``verdict`` ("ok" | "doubtful" | "failed") — gets every
        node's warning added to its ``warnings`` list (once each); an "ok" verdict with warnings becomes
        "doubtful", the warning's node named in ``verdict_reasons``. Other values are returned as they are."""
        if not isinstance(value, dict) or "verdict" not in value:
            return value
        found = self.node_warnings()
        if not found:
            return value
        out = dict(value)
        warnings = [str(w) for w in out.get("warnings") or []]
        reasons = [str(r) for r in out.get("verdict_reasons") or []]
        added = []
        for w in found:
            if w["message"] not in warnings and not any(w["message"] in x for x in warnings):
                warnings.append(f"{w['node']}: {w['message']}")
                added.append(w)
        out["warnings"] = warnings
        nodes = sorted({w["node"] for w in found})
        if out.get("verdict") == "ok":
            out["verdict"] = "doubtful"
        for n in nodes:
            r = f"node '{n}' gave a warning"
            if r not in reasons:
                reasons.append(r)
        out["verdict_reasons"] = reasons
        return out


def targets_of(graph: Graph, outputs: list[str] | None) -> list[str]:
    """Node ids needed for the given output names (all outputs when None; all sinks if none declared)."""
    if outputs:
        ids = []
        for name in outputs:
            if name in graph.outputs:
                ids.append(graph.outputs[name][0])
            elif name in graph.nodes:
                ids.append(name)
            else:
                raise TbhaError(f"'{name}' is neither an output nor a node of the pipeline")
        return ids
    if graph.outputs:
        return sorted({n for n, _ in graph.outputs.values()})
    return list(graph.order)


def run_local(
    graph: Graph,
    node_ids: list[str],
    cache: Cache | None,
    reporter: Reporter,
    work_root: Path | None = None,
    materialise: list[tuple[str, str]] = (),
    jobs: int = 1,
) -> dict[str, NodeResult]:
    """The local executor: with ``jobs`` 1 one node after another, in topological order; with more, each node
    starts on a thread as soon as its inputs are ready, at most ``jobs`` at once (:func:`_run_concurrent`).
    Either way the results come back in topological order and are the same (keys, values, warnings).

    ``materialise``: (node, port) values to load at the end (the outputs to write), so that a corrupt
    cached value is found here, where the node can be recomputed, rather than when writing.

    With one job the garbage collector is off for the scheduler's own steps (keys, lookups, bookkeeping: many
    small long-lived objects, no cycles; at 10,000 cached nodes its passes cost about a quarter of the time)
    and on while a node's function runs. With several it stays on: the collector is one per process, and
    some node is nearly always running."""
    if jobs > 1:
        return _run_concurrent(graph, node_ids, cache, reporter, work_root, materialise, jobs)
    was_enabled = gc.isenabled()
    paused_before = getattr(_gc, "paused_by_scheduler", False)
    gc.disable()
    _gc.paused_by_scheduler = was_enabled
    try:
        return _run_local(graph, node_ids, cache, reporter, work_root, materialise)
    finally:
        _gc.paused_by_scheduler = paused_before
        if was_enabled:
            gc.enable()


def _materialise(results: dict[str, NodeResult], graph: Graph, materialise) -> None:
    """Load the (node, port) values to write, so that a corrupt cached one is found while it can be recomputed."""
    for nid, port in materialise:
        if nid in results:
            results[nid].value(port, graph.nodes[nid])


def _report(reporter: Reporter, bound: BoundNode, res: NodeResult) -> None:
    for w in res.warnings:
        reporter.warn(w)
    for w in res.node_warnings:
        reporter.warn(f"{bound.id}: {w}")
    reporter.node_done(bound.id, bound.spec.type, res.status, res.seconds)


def _run_concurrent(graph: Graph, node_ids: list[str], cache: Cache | None, reporter: Reporter,
                    work_root: Path | None, materialise, jobs: int) -> dict[str, NodeResult]:
    """Nodes on a pool of ``jobs`` threads, each submitted when every node it reads from is done (numpy,
    OpenCV and MediaPipe release the GIL in their heavy work, so independent branches overlap). A failure
    stops new submissions; the running nodes finish, then the first failure in topological order is raised.
    A cached value found corrupt while loading (an input, or an output at the end): that node's entry is
    removed and it and everything downstream of it run again, as in :func:`_run_local`. Ctrl-C (a
    KeyboardInterrupt while waiting) sets the run's cancel event (:data:`.node.CANCEL`): the running nodes stop
    at their next ``ctx.progress`` step instead of running to their end, and the interrupt is raised."""
    import contextvars
    from concurrent.futures import FIRST_COMPLETED, ThreadPoolExecutor, wait

    order = graph.needed_for(node_ids)
    rank = {nid: i for i, nid in enumerate(order)}
    deps = {nid: {src for src, _ in graph.nodes[nid].inputs.values()} for nid in order}
    results: dict[str, NodeResult] = {}
    retries = 0

    def recompute(e: CorruptEntry) -> bool:
        """Forget the corrupt node and what depends on it; False when that cannot help."""
        nonlocal retries
        bad = e.node or ""
        if cache is None or bad not in results or retries > len(order):
            return False
        retries += 1
        reporter.warn(f"{e.message}; recomputing node '{bad}'")
        cache.remove(results[bad].key or "")
        for k in order[rank[bad]:]:  # as _run_local: it and every later node again (those not below it: from the cache)
            results.pop(k, None)
        return True

    cancel = threading.Event()
    token = CANCEL.set(cancel)  # copied into each node's thread with the context (ctx.progress checks it)
    try:
        with ThreadPoolExecutor(max_workers=jobs, thread_name_prefix="tbha-node") as pool:
            try:
                while True:
                    running: dict = {}  # future -> node id
                    failures: dict[str, BaseException] = {}
                    while True:
                        if not failures:
                            busy = set(running.values())
                            for nid in order:
                                if len(running) >= jobs:
                                    break
                                if nid in results or nid in busy or not deps[nid] <= results.keys():
                                    continue
                                inputs = {src: results[src] for src in deps[nid]}
                                ctx = contextvars.copy_context()  # the run's cache folder (using_cache_dir) in the thread
                                running[pool.submit(ctx.run, execute_node, graph.nodes[nid], graph, inputs, cache, reporter,
                                                    work_root)] = nid
                        if not running:
                            break
                        done, _ = wait(list(running), return_when=FIRST_COMPLETED)
                        for fut in sorted(done, key=lambda f: rank[running[f]]):
                            nid = running.pop(fut)
                            try:
                                res = fut.result()
                            except CorruptEntry as e:
                                if not recompute(e):
                                    failures[nid] = e
                                continue
                            except BaseException as e:  # noqa: BLE001 - raised below, once the running nodes end
                                failures[nid] = e
                                continue
                            if not deps[nid] <= results.keys():  # an input was found corrupt meanwhile: run it again
                                continue
                            _report(reporter, graph.nodes[nid], res)
                            results[nid] = res
                    if failures:
                        raise failures[min(failures, key=rank.__getitem__)]
                    try:
                        _materialise(results, graph, materialise)
                    except CorruptEntry as e:
                        if not recompute(e):
                            raise
                        continue
                    return {nid: results[nid] for nid in order}
            except KeyboardInterrupt:  # Ctrl-C: the running nodes stop at their next progress step, not at their end
                cancel.set()
                pool.shutdown(wait=True, cancel_futures=True)
                raise
    finally:
        CANCEL.reset(token)


def _run_local(graph: Graph, node_ids: list[str], cache: Cache | None, reporter: Reporter, work_root: Path | None,
               materialise: list[tuple[str, str]] | tuple = ()) -> dict[str, NodeResult]:
    results: dict[str, NodeResult] = {}
    order = graph.needed_for(node_ids)
    i = 0
    retries = 0
    while True:
        try:
            while i < len(order):
                nid = order[i]
                bound = graph.nodes[nid]
                res = execute_node(bound, graph, results, cache, reporter, work_root)
                _report(reporter, bound, res)
                results[nid] = res
                i += 1
            _materialise(results, graph, materialise)
            return results
        except CorruptEntry as e:  # a cached value failed its checksum while loading: recompute it
            bad = e.node or ""
            if cache is None or bad not in results or retries > len(order):
                raise
            retries += 1
            reporter.warn(f"{e.message}; recomputing node '{bad}'")
            cache.remove(results[bad].key or "")
            i = order.index(bad)
            for later in order[i:]:
                results.pop(later, None)
