"""Detector keypoint files made from real motion capture, for tests and the bundled examples.

:func:`synthesize_keypoints` takes a CMU BVH clip, opens it with a T-pose lead-in
(:func:`tbha_graph.mocap.synth.tpose_lead_in.lead_in_motion`), resamples it to a video frame rate, films it
with a known pinhole camera and writes what the detectors would have written:

* ``mediapipe.json`` and ``mediapipe.csv``: MediaPipe Pose (33 landmarks, image coordinates normalised to
  [0, 1], ``z`` relative to the hips, ``visibility``; ``world_landmarks`` in metres, camera-aligned axes x
  right, y down, z away from the camera, origin between the hips), in the layouts documented in
  :mod:`tbha_graph.mocap.io.mediapipe_keypoints`;
* ``openpose/<name>_<12-digit frame>_keypoints.json``: one OpenPose file per frame (``BODY_25`` or ``COCO``);
* ``ground_truth.npz``: ``joints3d_world`` (n, 16, 3) m, ``joints2d`` (n, 16, 2) px, ``K``, ``R``, ``t``,
  ``width``, ``height``, ``fps``, ``joint_names`` (the keys of the renderer's ground truth; also a camera
  file for ``calibrate.known``).

Where the landmarks are, from the 16 ground-truth joints (metres, world frame): the limb joints are the
detector's shoulder/elbow/wrist/hip/knee/ankle landmarks. Face points sit on the head: its centre is 0.066 m
above the skull base (``head`` joint) along the neck-to-head direction, the face looks along the body's
forward (shoulder line x head axis); nose 0.10 m in front of the centre, eyes 0.03 m up and 0.085 m in
front, ears 0.075 m to each side, mouth corners 0.045 m down. Hands: index/pinky/thumb 4-9 cm past the
wrist along the forearm. Feet: heel 6 cm behind and 5 cm below the ankle, toes 15 cm in front and 7 cm
below, along the horizontal forward direction. OpenPose's ``Neck`` is the shoulders' midpoint and
``MidHip`` the hips' midpoint (their definitions in its training data).

Detector noise: every 2D landmark gets Gaussian noise (``noise_px``, per axis); occasional occlusion-like
events (``low_confidence_rate`` per landmark and frame, lasting 3-8 frames) drop the confidence to
0.05-0.35 and add ``outlier_px`` of extra error; OpenPose writes ``0, 0, 0`` for parts under 0.1
confidence, as it does for parts it did not find. World landmarks get ``noise_m`` of Gaussian noise.

CLI (writes the bundled set in ``data/keypoints/``)::

    python -m tbha_graph.mocap.synth.keypoints data/mocap/cmu/131_02.bvh data/keypoints/cmu131_02 --duration 3
"""
from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ...core.atomic import atomic_path, atomic_write_text
from ..camera import Camera
from ..skeleton import JOINT_INDEX, JOINT_NAMES
from ..io.keypoint_layouts import MEDIAPIPE_POSE, OPENPOSE_BODY25, OPENPOSE_COCO18, Layout

#: OpenPose part -> MediaPipe landmark (or helper point) it is written from.
_OPENPOSE_FROM = {
    "Nose": "nose", "Neck": "@neck", "RShoulder": "right_shoulder", "RElbow": "right_elbow", "RWrist": "right_wrist",
    "LShoulder": "left_shoulder", "LElbow": "left_elbow", "LWrist": "left_wrist", "MidHip": "@midhip",
    "RHip": "right_hip", "RKnee": "right_knee", "RAnkle": "right_ankle", "LHip": "left_hip", "LKnee": "left_knee",
    "LAnkle": "left_ankle", "REye": "right_eye", "LEye": "left_eye", "REar": "right_ear", "LEar": "left_ear",
    "LBigToe": "left_foot_index", "LSmallToe": "@left_small_toe", "LHeel": "left_heel",
    "RBigToe": "right_foot_index", "RSmallToe": "@right_small_toe", "RHeel": "right_heel",
}


