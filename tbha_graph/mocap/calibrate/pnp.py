"""``calibrate.pnp``: camera pose from the T-pose with known intrinsics (``cv2.solvePnPGeneric`` + LM polish).

The T-pose joints' world positions are those of the coplanar Tsai node (same calibration world frame:
metres, y up, x = actor's left, actor faces +z, body on the plane z = 0, origin on the floor below the hips;
see :func:`tbha_graph.mocap.calibrate.observations.model_points`). All T-pose joints are coplanar, so
``SOLVEPNP_IPPE`` gives the (up to) two planar solutions; the one with every point in front of the camera
and the camera in front of the actor (z > 0) and the lower reprojection error wins, then
``cv2.solvePnPRefineLM`` polishes it.
"""
from __future__ import annotations

from typing import Annotated

import numpy as np
from pydantic import AfterValidator, BaseModel, ConfigDict, Field, model_validator

from ...core.errors import NodeError
from ...core.node import node, optional
from ..camera import Camera
from ..ports import BODY, CAMERA, TRACKS2D, report_port
from ..body import DEFAULT_ANKLE_HEIGHT
from ..skeleton import CALIBRATION_JOINTS
from ..bundles.tracks import read_tracks
from .observations import check_joint_names, model_points, tpose_observation
from .report import calibration_report


class PnPParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    focal_px: float | None = Field(None, gt=0, description="focal length (square pixels); principal point at the image centre", json_schema_extra={"unit": "px"})
    K: list[list[float]] | None = Field(None, description="full 3x3 intrinsics instead of focal_px", json_schema_extra={"unit": "px"})
    dist: list[float] = Field([0.0] * 5, min_length=5, max_length=5, description="OpenCV distortion coefficients (k1, k2, p1, p2, k3)")
    joints: Annotated[list[str], AfterValidator(check_joint_names)] = Field(
        list(CALIBRATION_JOINTS), min_length=4,
        description="T-pose joints used (all on the torso plane); add limbs (e.g. wrists, ankles) for a steadier pose",
    )
    n_frames: int = Field(10, ge=1, description="number of first frames (all joints tracked) averaged as the T-pose")
    ankle_height: float = Field(DEFAULT_ANKLE_HEIGHT, ge=0, le=0.3, description="ankle joint height above the floor in the T-pose", json_schema_extra={"unit": "m"})

    @model_validator(mode="after")
    def _one_intrinsics(self) -> "PnPParams":
        if (self.focal_px is None) == (self.K is None):
            raise ValueError("give exactly one of focal_px or K")
        if self.K is not None and (len(self.K) != 3 or any(len(r) != 3 for r in self.K)):
            raise ValueError("K must be a 3x3 matrix")
        return self


def solve_pnp_planar(world: np.ndarray, image: np.ndarray, K: np.ndarray, dist: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pose ``(R (3, 3), t (3,))`` world -> camera from coplanar ``world`` (n, 3) metres and ``image`` (n, 2) px.

    Raises ``ValueError`` when OpenCV finds no pose with the points in front of the camera.
    """
    import cv2

    obj = np.ascontiguousarray(world, dtype=np.float64)
    img = np.ascontiguousarray(image, dtype=np.float64)
    n, rvecs, tvecs, errs = cv2.solvePnPGeneric(obj, img, K, dist, flags=cv2.SOLVEPNP_IPPE)
    best, best_key = None, None
    for rvec, tvec, err in zip(rvecs, tvecs, np.ravel(errs) if errs is not None else [0.0] * n):
        R = cv2.Rodrigues(rvec)[0]
        t = tvec.reshape(3)
        in_front = bool(((obj @ R.T + t)[:, 2] > 0).all())
        facing = bool((-R.T @ t)[2] > 0)
        key = (not in_front, not facing, float(err))
        if best_key is None or key < best_key:
            best, best_key = (rvec, tvec), key
    if best is None or best_key[0]:
        raise ValueError("no pose puts the T-pose in front of the camera")
    rvec, tvec = cv2.solvePnPRefineLM(obj, img, K, dist, best[0].copy(), best[1].copy())
    return cv2.Rodrigues(rvec)[0], tvec.reshape(3)


@node(
    "calibrate.pnp",
    version=1,
    inputs={"tracks": TRACKS2D, "body": optional(BODY, "bone lengths; defaults if absent")},
    outputs={"camera": CAMERA, "report": report_port("reprojection errors (px), camera position")},
    params=PnPParams,
)
def pnp(ctx, tracks, body):
    """Camera pose from the T-pose torso with known intrinsics (OpenCV PnP, planar IPPE + LM)."""
    p: PnPParams = ctx.params
    tr = read_tracks(tracks)
    image, used = tpose_observation(tr, p.joints, p.n_frames)
    world = model_points(body, p.ankle_height, p.joints)
    if p.K is not None:
        K = np.asarray(p.K, dtype=np.float64)
    else:
        cx, cy = tr.centre
        K = np.array([[p.focal_px, 0.0, cx], [0.0, p.focal_px, cy], [0.0, 0.0, 1.0]])
    dist = np.asarray(p.dist, dtype=np.float64)
    try:
        R, t = solve_pnp_planar(world, image, K, dist)
    except ValueError as e:
        raise NodeError(
            f"PnP failed on the T-pose of frames {used.tolist()}: {e}",
            hint="check focal_px / K and that the take starts with a T-pose facing the camera",
        ) from None
    cam = Camera(K=K, R=R, t=t, width=tr.width, height=tr.height, dist=dist)
    return {"camera": cam.to_model(), "report": calibration_report(cam, world, image, used, {"method": "pnp"}, p.joints)}
