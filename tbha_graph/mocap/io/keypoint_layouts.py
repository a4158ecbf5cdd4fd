"""Keypoint layouts of common pose detectors and their mapping onto the 16 TBHA joints.

Layouts (landmark index -> name; "left"/"right" are the *person's* sides, as the detectors define them):

* :data:`MEDIAPIPE_POSE` - MediaPipe Pose / BlazePose, 33 landmarks (0 nose ... 32 right_foot_index).
* :data:`OPENPOSE_BODY25` - OpenPose ``BODY_25`` (0 Nose, 1 Neck, 2 RShoulder, ..., 8 MidHip, ..., 24 RHeel).
* :data:`OPENPOSE_COCO18` - OpenPose ``COCO`` (18 parts: 0 Nose, 1 Neck, ..., 17 LEar).

Mapping onto the 16 joints (:func:`joints16_from_landmarks`, works on 2D pixels or 3D metres alike).
Detectors see the limbs' joints (shoulders, elbows, wrists, hips, knees, ankles), which map one to one.
They do not see the spine, so the spine joints are placed on the *torso axis*, from the midpoint of the two
hip landmarks ``H`` to the midpoint of the two shoulder landmarks ``S`` (``T = S - H``):

* ``hips``  = ``H + hips_fraction * T``   (the pelvis/abdomen root, above the hip joint centres)
* ``chest`` = ``H + chest_fraction * T``  (upper chest, where the collar bones meet)
* ``neck``  = ``H + neck_fraction * T``   (base of the neck, about shoulder height)
* ``head``  = ``neck + head_fraction * (E - neck)`` with ``E`` the midpoint of the ears (base of the skull,
  on the way from the neck to the centre of the head); only one ear confident: that ear; neither: the nose.

The default fractions are where the reference skeleton puts those joints: measured on the CMU skeleton
that defines the 16 joints (``data/mocap/cmu``, subject 131, T-pose): hips 0.23, chest 0.80, neck 1.03 of
the hip-to-shoulder axis; the skull base is 0.58 of the way from the neck to the head's centre (the ears).

Confidence of a derived joint is the smallest confidence of the landmarks it is built from.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ..skeleton import JOINT_INDEX, JOINT_NAMES, N_JOINTS


@dataclass(frozen=True)
class Layout:
    """A detector's keypoint layout: ``name`` and the landmark names in index order."""

    name: str
    landmarks: tuple[str, ...]

    @property
    def size(self) -> int:
        return len(self.landmarks)

    def index(self, name: str) -> int:
        return self.landmarks.index(name)


MEDIAPIPE_POSE = Layout(
    "mediapipe_pose",
    (
        "nose", "left_eye_inner", "left_eye", "left_eye_outer", "right_eye_inner", "right_eye", "right_eye_outer",
        "left_ear", "right_ear", "mouth_left", "mouth_right", "left_shoulder", "right_shoulder", "left_elbow",
        "right_elbow", "left_wrist", "right_wrist", "left_pinky", "right_pinky", "left_index", "right_index",
        "left_thumb", "right_thumb", "left_hip", "right_hip", "left_knee", "right_knee", "left_ankle", "right_ankle",
        "left_heel", "right_heel", "left_foot_index", "right_foot_index",
    ),
)

OPENPOSE_BODY25 = Layout(
    "BODY_25",
    (
        "Nose", "Neck", "RShoulder", "RElbow", "RWrist", "LShoulder", "LElbow", "LWrist", "MidHip", "RHip", "RKnee",
        "RAnkle", "LHip", "LKnee", "LAnkle", "REye", "LEye", "REar", "LEar", "LBigToe", "LSmallToe", "LHeel",
        "RBigToe", "RSmallToe", "RHeel",
    ),
)

OPENPOSE_COCO18 = Layout(
    "COCO",
    (
        "Nose", "Neck", "RShoulder", "RElbow", "RWrist", "LShoulder", "LElbow", "LWrist", "RHip", "RKnee", "RAnkle",
        "LHip", "LKnee", "LAnkle", "REye", "LEye", "REar", "LEar",
    ),
)

OPENPOSE_LAYOUTS: dict[int, Layout] = {OPENPOSE_BODY25.size: OPENPOSE_BODY25, OPENPOSE_COCO18.size: OPENPOSE_COCO18}

#: The landmarks each layout uses for the 16-joint mapping: TBHA joint or helper point -> landmark name.
_SOURCES: dict[str, dict[str, str]] = {
    MEDIAPIPE_POSE.name: {
        "left_shoulder": "left_shoulder", "right_shoulder": "right_shoulder",
        "left_elbow": "left_elbow", "right_elbow": "right_elbow",
        "left_wrist": "left_wrist", "right_wrist": "right_wrist",
        "left_hip": "left_hip", "right_hip": "right_hip",
        "left_knee": "left_knee", "right_knee": "right_knee",
        "left_ankle": "left_ankle", "right_ankle": "right_ankle",
        "left_ear": "left_ear", "right_ear": "right_ear", "nose": "nose",
    },
}
_OPENPOSE_SOURCES = {
    "left_shoulder": "LShoulder", "right_shoulder": "RShoulder",
    "left_elbow": "LElbow", "right_elbow": "RElbow",
    "left_wrist": "LWrist", "right_wrist": "RWrist",
    "left_hip": "LHip", "right_hip": "RHip",
    "left_knee": "LKnee", "right_knee": "RKnee",
    "left_ankle": "LAnkle", "right_ankle": "RAnkle",
    "left_ear": "LEar", "right_ear": "REar", "nose": "Nose",
}
_SOURCES[OPENPOSE_BODY25.name] = _OPENPOSE_SOURCES
_SOURCES[OPENPOSE_COCO18.name] = _OPENPOSE_SOURCES