@dataclass(frozen=True)
class SynthOptions:
    """How the keypoint files are made (units in the names)."""

    start: float = 0.0            # s, start of the clip part used
    duration: float | None = 3.0  # s of clip after the lead-in (None: to the end)
    hold_seconds: float = 1.0     # s standing in the T-pose
    blend_seconds: float = 0.5    # s blending into the clip
    fps: float = 30.0             # video frame rate
    width: int = 640
    height: int = 480
    focal_px: float = 700.0
    eye: tuple[float, float, float] = (0.8, 1.45, 4.6)      # camera centre, world metres
    target: tuple[float, float, float] = (0.0, 0.95, 0.0)  # point looked at
    noise_px: float = 1.5
    low_confidence_rate: float = 0.01
    outlier_px: float = 6.0
    noise_m: float = 0.02
    seed: int = 0
    openpose_layout: str = "BODY_25"  # or "COCO"


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def anatomical_points(joints: np.ndarray) -> dict[str, np.ndarray]:
    """Detector landmark positions ``{name: (n, 3)}`` metres world from 16 joints ``(n, 16, 3)``
    (MediaPipe names plus ``@neck``, ``@midhip``, ``@left_small_toe``, ``@right_small_toe``)."""
    J = {n: joints[:, JOINT_INDEX[n]] for n in JOINT_NAMES}
    up_w = np.array([0.0, 1.0, 0.0])
    up_h = _unit(J["head"] - J["neck"])
    side = J["left_shoulder"] - J["right_shoulder"]
    left = _unit(side - np.sum(side * up_h, axis=-1, keepdims=True) * up_h)
    fwd = np.cross(left, up_h)  # x = left, y = up, z = forward is right-handed
    c = J["head"] + 0.066 * up_h
    pts = {n: J[n] for n in ("left_shoulder", "right_shoulder", "left_elbow", "right_elbow", "left_wrist",
                             "right_wrist", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle")}
    pts["nose"] = c + 0.10 * fwd - 0.01 * up_h
    for s, sign in (("left", 1.0), ("right", -1.0)):
        for part, lateral in (("eye_inner", 0.015), ("eye", 0.032), ("eye_outer", 0.045)):
            pts[f"{s}_{part}"] = c + 0.03 * up_h + 0.085 * fwd + sign * lateral * left
        pts[f"{s}_ear"] = c + sign * 0.075 * left - 0.01 * fwd
        pts[f"mouth_{s}"] = c - 0.045 * up_h + 0.08 * fwd + sign * 0.025 * left
        fore = _unit(J[f"{s}_wrist"] - J[f"{s}_elbow"])
        across = _unit(np.cross(fore, fwd))
        pts[f"{s}_pinky"] = J[f"{s}_wrist"] + 0.07 * fore + sign * 0.025 * across
        pts[f"{s}_index"] = J[f"{s}_wrist"] + 0.09 * fore - sign * 0.02 * across
        pts[f"{s}_thumb"] = J[f"{s}_wrist"] + 0.04 * fore - sign * 0.04 * across
        body_fwd = np.cross(_unit(J["left_hip"] - J["right_hip"]), up_w)
        foot = _unit(body_fwd - np.sum(body_fwd * up_w, axis=-1, keepdims=True) * up_w)
        outward = sign * np.cross(up_w, foot)
        pts[f"{s}_heel"] = J[f"{s}_ankle"] - 0.06 * foot - 0.05 * up_w
        pts[f"{s}_foot_index"] = J[f"{s}_ankle"] + 0.15 * foot - 0.07 * up_w
        pts[f"@{s}_small_toe"] = pts[f"{s}_foot_index"] + 0.04 * outward - 0.02 * foot
    pts["@neck"] = 0.5 * (J["left_shoulder"] + J["right_shoulder"])
    pts["@midhip"] = 0.5 * (J["left_hip"] + J["right_hip"])
    return pts


def _resample(joints: np.ndarray, fps_in: float, fps_out: float) -> np.ndarray:
    """Linear resampling of ``(n, 16, 3)`` from ``fps_in`` to ``fps_out`` (frame k at time k / fps_out)."""
    n = joints.shape[0]
    t = np.arange(int(np.floor((n - 1) / fps_in * fps_out + 1e-9)) + 1) / fps_out * fps_in
    i0 = np.minimum(np.floor(t).astype(int), n - 1)
    i1 = np.minimum(i0 + 1, n - 1)
    a = (t - i0)[:, None, None]
    return (1 - a) * joints[i0] + a * joints[i1]


def _events(rng: np.random.Generator, shape: tuple[int, int], rate: float) -> np.ndarray:
    """Bool ``shape`` (frames, landmarks): occlusion-like events of 3-8 frames, ``rate`` of the entries."""
    n, m = shape
    out = np.zeros(shape, dtype=bool)
    if rate <= 0 or n == 0:
        return out
    mean_len = 5.5
    starts = rng.random(shape) < rate / mean_len
    lengths = rng.integers(3, 9, size=shape)
    f, j = np.nonzero(starts)
    for k in range(8):  # spread each start over its length (vectorised over all events)
        keep = k < lengths[f, j]
        out[np.minimum(f[keep] + k, n - 1), j[keep]] = True
    return out


def _detector_view(rng, camera: Camera, world: np.ndarray, o: SynthOptions) -> tuple[np.ndarray, np.ndarray]:
    """Noisy pixels ``(n, L, 2)`` and confidence ``(n, L)`` of landmarks ``(n, L, 3)`` world."""
    px = camera.project(world)
    n, m = px.shape[:2]
    conf = rng.uniform(0.75, 0.99, size=(n, m))
    low = _events(rng, (n, m), o.low_confidence_rate)
    conf[low] = rng.uniform(0.05, 0.35, size=int(low.sum()))
    noise = rng.normal(0.0, o.noise_px, size=px.shape)
    noise[low] += rng.normal(0.0, o.outlier_px, size=(int(low.sum()), 2))
    inside = camera.in_image(px)
    conf[~inside] = np.minimum(conf[~inside], 0.1)
    return px + noise, conf


def _openpose_frames(px: np.ndarray, conf: np.ndarray, layout: Layout) -> list[str]:
    """One OpenPose JSON document per frame (a single person)."""
    docs = []
    flat = np.concatenate([px, conf[..., None]], axis=-1)
    flat[conf < 0.1] = 0.0
    for f in range(flat.shape[0]):
        values = [round(float(v), 3) for v in flat[f].reshape(-1)]
        person = {"person_id": [-1], "pose_keypoints_2d": values, "face_keypoints_2d": [], "hand_left_keypoints_2d": [],
                  "hand_right_keypoints_2d": [], "pose_keypoints_3d": [], "face_keypoints_3d": [],
                  "hand_left_keypoints_3d": [], "hand_right_keypoints_3d": []}
        docs.append(json.dumps({"version": 1.3, "people": [person]}, separators=(",", ":")))
    return docs


def synthesize_keypoints(bvh_path: str | Path, out_dir: str | Path, options: SynthOptions | None = None,
                         name: str | None = None, formats: tuple[str, ...] = ("mediapipe_json", "mediapipe_csv", "openpose")) -> dict[str, Path]:
    """Write detector keypoint files for a CMU clip (see the module docstring); returns the written paths
    by kind (``mediapipe_json``, ``mediapipe_csv``, ``openpose`` (folder), ``ground_truth``)."""
    from .tpose_lead_in import LeadInParams, lead_in_motion

    o = options or SynthOptions()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    name = name or Path(bvh_path).stem
    joints_src, fps_src = lead_in_motion(LeadInParams(path=Path(bvh_path), start=o.start, duration=o.duration,
                                                      hold_seconds=o.hold_seconds, blend_seconds=o.blend_seconds))
    joints = _resample(joints_src, fps_src, o.fps)
    n = joints.shape[0]
    cam = Camera.look_at(o.eye, o.target, focal_px=o.focal_px, width=o.width, height=o.height)
    rng = np.random.default_rng(o.seed)
    anat = anatomical_points(joints)
    written: dict[str, Path] = {}

    gt = {
        "joints3d_world": joints, "joints2d": cam.project(joints), "K": cam.K, "R": cam.R, "t": cam.t,
        "width": np.array(o.width), "height": np.array(o.height), "fps": np.array(float(o.fps)),
        "joint_names": np.array(JOINT_NAMES),
    }
    gt_path = out / "ground_truth.npz"
    with atomic_path(gt_path) as tmp, open(tmp, "wb") as f:
        np.savez(f, **gt)
    written["ground_truth"] = gt_path

    if any(f.startswith("mediapipe") for f in formats):
        world = np.stack([anat[m] for m in MEDIAPIPE_POSE.landmarks], axis=1)  # (n, 33, 3)
        px, vis = _detector_view(rng, cam, world, o)
        cam_pts = cam.to_camera(world)
        hip_mid = 0.5 * (cam_pts[:, MEDIAPIPE_POSE.index("left_hip")] + cam_pts[:, MEDIAPIPE_POSE.index("right_hip")])
        x = px[..., 0] / o.width
        y = px[..., 1] / o.height
        z = (cam_pts[..., 2] - hip_mid[:, None, 2]) / hip_mid[:, None, 2] * o.focal_px / o.width
        wl = (cam_pts - hip_mid[:, None]) + rng.normal(0.0, o.noise_m, size=cam_pts.shape)  # camera axes, metres
        img = np.stack([x.round(5), y.round(5), z.round(4), vis.round(3)], axis=-1)
        wld = np.concatenate([wl.round(4), vis[..., None].round(3)], axis=-1)
        if "mediapipe_json" in formats:
            keys = ("x", "y", "z", "visibility")
            frames = []
            for f in range(n):
                frames.append({
                    "frame": f,
                    "landmarks": [dict(zip(keys, map(float, r))) for r in img[f]],
                    "world_landmarks": [dict(zip(keys, map(float, r))) for r in wld[f]],
                })
            doc = {"format": "mediapipe_pose", "fps": o.fps, "width": o.width, "height": o.height, "frames": frames}
            text = "{" + ",".join(f'"{k}":{json.dumps(v)}' for k, v in doc.items() if k != "frames")
            text += ',"frames":[\n' + ",\n".join(json.dumps(fr, separators=(",", ":")) for fr in frames) + "\n]}\n"
            path = out / "mediapipe.json"
            atomic_write_text(path, text)
            written["mediapipe_json"] = path
        if "mediapipe_csv" in formats:
            lines = ["frame,landmark,x,y,z,visibility,world_x,world_y,world_z"]
            for f in range(n):
                for i in range(MEDIAPIPE_POSE.size):
                    a, w = img[f, i], wld[f, i]
                    lines.append(f"{f},{i},{a[0]:.5f},{a[1]:.5f},{a[2]:.4f},{a[3]:.3f},{w[0]:.4f},{w[1]:.4f},{w[2]:.4f}")
            path = out / "mediapipe.csv"
            atomic_write_text(path, "\n".join(lines) + "\n")
            written["mediapipe_csv"] = path

    if "openpose" in formats:
        layout = {"BODY_25": OPENPOSE_BODY25, "COCO": OPENPOSE_COCO18}[o.openpose_layout]
        world = np.stack([anat[_OPENPOSE_FROM[p]] for p in layout.landmarks], axis=1)
        px, conf = _detector_view(rng, cam, world, o)
        folder = out / "openpose"
        folder.mkdir(exist_ok=True)
        for f, text in enumerate(_openpose_frames(px, conf, layout)):
            atomic_write_text(folder / f"{name}_{f:012d}_keypoints.json", text)
        written["openpose"] = folder
    return written


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, prog="python -m tbha_graph.mocap.synth.keypoints",
                                 description="Write MediaPipe/OpenPose keypoint files and ground truth from a CMU BVH clip.")
    ap.add_argument("bvh", help="BVH clip (CMU skeleton)")
    ap.add_argument("out_dir", help="folder to write into")
    d = SynthOptions()
    ap.add_argument("--start", type=float, default=d.start, help="start of the clip part, s")
    ap.add_argument("--duration", type=float, default=d.duration, help="clip seconds after the T-pose lead-in")
    ap.add_argument("--fps", type=float, default=d.fps)
    ap.add_argument("--noise-px", type=float, default=d.noise_px)
    ap.add_argument("--low-confidence-rate", type=float, default=d.low_confidence_rate)
    ap.add_argument("--seed", type=int, default=d.seed)
    ap.add_argument("--openpose-layout", choices=("BODY_25", "COCO"), default=d.openpose_layout)
    ap.add_argument("--formats", default="mediapipe_json,mediapipe_csv,openpose",
                    help="comma-separated: mediapipe_json, mediapipe_csv, openpose")
    a = ap.parse_args(argv)
    opts = SynthOptions(start=a.start, duration=a.duration, fps=a.fps, noise_px=a.noise_px,
                        low_confidence_rate=a.low_confidence_rate, seed=a.seed, openpose_layout=a.openpose_layout)
    paths = synthesize_keypoints(a.bvh, a.out_dir, opts, formats=tuple(s.strip() for s in a.formats.split(",") if s.strip()))
    for kind, p in paths.items():
        print(f"{kind}={p}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
