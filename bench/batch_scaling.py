"""How ``tbha-graph batch`` scales: the same takes run locally (one after another) and on a Dask
LocalCluster with 1 and 2 workers, cache off (every take computes everything).

Two workloads (``--work``):

* ``bvh`` (default): CMU BVH -> Butterworth -> quaternion rotations -> export.bvh, one take per copy of
  a CMU clip whose 720 frames are repeated ``--repeat-clip`` times (default 75: 54,000 frames, a few
  seconds of work per take, like a real take);
* ``video``: ``pipelines/default.yaml`` (the whole tight-suit pipeline) on the first ``--frames``
  frames of the bundled sample video.

The fixed cost is measured apart from the takes: starting each cluster (``dask<N>_cluster_start_s``)
and warming its workers (``dask<N>_warm_s``: registry and the pipeline's node modules imported in every
worker, :func:`tbha_graph.core.batch.warm_workers`); the batch is then timed on the warm cluster
(``dask<N>_s``), as a long-lived cluster reused batch after batch runs it. Locally the registry is
warmed once too (``local_warm_s``). Prints ``name=value`` lines: ``<executor>_s``,
``<executor>_takes_per_s``, ``<executor>_take_median_s`` (one take, timed inside its worker),
``speedup`` (1 worker over 2 workers, warm clusters) and ``speedup_with_fixed_cost`` (the same with each
cluster's start and warm-up added), and ``machine_parallelism_2proc`` (two pure-Python busy loops at
once over one, measured right after: the speedup the machine itself allows at that moment; on a shared
machine it can be far below 2). Dask workers run one thread each. Run:
``python bench/batch_scaling.py [--work bvh|video] [--takes 8] [--repeat-clip 75] [--frames 60]``.
The machine has 2 cores, shared; numbers vary with its load (``load_average=`` is printed).
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

from tbha_graph.core.batch import Take, _warm, run_batch, warm_workers
from tbha_graph.core.progress import Reporter

REPO = Path(__file__).resolve().parents[1]
CMU = sorted((REPO / "data" / "mocap" / "cmu").glob("*.bvh"))

BVH_PIPELINE = """\
description: CMU BVH -> smoothed -> joint rotations -> BVH (batch benchmark)
vars: {clip: none.bvh}
nodes:
  load: {type: io.bvh_load, params: {path: "${clip}"}}
  smooth: {type: filter.butterworth, inputs: {motion: load.motion}}
  solve: {type: rotations.quaternion, inputs: {motion: smooth.motion}}
  export: {type: export.bvh, inputs: {rotations: solve.rotations}, params: {sheet: false}}
outputs: {motion.bvh: export.bvh}
"""


def long_clip(src: Path, dst: Path, repeat: int) -> None:
    """``src`` with its motion frames repeated ``repeat`` times (a take ``repeat`` x as long)."""
    text = src.read_text()
    head, motion = text.split("MOTION", 1)
    lines = motion.strip("\n").splitlines()
    frames_line, time_line, frames = lines[0], lines[1], lines[2:]
    assert frames_line.startswith("Frames:") and time_line.startswith("Frame Time:")
    dst.write_text(head + "MOTION\n" + f"Frames: {len(frames) * repeat}\n" + time_line + "\n" + "\n".join(frames * repeat) + "\n")


def make_takes(work: str, n: int, frames: int, tmp: Path, repeat_clip: int = 75) -> tuple[Path, list[Take], str]:
    """The pipeline file, ``n`` takes and the variable each take's path is bound to."""
    if work == "bvh":
        pipeline = tmp / "bvh.yaml"
        pipeline.write_text(BVH_PIPELINE)
        takes = []
        for i in range(n):
            src = CMU[i % len(CMU)]
            dst = tmp / f"take{i:02d}_{src.name}"
            long_clip(src, dst, repeat_clip)
            takes.append(Take(dst.stem, str(dst)))
        return pipeline, takes, "clip"
    video = REPO / "data" / "sample" / "sample.mp4"
    truth = REPO / "data" / "sample" / "ground_truth.npz"
    sets = {"decode.stop": frames, "truth.stop": frames, "overlay.codec": "mp4v"}
    takes = [Take(f"take{i:02d}", str(video), {**sets, "truth.path": str(truth)}) for i in range(n)]
    return REPO / "pipelines" / "default.yaml", takes, "video"


