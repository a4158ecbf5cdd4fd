"""Speed of the MediaPipe stage on the bundled sample (640x480, 210 frames): decoding alone, Pose alone, and
the node with decoding in line or in its reader thread; ``--repeat`` runs each (default 3), medians printed:

    decode_ms_per_frame=, pose_ms_per_frame= (MediaPipe's process() alone), node_inline_ms_per_frame=,
    node_prefetch_ms_per_frame=, detect_fps= (the node with the reader thread)

    python bench/mediapipe_speed.py [--repeat 3]     (needs the mediapipe extra)
"""
from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from tbha_graph.core.testing import run_node
from tbha_graph.mocap.detect.mediapipe_pose import detect_landmarks, mediapipe_pose
from tbha_graph.mocap.io.video import iter_frames, probe_video

ROOT = Path(__file__).resolve().parents[1]


class _Ctx:
    def progress(self, it, total=None, desc=""):
        return it


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    import cv2

    clip = probe_video(ROOT / "data" / "sample" / "sample.mp4")
    n = clip.n_frames
    res: dict[str, list[float]] = {"decode": [], "pose": [], "node_inline": [], "node_prefetch": []}
    P = mediapipe_pose.params
    for _ in range(a.repeat):
        t = time.perf_counter()
        for _i, f in iter_frames(clip):
            cv2.cvtColor(f, cv2.COLOR_BGR2RGB)
        res["decode"].append((time.perf_counter() - t) * 1000 / n)
        _, timing = detect_landmarks(_Ctx(), clip, P.model_validate({"prefetch": 0, "backfill": False}))
        res["pose"].append(timing["detect_ms_per_frame"])
        for key, depth in (("node_inline", 0), ("node_prefetch", 16)):
            t = time.perf_counter()
            run_node(mediapipe_pose, {"prefetch": depth}, video=clip)
            res[key].append((time.perf_counter() - t) * 1000 / n)
    med = {k: statistics.median(v) for k, v in res.items()}
    for k, v in med.items():
        print(f"{k}_ms_per_frame={v:.1f}")
    print(f"detect_fps={1000.0 / med['node_prefetch']:.1f}")


if __name__ == "__main__":
    main()
