"""H.264 encoding speed of the project's video writer (``io.video_writer``, libx264 through PyAV: the overlay's
and the re-encoded renders' codec) on the bundled sample's 210 frames (640x480), frames decoded beforehand:

    h264_ms_per_frame=        libx264's frame threads (the writer's ``H264_THREADS``)
    h264_slice_ms_per_frame=  PyAV's default threading (slices), for the ratio
    ratio=                    slices over frames (above 1: the writer's setting is the faster)

Medians of ``--repeat`` runs (default 5), wall time. Needs the ``av`` extra.

    python bench/video_encode.py [--repeat 5]
"""
from __future__ import annotations

import argparse
import statistics
import tempfile
import time
from pathlib import Path

from tbha_graph.mocap.io import video_writer
from tbha_graph.mocap.io.video import iter_frames, probe_video

ROOT = Path(__file__).resolve().parents[1]


def encode_ms_per_frame(frames: list, threads: str, out: Path) -> float:
    video_writer.H264_THREADS = threads
    h, w = frames[0].shape[:2]
    t = time.perf_counter()
    with video_writer.open_video_writer(out, 30.0, w, h, codec="h264") as wr:
        for f in frames:
            wr.write(f)
    return (time.perf_counter() - t) * 1000.0 / len(frames)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=5)
    a = ap.parse_args()
    frames = [f for _, f in iter_frames(probe_video(ROOT / "data" / "sample" / "sample.mp4"))]
    default = video_writer.H264_THREADS
    res: dict[str, list[float]] = {default: [], "SLICE": []}
    with tempfile.TemporaryDirectory(prefix="tbha-enc-") as tmp:
        for _ in range(a.repeat):
            for threads in res:
                res[threads].append(encode_ms_per_frame(frames, threads, Path(tmp) / "out.mp4"))
    video_writer.H264_THREADS = default
    ours, slices = statistics.median(res[default]), statistics.median(res["SLICE"])
    print(f"h264_ms_per_frame={ours:.2f}")
    print(f"h264_slice_ms_per_frame={slices:.2f}")
    print(f"ratio={slices / ours:.2f}")


if __name__ == "__main__":
    main()
