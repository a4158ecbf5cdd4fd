"""``reconstruct.bone_lengths``: the actor's bone lengths ``{joint: metres}`` (bone named by its child joint).

Sources (``method``):

* ``file``: a user's YAML/JSON of measurements ``{bone: metres}``; a partial file is fine, missing bones
  come from :data:`~tbha_graph.mocap.skeleton.DEFAULT_BONE_LENGTHS` scaled by ``height``.
* ``defaults``: the default adult body scaled to ``height``.
* ``tpose``: measured from the T-pose at the start of the take with a calibrated camera: the 2D joints
  (averaged over the first frames) are back-projected onto the actor's coronal plane (the plane facing the
  camera, normal = world +z since the actor faces +z in the T-pose) and the bones measured there. The
  plane's depth is ``plane_z`` (world z, metres) or, if unset, found from the ankles standing on the floor
  (world y = ``ankle_height``). With the camera of ``calibrate.tsai_coplanar`` both give z = 0 (the torso plane
  of its world frame); its torso bones are then those it was given, the limbs are measured.
* ``auto``: ``file`` if ``path`` is set, else ``tpose`` if tracks and camera are connected, else ``defaults``.
"""
from __future__ import annotations

from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.errors import NodeError
from ...core.node import InputPath, node, optional
from ...core.yamlfile import read_data_file
from ..bundles.tracks import read_tracks
from ..calibrate.observations import tpose_observation
from ..ports import BODY, CAMERA, REPORT, TRACKS2D
from ..skeleton import BONES, JOINT_INDEX, JOINT_NAMES, bone_lengths_array
from ..body import DEFAULT_ANKLE_HEIGHT, DEFAULT_STATURE, body_lengths, check_bone_names, lengths_to_body

#: Left/right bone pairs, as child joint indices.
MIRROR_PAIRS = tuple(
    (JOINT_INDEX[n], JOINT_INDEX["right_" + n[5:]]) for n in JOINT_NAMES if n.startswith("left_")
)


class BoneLengthsParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    method: Literal["auto", "file", "defaults", "tpose"] = Field("auto", description="where the lengths come from (see the node doc)")
    path: InputPath | None = Field(None, description="YAML/JSON file of measured bones {bone: metres}, partial allowed")
    height: float = Field(DEFAULT_STATURE, gt=0.5, lt=2.6, description="actor's standing height; scales the default bones", json_schema_extra={"unit": "m"})
    n_frames: int = Field(10, ge=1, description="T-pose frames averaged (tpose method)")
    plane_z: float | None = Field(None, description="world z of the actor's coronal plane in the T-pose (tpose method); None: from the ankles on the floor", json_schema_extra={"unit": "m"})
    ankle_height: float = Field(DEFAULT_ANKLE_HEIGHT, ge=0, le=0.3, description="ankle joint height above the floor (tpose method)", json_schema_extra={"unit": "m"})
    symmetric: bool = Field(True, description="average left and right bones (tpose method)")


def read_measurements(path: Path) -> dict[str, float]:
    """``{bone: metres}`` from a YAML/JSON file; :class:`NodeError` naming the file and bad entry."""
    path = Path(path)
    if not path.is_file():
        raise NodeError(f"bone length file {path} does not exist", hint="check the path (relative to the pipeline file)")
    data = read_data_file(path, "bone lengths", NodeError)  # safe YAML or JSON; errors name the file and line
    if data is None:
        data = {}
    if not isinstance(data, dict):
        raise NodeError(f"{path}: expected a mapping {{bone: metres}}, got {type(data).__name__}")
    check_bone_names(data, str(path))
    body_lengths(data, str(path))  # value checks
    return {k: float(v) for k, v in data.items()}


def scaled_defaults(height: float) -> np.ndarray:
    """Default bone lengths ``(N_JOINTS,)`` metres scaled so the body is ``height`` metres tall."""
    return bone_lengths_array() * (height / DEFAULT_STATURE)


def tpose_lengths(points2d: np.ndarray, cam, plane_z: float | None, ankle_height: float) -> tuple[np.ndarray, float]:
    """Bone lengths ``(N_JOINTS,)`` metres from T-pose pixels ``(N_JOINTS, 2)`` back-projected onto the plane
    world z = ``plane_z`` (or the plane through the ankles' floor points); also returns that plane's z."""
    rays = cam.rays(points2d) @ cam.R  # world directions (N_JOINTS, 3)
    c = cam.center
    if plane_z is None:
        ank = [JOINT_INDEX["left_ankle"], JOINT_INDEX["right_ankle"]]
        dy = rays[ank, 1]
        if np.any(dy >= -1e-9):
            raise NodeError("the ankles' rays do not go down to the floor, so the T-pose plane cannot be placed",
                            hint="set plane_z (world z of the actor's coronal plane)")
        s = (ankle_height - c[1]) / dy
        plane_z = float(np.mean(c[2] + s * rays[ank, 2]))
    dz = rays[:, 2]
    if np.any(np.abs(dz) < 1e-9):
        raise NodeError("a joint's ray is parallel to the actor's plane; the camera must face the actor")
    s = (plane_z - c[2]) / dz
    if np.any(s <= 0):
        raise NodeError(f"the actor's plane z = {plane_z:.3f} m is behind the camera for some joints",
                        hint="check the camera (the actor must face +z, the camera in front of it) or set plane_z")
    pts = c + s[:, None] * rays
    lengths = np.zeros(len(JOINT_NAMES))
    lengths[BONES[:, 1]] = np.linalg.norm(pts[BONES[:, 1]] - pts[BONES[:, 0]], axis=1)
    return lengths, plane_z


@node(
    "reconstruct.bone_lengths",
    version=1,
    inputs={"tracks": optional(TRACKS2D, "2D tracks starting with a T-pose (tpose method)"),
            "camera": optional(CAMERA, "calibrated camera (tpose method)")},
    outputs={"body": BODY, "report": REPORT},
    params=BoneLengthsParams,
)
def bone_lengths(ctx, tracks, camera):
    """Bone lengths from a measurement file, scaled defaults, or the T-pose seen by a calibrated camera."""
    p: BoneLengthsParams = ctx.params
    method = p.method
    if method == "auto":
        method = "file" if p.path is not None else ("tpose" if tracks is not None and camera is not None else "defaults")
    report: dict = {"method": method}
    lengths = scaled_defaults(p.height)
    if method == "file":
        if p.path is None:
            raise NodeError("method 'file' needs a path", hint="set path: my_measurements.yaml")
        given = read_measurements(p.path)
        for name, value in given.items():
            lengths[JOINT_INDEX[name]] = value
        report.update(from_file=sorted(given), from_defaults=sorted(set(lengths_to_body(lengths)) - set(given)))
    elif method == "tpose":
        if tracks is None or camera is None:
            raise NodeError("method 'tpose' needs the tracks and camera inputs connected")
        tr = read_tracks(tracks)
        pts, used = tpose_observation(tr, JOINT_NAMES, p.n_frames)
        lengths, plane_z = tpose_lengths(pts, camera.camera(), p.plane_z, p.ankle_height)
        if p.symmetric:
            for a, b in MIRROR_PAIRS:
                lengths[a] = lengths[b] = 0.5 * (lengths[a] + lengths[b])
        report.update(frames_used=int(len(used)), plane_z_m=plane_z)
    body = lengths_to_body(lengths)
    report.update({f"length_m_{k}": v for k, v in body.items()})
    return {"body": body, "report": report}
