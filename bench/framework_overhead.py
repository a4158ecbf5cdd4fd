"""Scheduler overhead per node: a chain of 1,000 trivial nodes, cache disabled and fully cached.

Prints ``chain_us_per_node=`` (cache off) and ``cache_hit_us_per_node=`` (every node a cache hit),
medians of several repetitions. Run: ``python bench/framework_overhead.py [--nodes 1000 --repeat 7]``.
"""
from __future__ import annotations

import argparse
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


def main() -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False)
    ap.add_argument("--nodes", type=int, default=1000)
    ap.add_argument("--repeat", type=int, default=7)
    a = ap.parse_args()
    t0 = time.perf_counter()
    g = chain(a.nodes)
    build_us = (time.perf_counter() - t0) / a.nodes * 1e6
    nocache = []
    for _ in range(a.repeat):
        t = time.perf_counter()
        run_graph(g, cache=False)
        nocache.append((time.perf_counter() - t) / a.nodes * 1e6)
    with tempfile.TemporaryDirectory() as d:
        cache = Cache(Path(d))
        t = time.perf_counter()
        run_graph(g, cache=cache)
        cold = (time.perf_counter() - t) / a.nodes * 1e6
        hits = []
        for _ in range(a.repeat):
            t = time.perf_counter()
            r = run_graph(g, cache=cache)
            hits.append((time.perf_counter() - t) / a.nodes * 1e6)
            assert all(x.status == "cached" for x in r.results.values())
    print(f"nodes={a.nodes}")
    print(f"build_and_check_us_per_node={build_us:.1f}")
    print(f"chain_us_per_node={statistics.median(nocache):.1f}")
    print(f"cache_cold_us_per_node={cold:.1f}")
    print(f"cache_hit_us_per_node={statistics.median(hits):.1f}")


if __name__ == "__main__":
    main()