def timed(label: str, pipeline: Path, takes: list[Take], var: str, out: Path, **kw) -> tuple[float, float]:
    """Wall time of the whole batch and the median wall time of one take (inside its worker), seconds."""
    t0 = time.perf_counter()
    rows = run_batch(pipeline, takes, out / label, var_name=var, cache=None, reporter=Reporter(quiet=True), **kw)
    seconds = time.perf_counter() - t0
    failed = [r for r in rows if r["status"] != "ok"]
    if failed:
        print(f"error: {len(failed)} take(s) failed under {label}: {failed[0].get('error')}", file=sys.stderr)
        sys.exit(1)
    return seconds, statistics.median(r["wall_s"] for r in rows)


def _busy(n: int) -> float:
    t = time.perf_counter()
    x = 0
    for i in range(n):
        x += i
    return time.perf_counter() - t


def machine_parallelism(n: int = 20_000_000) -> float:
    """What 2 processes get from this machine now: one pure-Python busy loop, then two at once
    (speedup = 2 x one / both; 2.0 on 2 free cores, 1.0 when only one core's worth is free)."""
    import multiprocessing as mp

    one = _busy(n)
    with mp.get_context("spawn").Pool(2) as pool:
        pool.map(_busy, [1000, 1000])  # started
        t = time.perf_counter()
        pool.map(_busy, [n, n])
        both = time.perf_counter() - t
    return 2 * one / both


def on_cluster(workers: int, pipeline: Path, takes: list[Take], var: str, out: Path) -> dict[str, float]:
    """Start a LocalCluster, warm its workers, then time the batch on it; each phase apart."""
    from distributed import Client, LocalCluster

    t0 = time.perf_counter()
    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, dashboard_address=":0")
    client = Client(cluster)
    try:
        client.wait_for_workers(workers)
        start = time.perf_counter() - t0
        t1 = time.perf_counter()
        warm_workers(client, str(pipeline), takes[0], var)
        warm = time.perf_counter() - t1
        seconds, take_s = timed(f"dask{workers}", pipeline, takes, var, out, executor="dask", client=client)
    finally:
        client.close()
        cluster.close()
    return {"cluster_start": start, "warm": warm, "batch": seconds, "take": take_s}


def main() -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--work", choices=["bvh", "video"], default="bvh")
    ap.add_argument("--takes", type=int, default=8)
    ap.add_argument("--repeat-clip", type=int, default=75, help="bvh takes: the clip's frames repeated this many times")
    ap.add_argument("--frames", type=int, default=60, help="video frames per take (--work video)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="batch-bench-") as d:
        tmp = Path(d)
        pipeline, takes, var = make_takes(args.work, args.takes, args.frames, tmp, args.repeat_clip)
        print(f"work={args.work}")
        print(f"takes={len(takes)}")
        print(f"load_average={os.getloadavg()[0]:.1f}" if hasattr(os, "getloadavg") else "load_average=?")
        t0 = time.perf_counter()
        _warm(str(pipeline), takes[0], var, (), None, None, None)  # this process: registry and node modules
        print(f"local_warm_s={time.perf_counter() - t0:.2f}")
        local = timed("local", pipeline, takes, var, tmp / "out")
        d1 = on_cluster(1, pipeline, takes, var, tmp / "out")
        d2 = on_cluster(2, pipeline, takes, var, tmp / "out")
        n = len(takes)
        print(f"local_s={local[0]:.2f}")
        print(f"local_takes_per_s={n / local[0]:.3f}")
        print(f"local_take_median_s={local[1]:.2f}")
        for label, r in (("dask1", d1), ("dask2", d2)):
            print(f"{label}_cluster_start_s={r['cluster_start']:.2f}")
            print(f"{label}_warm_s={r['warm']:.2f}")
            print(f"{label}_s={r['batch']:.2f}")
            print(f"{label}_takes_per_s={n / r['batch']:.3f}")
            print(f"{label}_take_median_s={r['take']:.2f}")
        print(f"dask2_speedup_vs_local={local[0] / d2['batch']:.2f}")
        print(f"takes_per_minute_1worker={60 * n / d1['batch']:.1f}")
        print(f"takes_per_minute_2workers={60 * n / d2['batch']:.1f}")
        fixed1 = d1["cluster_start"] + d1["warm"]
        fixed2 = d2["cluster_start"] + d2["warm"]
        print(f"speedup_with_fixed_cost={(d1['batch'] + fixed1) / (d2['batch'] + fixed2):.2f}")
        print(f"speedup={d1['batch'] / d2['batch']:.2f}")
        print(f"machine_parallelism_2proc={machine_parallelism():.2f}")  # the most 2 workers could get now
    return 0


if __name__ == "__main__":
    sys.exit(main())
