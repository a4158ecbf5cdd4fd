"""Rendering speed of synth.render_suit_video at 640x480 on one core: prints ``name=value`` lines.

    python bench/render_speed.py [--frames 150] [--motion-blur 1]

The motion is the bundled CMU walk (data/mocap/cmu/131_02.bvh, with its T-pose lead-in) when the
motion reader is available, else a synthetic arm-swinging T-pose. Includes everything the node does:
resampling, body building, ray casting, shading, background and shadows, noise, mp4v encoding and
ground truth. ``render_fps`` is wall-clock (affected by other load on the machine); ``render_cpu_fps``
uses this process's CPU time.
"""
from __future__ import annotations

import os

for _v in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMEXPR_NUM_THREADS"):
    os.environ[_v] = "1"

import argparse  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import cv2  # noqa: E402
import numpy as np  # noqa: E402

cv2.setNumThreads(1)

from tbha_graph.mocap import skeleton  # noqa: E402
from tbha_graph.mocap.camera import Camera  # noqa: E402
from tbha_graph.mocap.suit import load_suit  # noqa: E402
from tbha_graph.mocap.synth.camera import CameraParams  # noqa: E402
from tbha_graph.mocap.synth.render import RenderParams, render_video  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def synthetic_motion(n: int, fps: float) -> np.ndarray:
    """A T-pose whose arms swing down and up again, (n, 16, 3) metres."""
    base = skeleton.tpose()
    base[:, 1] += 0.08 - base[skeleton.JOINT_INDEX["left_ankle"], 1]
    joints = np.repeat(base[None], n, axis=0)
    angle = 0.6 * np.pi * (0.5 - 0.5 * np.cos(2 * np.pi * np.arange(n) / fps / 3.0))
    for side, sign in (("left", 1.0), ("right", -1.0)):
        sh = base[skeleton.JOINT_INDEX[f"{side}_shoulder"]]
        for name in (f"{side}_elbow", f"{side}_wrist"):
            k = skeleton.JOINT_INDEX[name]
            r = abs(base[k, 0] - sh[0])
            joints[:, k, 0] = sh[0] + sign * r * np.cos(angle)
            joints[:, k, 1] = sh[1] - r * np.sin(angle)
    return joints


def bundled_motion(n: int) -> tuple[np.ndarray, float] | None:
    bvh = ROOT / "data" / "mocap" / "cmu" / "131_02.bvh"
    try:
        from tbha_graph.core.testing import run_node
        from tbha_graph.mocap.synth.tpose_lead_in import tpose_lead_in

        m = run_node(tpose_lead_in, {"path": str(bvh), "duration": max(n / 30.0 - 1.0, 0.1)})["motion"]
        return m["joints"], float(m["fps"])
    except Exception:  # the motion reader is not there yet: fall back
        return None


def main() -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=150)
    ap.add_argument("--motion-blur", type=int, default=1)
    args = ap.parse_args()
    got = bundled_motion(args.frames)
    joints, fps = got if got is not None else (synthetic_motion(args.frames, 30.0), 30.0)
    cp = CameraParams()
    cam = Camera.look_at(cp.eye, cp.target, focal_px=cp.focal_px, width=cp.width, height=cp.height)
    params = RenderParams(motion_blur_samples=args.motion_blur)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "bench.mp4"
        render_video(joints[:2], fps, cam, load_suit(), params, out)  # warm-up
        t0, c0 = time.perf_counter(), time.process_time()
        gt = render_video(joints, fps, cam, load_suit(), params, out)
        dt, cpu = time.perf_counter() - t0, time.process_time() - c0
        n = gt["joints2d"].shape[0]
        print(f"motion={'cmu_131_02' if got is not None else 'synthetic'}")
        print(f"frames={n}")
        print(f"size={params.width}x{params.height}")
        print(f"motion_blur_samples={args.motion_blur}")
        print(f"render_seconds={dt:.3f}")
        print(f"render_fps={n / dt:.1f}")
        print(f"render_cpu_fps={n / cpu:.1f}")  # CPU time of this process: less sensitive to other load
        print(f"mp4_kib_per_frame={out.stat().st_size / 1024 / n:.1f}")


if __name__ == "__main__":
    main()
