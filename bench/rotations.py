"""Benchmark: rotation solvers and motion filters on real CMU motion. Prints ``name=value`` lines.

Speed: CMU 131_02 (16 joints) tiled to 10,000 frames; figures are the median of 7 runs divided by the
number of frames (all 16 joints of one frame). The solvers are timed with ``torso_fit`` off (the seed's reference
rotations); ``quaternion_torso_fit_us_per_frame`` is the default (the torso fitted by least squares), on the first
2,000 frames, median of 3 runs. Accuracy, on each trimmed clip in data/mocap/cmu with
bone lengths made constant (filter.bone_length):

* ``<solver>_mpjpe_mm_<clip>``: mean joint position error of the re-posed skeleton (forward kinematics
  of the solved rotations) against the input positions, millimetres (``quaternion_exact``: ``torso_fit`` off).
* ``quaternion_deg_<joint>_<clip>``: mean angle between the solved world rotation of a joint and the
  CMU joint's own (``rotations16_from_bvh``), after removing the constant difference of the two rest
  poses; ``..._nohinge_...`` the same without the hinge refinement (shortest arcs only);
  ``..._hips_triangle_...`` with the hips oriented by the pelvis triangle instead of the spine.

Run: ``python bench/rotations.py``.
"""
from __future__ import annotations

import statistics
import time
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from tbha_graph.mocap import skeleton as sk
from tbha_graph.mocap.filter.bone_length import constant_bone_lengths
from tbha_graph.mocap.lowpass import butterworth_lowpass
from tbha_graph.mocap.filter.one_euro import one_euro_filter
from tbha_graph.mocap.io.skeleton_map import motion16_from_bvh, rotations16_from_bvh
from tbha_graph.mocap.kinematics import forward_kinematics
from tbha_graph.mocap.rotations.kabsch import KabschParams, kabsch_rotations
from tbha_graph.mocap.quat import angle_of, quat_inv, quat_mul
from tbha_graph.mocap.rotations.quaternion import QuaternionParams, quaternion_rotations

DATA = Path(__file__).resolve().parents[1] / "data" / "mocap" / "cmu"
CLIPS = ("131_01", "131_02", "131_03")
N_FRAMES = 10_000
FIT_FRAMES = 2_000
COMPARED = ("hips", "chest", "neck", "left_shoulder", "right_shoulder", "left_elbow", "right_elbow",
            "left_hip", "right_hip", "left_knee", "right_knee")


def median_seconds(fn, repeats: int = 7) -> float:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def fk(rot):
    return forward_kinematics(sk.PARENTS, rot["offsets"], rot["local_quat"], rot["root_position"])


def world_error_deg(rot, truth) -> dict[str, float]:
    _, w = fk(rot)
    _, wt = fk(truth)
    out = {}
    for name in COMPARED:
        j = sk.JOINT_INDEX[name]
        d = quat_mul(quat_inv(wt[:, j]), w[:, j])
        c = Rotation.from_quat(d).mean().inv().as_quat()
        out[name] = float(np.degrees(angle_of(quat_mul(d, c))).mean())
    return out


def speed() -> None:
    m = motion16_from_bvh(DATA / "131_02.bvh")
    reps = -(-N_FRAMES // m["joints"].shape[0])
    joints = np.tile(m["joints"], (reps, 1, 1))[:N_FRAMES]
    fps = float(m["fps"])
    print(f"frames={N_FRAMES}")
    exact = QuaternionParams(torso_fit=False)
    for name, fn in (
        ("quaternion", lambda: quaternion_rotations(joints, fps, exact)),
        ("kabsch", lambda: kabsch_rotations(joints, fps, KabschParams(torso_fit=False))),
        ("one_euro", lambda: one_euro_filter(joints, fps)),
        ("butterworth", lambda: butterworth_lowpass(joints, fps, 7.0, 4)),
        ("bone_length", lambda: constant_bone_lengths(joints)),
    ):
        fn()
        print(f"{name}_us_per_frame={median_seconds(fn) / N_FRAMES * 1e6:.2f}")
    # the torso's least-squares fit (the default, rotations.torso_fit) costs far more: timed on the first FIT_FRAMES
    part = joints[:FIT_FRAMES]
    print(f"quaternion_torso_fit_us_per_frame={median_seconds(lambda: quaternion_rotations(part, fps), 3) / FIT_FRAMES * 1e6:.0f}")


def accuracy() -> None:
    for clip in CLIPS:
        path = DATA / f"{clip}.bvh"
        m = motion16_from_bvh(path)
        joints, fps = constant_bone_lengths(m["joints"]), float(m["fps"])
        truth = rotations16_from_bvh(path)
        for solver, rot in (
            ("quaternion", quaternion_rotations(joints, fps)),
            ("quaternion_exact", quaternion_rotations(joints, fps, QuaternionParams(torso_fit=False))),
            ("kabsch", kabsch_rotations(joints, fps, KabschParams())),
        ):
            pos, _ = fk(rot)
            print(f"{solver}_mpjpe_mm_{clip}={np.linalg.norm(pos - joints, axis=-1).mean() * 1000:.3f}")
        pelvis = QuaternionParams(hips_reference="triangle")
        pos, _ = fk(quaternion_rotations(joints, fps, pelvis))
        print(f"quaternion_hips_triangle_mpjpe_mm_{clip}={np.linalg.norm(pos - joints, axis=-1).mean() * 1000:.3f}")
        for tag, params in (("", QuaternionParams()), ("nohinge_", QuaternionParams(hinge=False)), ("hips_triangle_", pelvis)):
            for name, deg in world_error_deg(quaternion_rotations(joints, fps, params), truth).items():
                print(f"quaternion_{tag}deg_{name}_{clip}={deg:.2f}")


if __name__ == "__main__":
    speed()
    accuracy()
