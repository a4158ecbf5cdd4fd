"""How ``tbha-graph batch`` scales: the same takes run locally (one after another) and on a Dask
LocalCluster with 1 and 2 workers, cache off (every take computes everything).

Two workloads (``--work``):

* ``bvh`` (default): CMU BVH -> Butterworth -> quaternion rotations -> export.bvh, one take per copy of
  the trimmed CMU clips (720 frames each), about 0.1-1 s of work per take;
* ``video``: ``pipelines/default.yaml`` (the whole tight-suit pipeline) on the first ``--frames``
  frames of the bundled sample video, a few seconds per take.

Prints ``name=value`` lines: ``<executor>_s`` (wall time of the whole batch, including starting the
cluster), ``<executor>_takes_per_s``, ``<executor>_take_median_s`` (one take, timed inside its
worker) and ``dask2_speedup_vs_local``. Dask workers run one thread each (OpenCV and numpy then use
one core per take), while a local take may use both cores. Run:
``python bench/batch_scaling.py [--work bvh|video] [--takes 8] [--frames 60]``. The machine has 2 cores;
numbers vary with its load.
"""
from __future__ import annotations

import argparse
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path

from tbha_graph.core.batch import Take, run_batch
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


def make_takes(work: str, n: int, frames: int, tmp: Path) -> tuple[Path, list[Take], str]:
    """The pipeline file, ``n`` takes and the variable each take's path is bound to."""
    if work == "bvh":
        pipeline = tmp / "bvh.yaml"
        pipeline.write_text(BVH_PIPELINE)
        takes = []
        for i in range(n):
            src = CMU[i % len(CMU)]
            dst = tmp / f"take{i:02d}_{src.name}"
            shutil.copyfile(src, dst)
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


def main() -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--work", choices=["bvh", "video"], default="bvh")
    ap.add_argument("--takes", type=int, default=8)
    ap.add_argument("--frames", type=int, default=60, help="video frames per take (--work video)")
    args = ap.parse_args()
    with tempfile.TemporaryDirectory(prefix="batch-bench-") as d:
        tmp = Path(d)
        pipeline, takes, var = make_takes(args.work, args.takes, args.frames, tmp)
        print(f"work={args.work}")
        print(f"takes={len(takes)}")
        results = {
            "local": timed("local", pipeline, takes, var, tmp / "out"),
            "dask1": timed("dask1", pipeline, takes, var, tmp / "out", executor="dask", workers=1),
            "dask2": timed("dask2", pipeline, takes, var, tmp / "out", executor="dask", workers=2),
        }
        for label, (s, take_s) in results.items():
            print(f"{label}_s={s:.2f}")
            print(f"{label}_takes_per_s={len(takes) / s:.3f}")
            print(f"{label}_take_median_s={take_s:.2f}")
        print(f"dask2_speedup_vs_local={results['local'][0] / results['dask2'][0]:.2f}")
        print(f"dask2_speedup_vs_dask1={results['dask1'][0] / results['dask2'][0]:.2f}")
        # the figures named in the issue: a LocalCluster with 1 vs 2 workers
        print(f"takes_per_minute_1worker={60 * len(takes) / results['dask1'][0]:.1f}")
        print(f"takes_per_minute_2workers={60 * len(takes) / results['dask2'][0]:.1f}")
        print(f"speedup={results['dask1'][0] / results['dask2'][0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
