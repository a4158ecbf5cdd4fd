"""Node ``export.joints3d``: the 3D joints a user gets beside the BVH, as one ``joints3d.npz``.

Keys (all ``allow_pickle=False``-safe):

* ``joints`` ``(n_frames, 16, 3)`` metres, world frame (y up): forward kinematics of the exported
  rotations, i.e. exactly where the BVH puts every joint;
* ``joints_solver`` ``(n_frames, 16, 3)`` metres: the 3D solver's (filtered) positions before the
  rotation fit, when ``motion`` is connected;
* ``tracked`` ``(n_frames, 16)`` bool: the joint's patch was seen in that frame;
* ``inferred`` ``(n_frames, 16)`` bool: not seen, filled by ``filter.fill_gaps`` (rigid torso or spline);
  a joint neither tracked nor inferred is missing (its position is the solver's prediction);
* ``joint_names`` ``(16,)`` str; ``fps`` (); ``K`` (3, 3), ``R`` (3, 3), ``t`` (3,) the calibrated camera
  (world -> camera, see :mod:`tbha_graph.mocap.camera`); ``width``, ``height`` ().
"""
from __future__ import annotations

import numpy as np

from ...core.node import node, optional
from ..kinematics import forward_kinematics
from ..ports import CAMERA, JOINTS3D_EXPORT, MOTION, ROTATIONS
from ..skeleton import JOINT_NAMES, N_JOINTS, PARENTS


@node(
    "export.joints3d",
    version=1,
    inputs={"rotations": ROTATIONS, "camera": CAMERA, "motion": optional(MOTION)},
    outputs={"joints3d": JOINTS3D_EXPORT},
)
def export_joints3d(ctx, rotations, camera, motion):
    """3D joints (forward kinematics of the rotations), tracking flags and the camera, as one npz."""
    joints, _ = forward_kinematics(PARENTS, rotations["offsets"], rotations["local_quat"], rotations["root_position"])
    n = joints.shape[0]
    out = {
        "joints": joints,
        "joint_names": np.array(JOINT_NAMES),
        "fps": np.asarray(float(rotations["fps"])),
        "K": np.asarray(camera.K, dtype=np.float64),
        "R": np.asarray(camera.R, dtype=np.float64),
        "t": np.asarray(camera.t, dtype=np.float64),
        "width": np.asarray(camera.width),
        "height": np.asarray(camera.height),
        "tracked": np.ones((n, N_JOINTS), dtype=bool),
    }
    if motion is not None:
        out["joints_solver"] = np.asarray(motion["joints"], dtype=np.float64)
        if "tracked" in motion:
            out["tracked"] = np.asarray(motion["tracked"], dtype=bool)
        out["inferred"] = np.asarray(motion.get("inferred", np.zeros((n, N_JOINTS), bool)), dtype=bool)
    return out
