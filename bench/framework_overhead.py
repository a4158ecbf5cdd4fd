"""Scheduler overhead per node: a chain of trivial nodes, built and checked, run with the cache disabled
and fully cached.

Prints, for each chain length, ``build_and_check_us_per_node=``, ``chain_us_per_node=`` (cache off) and
``cache_hit_us_per_node=`` (every node a cache hit, the run repeated on one cache object;
``cache_hit_fresh_us_per_node=``: a new cache object each time, so every entry's meta.json is parsed
again, as in a new process): medians of ``--repeat`` repetitions of wall time,
and the same as process CPU time (``*_cpu_us_per_node``, less disturbed by other processes on a shared
machine). With several lengths (``--nodes 1000,10000``) it also prints ``linearity_<figure>=`` (per-node
cost at the longest chain over that at the shortest; 1.0 is linear). The first chain length's lines are
also printed without a suffix (the acceptance figures). Run:
``python bench/framework_overhead.py [--nodes 1000,10000 --repeat 7]``.
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict

sys.setrecursionlimit(10_000)

from tbha_graph.core import Array, Cache, Pipeline, node  # noqa: E402
from tbha_graph.core.runner import run_graph  # noqa: E402


class P(BaseModel):
    model_config = ConfigDict(extra="forbid")
    k: int = 0


@node("bench.start", outputs={"y": Array("float64", (1,))}, params=P)
def start(ctx):
    "start"
    return np.zeros(1)


@node("bench.step", inputs={"x": Array("float64", (1,))}, outputs={"y": Array("float64", (1,))}, params=P)
def step(ctx, x):
    "identity"
    return x


def chain(n: int):
    p = Pipeline("chain")
    p.add("n0", start)
    for i in range(1, n):
        p.add(f"n{i}", step, x=f"n{i - 1}.y", params={"k": i})
    p.output("y.npz", f"n{n - 1}.y")
    return p.build()


def timed(fn, n: int, repeat: int) -> tuple[float, float]:
    """Median wall and CPU microseconds per node of ``fn()`` over ``repeat`` calls."""
    wall, cpu = [], []
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        fn()
        wall.append((time.perf_counter() - t) / n * 1e6)
        cpu.append((time.process_time() - c) / n * 1e6)
    return statistics.median(wall), statistics.median(cpu)


def measure(n: int, repeat: int) -> dict[str, float]:
    out: dict[str, float] = {}
    chain(min(n, 100))  # warm (imports, pydantic schemas)
    out["build_and_check"], out["build_and_check_cpu"] = timed(lambda: chain(n), n, max(3, repeat // 2))
    g = chain(n)
    out["chain"], out["chain_cpu"] = timed(lambda: run_graph(g, cache=False), n, repeat)
    with tempfile.TemporaryDirectory() as d:
        cache = Cache(Path(d))
        t = time.perf_counter()
        run_graph(g, cache=cache)
        out["cache_cold"] = (time.perf_counter() - t) / n * 1e6
        if hasattr(os, "sync"):
            os.sync()  # the cold run's writes reach the disk now, not while the hits are timed

        def hit(c: Cache = cache):
            r = run_graph(g, cache=c)
            assert all(x.status == "cached" for x in r.results.values())

        out["cache_hit"], out["cache_hit_cpu"] = timed(hit, n, repeat)
        # a new Cache object each time: every meta.json parsed again, as on a process's first run
        out["cache_hit_fresh"], out["cache_hit_fresh_cpu"] = timed(lambda: hit(Cache(Path(d))), n, repeat)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False)
    ap.add_argument("--nodes", default="1000", help="chain length(s), comma-separated (e.g. 1000,10000)")
    ap.add_argument("--repeat", type=int, default=7)
    a = ap.parse_args()
    sizes = [int(x) for x in a.nodes.split(",")]
    results = {n: measure(n, a.repeat if n <= 2000 else max(3, a.repeat // 2)) for n in sizes}
    first = results[sizes[0]]
    print(f"nodes={sizes[0]}")
    for k, v in first.items():
        print(f"{k}_us_per_node={v:.1f}")
    if len(sizes) > 1:
        for n in sizes[1:]:
            for k, v in results[n].items():
                print(f"{k}_us_per_node_at_{n}={v:.1f}")
        last = results[sizes[-1]]
        for k in ("build_and_check", "chain", "cache_hit", "cache_hit_fresh", "build_and_check_cpu", "chain_cpu", "cache_hit_cpu",
                  "cache_hit_fresh_cpu"):
            print(f"linearity_{k}={last[k] / first[k]:.2f}")


if __name__ == "__main__":
    main()
