"""The local executor's ``jobs`` (nodes run at once): ``pipelines/default.yaml`` and ``pipelines/mediapipe.yaml``
on the bundled sample (210 frames, 640x480), every output written, nothing cached, jobs 1 and 2 in turn
(1 2 1 2 ..., a fresh process each, imports excluded from the time), ``--repeat`` pairs.

Per pipeline ``P``:

* ``P_fps_jobs1=`` / ``P_fps_jobs2=``: frames / median wall time of the run;
* ``P_speedup=``: median over the pairs of wall(jobs 1) / wall(jobs 2) (above 1: two jobs are faster), with
  ``P_speedup_min=`` / ``P_speedup_max=``;
* ``P_cpu_ratio=``: median over the pairs of CPU(jobs 2) / CPU(jobs 1), the process's CPU time (above 1: work
  added by running side by side: threads competing for caches and cores);
* ``P_peak_rss_mb_jobs1=`` / ``P_peak_rss_mb_jobs2=``: peak resident memory (median);
* ``P_same_joints=``: 1 when every run's ``joints3d.npz`` is identical.

``load_before=`` / ``load_after=``: the 1-minute load average (other processes share the cores: on a loaded
machine a second job has no free core to run on). Without the mediapipe extra that pipeline is skipped
(``mediapipe_skipped=1``). Run: ``python bench/executor_jobs.py [--repeat 5] [--pipelines default,mediapipe]``.
"""
from __future__ import annotations

import argparse
import hashlib
import importlib.util
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def child(pipeline: str, jobs: int, out_dir: str) -> None:
    """Run the pipeline in this (fresh) process; print seconds, CPU seconds, peak RSS and the joints' hash as JSON."""
    import numpy as np

    from tbha_graph.core.runner import load_graph, run_graph

    graph = load_graph(ROOT / "pipelines" / f"{pipeline}.yaml")
    import cv2  # noqa: F401  (imports outside the timing)
    import matplotlib  # noqa: F401
    import scipy.signal  # noqa: F401

    t0, c0 = time.perf_counter(), time.process_time()
    run_graph(graph, out_dir=out_dir, cache=False, jobs=jobs)
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    h = hashlib.sha256()
    with np.load(Path(out_dir) / "joints3d.npz", allow_pickle=False) as z:
        for k in sorted(z.files):
            h.update(k.encode() + np.ascontiguousarray(z[k]).tobytes())
        frames = int(z["joints"].shape[0])
    print(json.dumps({"seconds": seconds, "cpu": cpu, "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0,
                      "joints": h.hexdigest(), "frames": frames}))


def run_child(pipeline: str, jobs: int) -> dict:
    with tempfile.TemporaryDirectory() as d:
        cmd = [sys.executable, __file__, "--child", pipeline, str(jobs), os.path.join(d, "run")]
        out = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout.strip().splitlines()[-1]
        return json.loads(out)


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        child(sys.argv[2], int(sys.argv[3]), sys.argv[4])
        return
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5, help="pairs of runs (jobs 1, jobs 2) per pipeline")
    ap.add_argument("--pipelines", default="default,mediapipe")
    a = ap.parse_args()
    print(f"load_before={os.getloadavg()[0]:.2f}", flush=True)
    for name in a.pipelines.split(","):
        if name == "mediapipe" and importlib.util.find_spec("mediapipe") is None:
            print("mediapipe_skipped=1")
            continue
        run_child(name, 1)  # warm-up: the file system cache, the first import of each module
        runs: dict[int, list[dict]] = {1: [], 2: []}
        for _ in range(a.repeat):
            for jobs in (1, 2):
                runs[jobs].append(run_child(name, jobs))
        frames = runs[1][0]["frames"]
        speedup = [r1["seconds"] / r2["seconds"] for r1, r2 in zip(runs[1], runs[2])]
        for jobs in (1, 2):
            print(f"{name}_fps_jobs{jobs}={frames / statistics.median(r['seconds'] for r in runs[jobs]):.1f}")
        print(f"{name}_speedup={statistics.median(speedup):.3f}")
        print(f"{name}_speedup_min={min(speedup):.3f}")
        print(f"{name}_speedup_max={max(speedup):.3f}")
        print(f"{name}_cpu_ratio={statistics.median(r2['cpu'] / r1['cpu'] for r1, r2 in zip(runs[1], runs[2])):.3f}")
        for jobs in (1, 2):
            print(f"{name}_peak_rss_mb_jobs{jobs}={statistics.median(r['rss_mb'] for r in runs[jobs]):.0f}")
        print(f"{name}_same_joints={int(len({r['joints'] for rs in runs.values() for r in rs}) == 1)}", flush=True)
    print(f"load_after={os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
