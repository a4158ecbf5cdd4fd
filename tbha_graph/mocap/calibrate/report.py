"""Helpers shared by the calibrators: pose polishing with OpenCV and the calibration report."""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..camera import Camera


def refine_pose(K: np.ndarray, R: np.ndarray, t: np.ndarray, world: np.ndarray, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Polish a pose with ``cv2.solvePnP`` (iterative, started from R, t); intrinsics fixed."""
    import cv2

    rvec, _ = cv2.Rodrigues(R)
    ok, rvec, tvec = cv2.solvePnP(
        world.astype(np.float64), image.astype(np.float64), K, None, rvec=rvec.copy(), tvec=t.reshape(3, 1).copy(),
        useExtrinsicGuess=True, flags=cv2.SOLVEPNP_ITERATIVE,
    )
    if not ok:
        return R, t
    return cv2.Rodrigues(rvec)[0], tvec.reshape(3)


def calibration_report(cam: Camera, world: np.ndarray, image: np.ndarray, used: np.ndarray, extra: dict, joints: Sequence[str]) -> dict:
    """Flat JSON report: per-joint reprojection error (px), RMS, focal, camera position (world, metres)."""
    err = np.linalg.norm(cam.project(world) - image, axis=1)
    c = cam.center
    depth = cam.to_camera(world)[:, 2]
    report = {
        "frames_used": int(len(used)),
        "first_frame": int(used[0]),
        "focal_px": float(cam.K[0, 0]),
        "reprojection_rms_px": float(np.sqrt(np.mean(err**2))),
        "reprojection_max_px": float(err.max()),
        "camera_x_m": float(c[0]),
        "camera_height_m": float(c[1]),
        "camera_z_m": float(c[2]),
        "actor_distance_m": float(depth.mean()),
        "camera_in_front_of_actor": bool(c[2] > 0),
        "points_in_front_of_camera": bool((depth > 0).all()),
    }
    report.update({f"reprojection_px_{j}": float(e) for j, e in zip(joints, err)})
    report.update(extra)
    return report