#: Limb joints taken one to one from a landmark.
DIRECT_JOINTS: tuple[str, ...] = tuple(n for n in JOINT_NAMES if n.startswith(("left_", "right_")))


class TorsoFractions(BaseModel):
    """Where the unseen spine joints sit on the torso axis (see the module docstring)."""

    model_config = ConfigDict(extra="forbid")

    hips_fraction: float = Field(0.23, ge=-0.5, le=1.0, description="hips (root) on the hip-to-shoulder axis, 0 = hip landmarks' midpoint")
    chest_fraction: float = Field(0.80, ge=0.0, le=1.5, description="chest on the hip-to-shoulder axis, 1 = shoulder landmarks' midpoint")
    neck_fraction: float = Field(1.03, ge=0.5, le=2.0, description="neck on the hip-to-shoulder axis")
    head_fraction: float = Field(0.58, ge=0.0, le=1.5, description="head (skull base) from the neck towards the ears' midpoint")


def joints16_from_landmarks(
    points: np.ndarray,
    confidence: np.ndarray,
    layout: Layout,
    fractions: TorsoFractions | None = None,
    threshold: float = 0.5,
) -> tuple[np.ndarray, np.ndarray]:
    """Map detector landmarks onto the 16 TBHA joints.

    Args:
        points: ``(n_frames, layout.size, D)`` landmark positions, ``D`` = 2 (pixels) or 3 (metres).
        confidence: ``(n_frames, layout.size)`` detector confidence / visibility in [0, 1].
        layout: the detector layout the columns follow.
        fractions: spine placement (defaults: :class:`TorsoFractions`).
        threshold: an ear below this confidence is not used for the head (the other ear or the nose is).

    Returns:
        ``joints`` ``(n_frames, 16, D)`` in the order of :data:`~tbha_graph.mocap.skeleton.JOINT_NAMES` and
        ``confidence`` ``(n_frames, 16)`` (derived joints: the smallest confidence of their landmarks).
    """
    f = fractions or TorsoFractions()
    pts = np.asarray(points, dtype=np.float64)
    conf = np.asarray(confidence, dtype=np.float64)
    if pts.ndim != 3 or pts.shape[1] != layout.size or conf.shape != pts.shape[:2]:
        raise ValueError(f"expected points (n, {layout.size}, D) and confidence (n, {layout.size}) for {layout.name}, "
                         f"got {pts.shape} and {conf.shape}")
    src = {k: layout.index(v) for k, v in _SOURCES[layout.name].items()}
    n, dim = pts.shape[0], pts.shape[2]
    out = np.zeros((n, N_JOINTS, dim))
    out_c = np.zeros((n, N_JOINTS))
    for name in DIRECT_JOINTS:
        out[:, JOINT_INDEX[name]] = pts[:, src[name]]
        out_c[:, JOINT_INDEX[name]] = conf[:, src[name]]

    def p(name: str) -> np.ndarray:
        return pts[:, src[name]]

    def c(name: str) -> np.ndarray:
        return conf[:, src[name]]

    hip_mid = 0.5 * (p("left_hip") + p("right_hip"))
    sh_mid = 0.5 * (p("left_shoulder") + p("right_shoulder"))
    axis = sh_mid - hip_mid
    torso_c = np.minimum.reduce([c("left_hip"), c("right_hip"), c("left_shoulder"), c("right_shoulder")])
    for name, frac in (("hips", f.hips_fraction), ("chest", f.chest_fraction), ("neck", f.neck_fraction)):
        out[:, JOINT_INDEX[name]] = hip_mid + frac * axis
        out_c[:, JOINT_INDEX[name]] = torso_c

    # head: towards the ears' midpoint (one confident ear: that ear; none: the nose)
    w = np.stack([c("left_ear") >= threshold, c("right_ear") >= threshold], axis=1).astype(np.float64)
    ears = np.stack([p("left_ear"), p("right_ear")], axis=1)
    ear_c = np.stack([c("left_ear"), c("right_ear")], axis=1)
    n_ok = w.sum(axis=1)
    safe = np.where(n_ok > 0, n_ok, 1.0)
    centre = np.einsum("fe,fed->fd", w, ears) / safe[:, None]
    centre_c = np.where(n_ok > 0, np.where(w > 0, ear_c, np.inf).min(axis=1), c("nose"))
    centre = np.where((n_ok > 0)[:, None], centre, p("nose"))
    neck = out[:, JOINT_INDEX["neck"]]
    out[:, JOINT_INDEX["head"]] = neck + f.head_fraction * (centre - neck)
    out_c[:, JOINT_INDEX["head"]] = np.minimum(centre_c, torso_c)
    return out, out_c


def fill_untracked(points: np.ndarray, tracked: np.ndarray, seen: np.ndarray | None = None) -> np.ndarray:
    """Points ``(n, J, D)`` with every untracked entry replaced by linear interpolation in time between the
    nearest tracked frames of the same joint (held constant before the first / after the last). A joint
    never tracked is interpolated between the frames where it was ``seen`` at all (``(n, J)`` bool, e.g.
    confidence > 0), when given; a joint never seen keeps its values. Returns a new array."""
    pts = np.array(points, dtype=np.float64, copy=True)
    n = pts.shape[0]
    t = np.arange(n)
    for j in range(pts.shape[1]):
        ok = tracked[:, j] & np.isfinite(pts[:, j]).all(axis=-1)
        if not ok.any() and seen is not None:
            ok = seen[:, j] & np.isfinite(pts[:, j]).all(axis=-1)
        if ok.all() or not ok.any():
            continue
        for d in range(pts.shape[2]):
            pts[~ok, j, d] = np.interp(t[~ok], t[ok], pts[ok, j, d])
    return pts
