"""Speed and accuracy of the 3D solvers on CMU 131_02 (720 frames, 120 fps) with a T-pose lead-in.

Prints ``name=value`` lines: frames per second of ``reconstruct.ray_sphere`` and ``reconstruct.sequence_lsq``
(core functions, median of repeats) and their MPJPE in mm against the ground truth, true camera and bones,
for exact 2D and for 1 px Gaussian 2D noise.

    python bench/reconstruct_speed.py [--clip data/mocap/cmu/131_02.bvh] [--repeats 5]

sequence_lsq's LSMR inner loop makes many small BLAS calls: on a busy machine multithreaded OpenBLAS slows
it several-fold; compare with ``OPENBLAS_NUM_THREADS=1 python bench/reconstruct_speed.py``.
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from tbha_graph.mocap.camera import Camera
from tbha_graph.mocap.io.skeleton_map import motion16_from_bvh
from tbha_graph.mocap.reconstruct.lead_in import tpose_lead_in
from tbha_graph.mocap.reconstruct.ray_sphere import solve_ray_sphere
from tbha_graph.mocap.reconstruct.sequence_lsq import SequenceLsqParams, solve_sequence_lsq
from tbha_graph.mocap.skeleton import JOINT_INDEX, measure_bone_lengths

ROOT = Path(__file__).resolve().parents[1]


def take(clip: Path) -> tuple[np.ndarray, Camera, float]:
    m = motion16_from_bvh(clip)
    J = m["joints"].copy()
    chest, hips = JOINT_INDEX["chest"], JOINT_INDEX["hips"]
    lower = [JOINT_INDEX[n] for n in ("hips", "left_hip", "left_knee", "left_ankle", "right_hip", "right_knee", "right_ankle")]
    v = J[:, hips] - J[:, chest]  # make the chest-hips distance rigid (the 16-joint model has no lower back)
    J[:, lower] += (v * (np.linalg.norm(v[0]) / np.linalg.norm(v, axis=1, keepdims=True) - 1.0))[:, None]
    J = tpose_lead_in(J)
    mid = J[:, 0].mean(axis=0)
    cam = Camera.look_at((mid[0], 1.3, J[0, 0, 2] + 4.5), (mid[0], 1.0, mid[2]), focal_px=800.0, width=640, height=480)
    return J, cam, float(m["fps"])


def timed(fn, repeats: int):
    times, out = [], None
    for _ in range(repeats):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return out, float(np.median(times))


def main() -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False)
    ap.add_argument("--clip", type=Path, default=ROOT / "data" / "mocap" / "cmu" / "131_02.bvh")
    ap.add_argument("--repeats", type=int, default=5)
    a = ap.parse_args()
    J, cam, fps = take(a.clip)
    n = len(J)
    lengths = measure_bone_lengths(J[0])
    truth = cam.to_camera(J)
    exact = cam.project(J)
    noisy = exact + np.random.default_rng(0).normal(0.0, 1.0, exact.shape)
    tracked = np.ones(exact.shape[:2], bool)
    mm = lambda P: float(np.linalg.norm(P - truth, axis=-1).mean() * 1000.0)  # noqa: E731
    print(f"frames={n}")
    for rule in ("previous", "velocity"):
        (P, _), dt = timed(lambda: solve_ray_sphere(exact, cam, lengths, continuity=rule), a.repeats)
        if rule == "previous":
            print(f"ray_sphere_fps={n / dt:.0f}")
        print(f"ray_sphere_{rule}_mpjpe_mm_exact={mm(P):.3f}")
        P, _ = solve_ray_sphere(noisy, cam, lengths, continuity=rule)
        print(f"ray_sphere_{rule}_mpjpe_mm_noise1px={mm(P):.1f}")
    (P, rep), dt = timed(lambda: solve_sequence_lsq(noisy, tracked, cam, lengths, fps, SequenceLsqParams()), 1)
    print(f"sequence_lsq_fps={n / dt:.0f}")
    print(f"sequence_lsq_mpjpe_mm_noise1px={mm(P):.1f}")
    P, _ = solve_sequence_lsq(exact, tracked, cam, lengths, fps, SequenceLsqParams())
    print(f"sequence_lsq_mpjpe_mm_exact={mm(P):.1f}")


if __name__ == "__main__":
    main()
