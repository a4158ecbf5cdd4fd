"""Speed (and, on the rendered sample, accuracy) of the 2D chain: decode, segmenters, trackers.

Usage: ``python bench/segment_speed.py [video.mp4] [--frames N] [--repeat R]``. Default video:
``data/sample/sample.mp4`` (with ``ground_truth.npz`` beside it, accuracy is measured too); if it is
missing, a synthetic clip is drawn (:mod:`tbha_graph.mocap.segment.testframes`).

Prints ``name=value`` lines. ``*_fps`` are frames per second of wall-clock time, best of ``--repeat``
runs, on frames already decoded in memory (``decode_fps`` is decoding alone; ``chain_fps`` runs the
nodes io.video -> segment.hierarchical -> track.posture_kalman, decoding included; ``silhouette_fps`` the
actor's outline, segment.silhouette's two passes over the video). ``*_cpu_fps`` use
process CPU time instead (steadier on a busy machine; OpenCV threads count twice). Accuracy:
pixels, over visible patches, against the projected joints (``joints2d``) and patch centres (``patch2d``).
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tbha_graph.core.testing import run_node  # noqa: E402
from tbha_graph.mocap.color.rg_chromaticity import rg_chromaticity  # noqa: E402
from tbha_graph.mocap.io.video import iter_frames, probe_video, video  # noqa: E402
from tbha_graph.mocap.segment.chroma_threshold import ChromaThresholdParams, chroma_threshold, threshold_frame  # noqa: E402
from tbha_graph.mocap.segment.hierarchical import HierarchicalParams, HierarchicalSegmenter, hierarchical  # noqa: E402
from tbha_graph.mocap.segment.labels import PixelClassifier  # noqa: E402
from tbha_graph.mocap.segment.silhouette import SilhouetteParams, silhouette_clip  # noqa: E402
from tbha_graph.mocap.skeleton import JOINT_INDEX, PATCHED_JOINTS  # noqa: E402
from tbha_graph.mocap.track.nearest import nearest  # noqa: E402
from tbha_graph.mocap.track.posture_kalman import posture_kalman  # noqa: E402


def best_of(fn, repeat: int) -> tuple[float, float]:
    """Best wall-clock and best CPU seconds of ``repeat`` calls."""
    wall, cpu = [], []
    for _ in range(repeat):
        w0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - w0)
        cpu.append(time.process_time() - c0)
    return min(wall), min(cpu)


def synthetic_clip(path: Path, n: int) -> None:
    from tbha_graph.mocap.segment.testframes import draw_frame, tpose_points, write_video

    p0 = tpose_points()
    write_video(path, [draw_frame(p0 + [1.5 * t, 0.5 * t], rng=np.random.default_rng(t)) for t in range(n)])


def main() -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("video", nargs="?", default=str(ROOT / "data" / "sample" / "sample.mp4"))
    ap.add_argument("--frames", type=int, default=None, help="use at most this many frames")
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    path = Path(a.video)
    if not path.is_file():
        path = Path(tempfile.mkdtemp()) / "synthetic.mp4"
        synthetic_clip(path, a.frames or 120)
        print(f"video=synthetic ({path})")
    else:
        print(f"video={path}")
    clip = probe_video(path, stop=a.frames)
    n = clip.n_frames
    print(f"frames={n}")
    print(f"size={clip.width}x{clip.height}")

    frames: list[np.ndarray] = []
    wall, cpu = best_of(lambda: frames.__setitem__(slice(None), [f for _, f in iter_frames(clip)]), a.repeat)
    print(f"decode_fps={n / wall:.0f}")

    model = run_node(rg_chromaticity)["model"]

    def run_hier():
        seg = HierarchicalSegmenter(model, HierarchicalParams(), clip.width, clip.height)
        for f in frames:
            seg.process(f)

    clf, ctp = PixelClassifier(model), ChromaThresholdParams()

    def run_thresh():
        for f in frames:
            threshold_frame(f, clf, ctp)

    for name, fn in (("hierarchical", run_hier), ("chroma_threshold", run_thresh)):
        wall, cpu = best_of(fn, a.repeat)
        print(f"{name}_fps={n / wall:.0f}")
        print(f"{name}_cpu_fps={n / cpu:.0f}")

    vclip = run_node(video, {"path": str(path), "stop": a.frames})["video"]
    dets = {s.type.split(".")[1]: run_node(s, video=vclip, colors=model)["detections"] for s in (hierarchical, chroma_threshold)}
    for tr in (posture_kalman, nearest):
        wall, _ = best_of(lambda: run_node(tr, detections=dets["hierarchical"], colors=model), a.repeat)
        print(f"{tr.type.split('.')[1]}_fps={n / wall:.0f}")

    def chain():
        det = run_node(hierarchical, video=vclip, colors=model)["detections"]
        run_node(posture_kalman, detections=det, colors=model)

    wall, cpu = best_of(chain, a.repeat)
    print(f"chain_fps={n / wall:.0f}")
    print(f"chain_cpu_fps={n / cpu:.0f}")

    tracks = run_node(posture_kalman, detections=dets["hierarchical"], colors=model)["tracks"]
    wall, cpu = best_of(lambda: silhouette_clip(vclip, tracks["points"], tracks["tracked"], SilhouetteParams()), a.repeat)
    print(f"silhouette_fps={n / wall:.1f}")  # segment.silhouette's work: two passes over the video, decoding included
    print(f"silhouette_cpu_fps={n / cpu:.1f}")

    gt_path = path.with_name("ground_truth.npz")
    if not gt_path.is_file():
        return
    with np.load(gt_path, allow_pickle=False) as z:
        j2d, p2d, vis = z["joints2d"][:n], z["patch2d"][:n], z["patch_visible"][:n]
    patched = [JOINT_INDEX[j] for j in PATCHED_JOINTS]
    for sname, det in dets.items():
        for tr in (posture_kalman, nearest):
            out = run_node(tr, detections=det, colors=model)["tracks"]
            pts = out["points"][:, patched]
            ej = np.linalg.norm(pts - j2d[:, patched], axis=2)[vis]
            ep = np.linalg.norm(pts - p2d, axis=2)[vis]
            key = f"{sname}_{tr.type.split('.')[1]}"
            print(f"{key}_joints2d_median_px={np.median(ej):.2f}")
            print(f"{key}_joints2d_p95_px={np.percentile(ej, 95):.2f}")
            print(f"{key}_patch2d_median_px={np.median(ep):.2f}")
            print(f"{key}_patch2d_p95_px={np.percentile(ep, 95):.2f}")
            print(f"{key}_tracked_visible_pct={100 * out['tracked'][:, patched][vis].mean():.1f}")
            print(f"{key}_tracked_frames_pct={100 * out['tracked'].all(axis=1).mean():.1f}")
            if tr is posture_kalman:
                eh = np.linalg.norm(out["points"][:, JOINT_INDEX["head"]] - j2d[:, JOINT_INDEX["head"]], axis=1)
                print(f"{sname}_head_joints2d_median_px={np.median(eh):.2f}")


if __name__ == "__main__":
    main()
