"""Port types shared by the mocap nodes (one place, so producers and consumers agree).

Bundles (``Arrays``) and their keys; all positions in metres, world frame y up unless stated:

* ``MOTION``: ``joints`` (n_frames, 16, 3) float metres world; ``fps`` () float; optional ``tracked``
  (n_frames, 16) bool (False = missing/inferred), ``joint_names`` (16,) str.
* ``TRACKS2D``: ``points`` (n_frames, 16, 2) float pixels (top-left origin); ``tracked`` (n_frames, 16) bool
  (False: occluded/lost, ``points`` then holds the prediction); ``fps`` (); ``width``, ``height`` () int;
  optional ``confidence`` (n_frames, 16) float.
* ``ROTATIONS``: ``local_quat`` (n_frames, 16, 4) float, scipy order (x, y, z, w), each joint's rotation
  relative to its parent, identity in the rest T-pose; ``root_position`` (n_frames, 3) metres;
  ``offsets`` (16, 3) metres, rest offset of each joint from its parent (root: 0);
  ``end_offsets`` (16, 3) metres, End Site offset of leaf joints (zero elsewhere); ``fps`` ().
  Semantics as in BVH: world_rot[j] = world_rot[parent] * local[j];
  pos[j] = pos[parent] + world_rot[parent] @ offsets[j].
"""
from __future__ import annotations

from pydantic import BaseModel, Field

from ..core.types import Array, Arrays, Json, Model
from .camera import CameraModel
from .skeleton import N_JOINTS
from .suit import SuitSpec

JOINTS3D = Array("float", ("n_frames", N_JOINTS, 3), doc="joint positions, metres, world frame")
JOINTS2D = Array("float", ("n_frames", N_JOINTS, 2), doc="joint positions, pixels, top-left origin")

MOTION = Arrays({"joints": JOINTS3D, "fps": Array("float", ())}, doc="3D motion of the 16 joints")
TRACKS2D = Arrays(
    {"points": JOINTS2D, "tracked": Array("bool", ("n_frames", N_JOINTS)), "fps": Array("float", ())},
    doc="2D joint tracks in pixels",
)
ROTATIONS = Arrays(
    {
        "local_quat": Array("float", ("n_frames", N_JOINTS, 4)),
        "root_position": Array("float", ("n_frames", 3)),
        "offsets": Array("float", (N_JOINTS, 3)),
        "end_offsets": Array("float", (N_JOINTS, 3)),
        "fps": Array("float", ()),
    },
    doc="joint rotations relative to parents (BVH semantics)",
)
CAMERA = Model(CameraModel, doc="calibrated camera")
SUIT = Model(SuitSpec, doc="suit colours")
METRICS = Json(doc="flat dict of named figures")


class VideoClip(BaseModel):
    """A reference to (a frame range of) a video file: what ``io.video`` outputs. Consumers stream
    frames with :func:`tbha_graph.mocap.io.video.iter_frames`; the file is never copied or loaded whole."""

    path: str = Field(description="absolute path of the video file")
    sha256: str = Field(description="content hash of the file (part of downstream cache keys)")
    start: int = Field(0, ge=0, description="first frame index (inclusive)")
    stop: int = Field(description="last frame index (exclusive)")
    scale: float = Field(1.0, gt=0, le=1, description="downscale factor applied to frames")
    fps: float = Field(gt=0, description="frames per second")
    width: int = Field(description="frame width after scaling, pixels")
    height: int = Field(description="frame height after scaling, pixels")

    @property
    def n_frames(self) -> int:
        return self.stop - self.start


VIDEO = Model(VideoClip, doc="video frames, streamed")
