"""End-to-end throughput and memory of ``pipelines/default.yaml`` on 640x480 renders, cache cold.

For a short take (the bundled 7 s sample) and a take 4x as long (the sample played forwards and
backwards, so the motion stays continuous), in a fresh process each:

* ``pipeline_fps=``: frames / wall time of the capture outputs (BVH, joints, metrics), imports excluded;
* ``pipeline_fps_with_viz=``: the same with the overlay video and plots;
* ``ratio=``: pipeline time over bare decode time of the same file (``cv2.VideoCapture`` read loop);
* ``peak_rss_mb_short=`` / ``peak_rss_mb_long=``: peak resident memory of the process (streamed video:
  it should not grow with the take's length).

Run: ``python bench/pipeline_throughput.py``.
"""
from __future__ import annotations

import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SAMPLE = ROOT / "data" / "sample" / "sample.mp4"
CAPTURE_OUTPUTS = ["motion.bvh", "joints3d.npz", "metrics.json"]


def child(video: str, outputs: list[str], out_dir: str) -> None:
    """Run the pipeline in this (fresh) process; print seconds and peak RSS as JSON."""
    from tbha_graph.core.runner import load_graph, run_graph

    graph = load_graph(ROOT / "pipelines" / "default.yaml", vars={"video": video, "ground_truth": None})
    import cv2  # noqa: F401  (imports outside the timing)
    import matplotlib  # noqa: F401
    import scipy.signal  # noqa: F401

    t0 = time.perf_counter()
    run_graph(graph, out_dir=out_dir, outputs=outputs or None, cache=False)
    seconds = time.perf_counter() - t0
    rss_mb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(json.dumps({"seconds": seconds, "rss_mb": rss_mb}))


def run_child(video: Path, outputs: list[str]) -> dict:
    with tempfile.TemporaryDirectory() as d:
        cmd = [sys.executable, __file__, "--child", str(video), os.path.join(d, "run"), *outputs]
        out = subprocess.run(cmd, capture_output=True, text=True, check=True).stdout.strip().splitlines()[-1]
        return json.loads(out)


def decode_seconds(video: Path) -> tuple[float, int]:
    import cv2

    t0 = time.perf_counter()
    cap = cv2.VideoCapture(str(video))
    n = 0
    while cap.read()[0]:
        n += 1
    return time.perf_counter() - t0, n


def ping_pong(src: Path, dst: Path, times: int) -> None:
    """Write ``src`` forwards, backwards, forwards... (``times`` passes) to ``dst`` (mp4v)."""
    import cv2

    from tbha_graph.mocap.io.video import iter_frames, probe_video

    clip = probe_video(src)
    frames = [f for _, f in iter_frames(clip)]
    wr = cv2.VideoWriter(str(dst), cv2.VideoWriter_fourcc(*"mp4v"), clip.fps, (clip.width, clip.height))
    for i in range(times):
        for f in frames if i % 2 == 0 else frames[::-1]:
            wr.write(f)
    wr.release()


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == "--child":
        child(sys.argv[2], sys.argv[4:], sys.argv[3])
        return
    with tempfile.TemporaryDirectory() as d:
        long_video = Path(d) / "long.mp4"
        ping_pong(SAMPLE, long_video, 4)
        dec_s, n_short = decode_seconds(SAMPLE)
        dec_l, n_long = decode_seconds(long_video)
        short = run_child(SAMPLE, CAPTURE_OUTPUTS)
        long = run_child(long_video, CAPTURE_OUTPUTS)
        viz = run_child(long_video, [])
    print(f"frames_short={n_short}")
    print(f"frames_long={n_long}")
    print(f"pipeline_fps={n_long / long['seconds']:.1f}")
    print(f"pipeline_fps_short={n_short / short['seconds']:.1f}")
    print(f"pipeline_fps_with_viz={n_long / viz['seconds']:.1f}")
    print(f"decode_fps={n_long / dec_l:.1f}")
    print(f"ratio={long['seconds'] / dec_l:.2f}")
    print(f"peak_rss_mb_short={short['rss_mb']:.0f}")
    print(f"peak_rss_mb_long={long['rss_mb']:.0f}")
    print(f"peak_rss_mb_long_with_viz={viz['rss_mb']:.0f}")


if __name__ == "__main__":
    main()
