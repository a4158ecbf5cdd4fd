"""Every port type the mocap stages exchange, declared once (so producers and consumers agree).

A node declares its ports with these constants and nothing else; ``tbha-graph validate`` checks every
connection with :meth:`PortType.accepts` before anything runs. The value classes and their readers
live with the types in :mod:`tbha_graph.mocap.bundles` (one module per bundle, named below; the body's in
:mod:`tbha_graph.mocap.body` with the T-pose it gives).

Array bundles are :class:`Bundle` s: named kinds of :class:`~tbha_graph.core.types.Arrays` (one ``.npz``
in the cache). A bundle input accepts a bundle of its own kind only (a ground truth never feeds a
``motion`` input even though both are arrays), or a generic ``Arrays`` output whose declared keys fit
(checked again when it runs). Positions are metres, world frame y up, pixels from the top-left, unless
stated.

* ``VIDEO``: :class:`~.bundles.video.VideoClip`, a frame range of a video file, streamed
  (``io.video.iter_frames``); ``VIDEO_FILE``: a video file (``.mp4``).
* ``DETECTIONS``: candidate patch regions per frame and colour class (:mod:`.bundles.detections`).
* ``TRACKS2D``: 2D joint tracks in pixels (:mod:`.bundles.tracks`).
* ``CAMERA``: :class:`~tbha_graph.mocap.camera.CameraModel` (``.camera()`` gives the working camera).
* ``LENS``: :class:`~.bundles.lens.LensEstimate`, a focal length (px, with its sd) found before the take is solved.
* ``BODY``: :class:`~.body.Body`, bone lengths in metres (:mod:`tbha_graph.mocap.body`).
* ``SUIT``: :class:`~tbha_graph.mocap.suit.SuitSpec`; ``COLORS``: :class:`~.bundles.colors.ColorModel`,
  the suit's colours in one colour space (:mod:`.bundles.colors`).
* ``MOTION``: 3D joint positions over time (:mod:`.bundles.motion`).
* ``ROTATIONS``: joint rotations relative to their parents, BVH semantics (:mod:`.bundles.rotations`).
* ``TRUTH``: a rendered video's ground truth, ``{}`` when there is none (:mod:`.bundles.truth`).
* ``SILHOUETTE``: the actor's outline per frame as a distance-outside field (``segment.silhouette``).
* ``SIDES`` (depth side per frame and joint), ``ERRORS`` (per-frame error curves), ``SMPL_PARAMS``
  (AMASS layout), ``JOINTS3D_EXPORT`` (``joints3d.npz``): arrays read by name.
* ``METRICS`` (metrics.json) and ``REPORT`` / :func:`report_port` (a node's report): JSON.
* ``BVH_FILE``, ``IMAGE`` (PNG), ``MESH`` (OBJ): files.
"""
from __future__ import annotations

from ..core.types import Array, Arrays, File, Json, Model, PortType
from .body import Body
from .bundles.colors import ColorModel
from .bundles.detections import DETECTION_KEYS
from .bundles.lens import LensEstimate
from .bundles.video import LensUndistortion, VideoClip
from .camera import CameraModel
from .skeleton import N_JOINTS
from .suit import SuitSpec

__all__ = [
    "Bundle", "VideoClip", "LensUndistortion", "VIDEO", "VIDEO_FILE", "DETECTIONS", "TRACKS2D", "CAMERA", "BODY", "SUIT", "COLORS",
    "LENS", "MOTION", "ROTATIONS", "TRUTH", "SILHOUETTE", "SIDES", "ERRORS", "SMPL_PARAMS", "JOINTS3D_EXPORT", "METRICS", "REPORT", "report_port",
    "BVH_FILE", "IMAGE", "MESH", "JOINTS3D", "JOINTS2D",
]


class Bundle(Arrays):
    """A named kind of :class:`Arrays` bundle (``kind``: ``"motion"``, ``"truth"``...).

    Accepts a bundle of the same kind with at least the declared keys, or a generic (unnamed)
    ``Arrays`` output whose declared keys fit. Stored, validated and hashed as :class:`Arrays`.
    """

    def __init__(self, kind: str, keys: dict[str, Array] | None = None, doc: str = ""):
        super().__init__(keys, doc)
        self.kind = kind

    def describe(self) -> str:
        return self.kind + super().describe()[len("Arrays"):]

    def _accepts(self, other: PortType) -> bool:
        if isinstance(other, Bundle) and other.kind != self.kind:
            return False
        return super()._accepts(other)


JOINTS3D = Array("float", ("n_frames", N_JOINTS, 3), doc="joint positions, metres, world frame")
JOINTS2D = Array("float", ("n_frames", N_JOINTS, 2), doc="joint positions, pixels, top-left origin")

VIDEO = Model(VideoClip, doc="video frames, streamed")
VIDEO_FILE = File(kind="video", suffix=".mp4", doc="a video file")
DETECTIONS = Bundle("detections", DETECTION_KEYS, doc="per-frame candidate patch regions per colour class")
TRACKS2D = Bundle(
    "tracks",
    {"points": JOINTS2D, "tracked": Array("bool", ("n_frames", N_JOINTS)), "fps": Array("float", ())},
    doc="2D joint tracks in pixels",
)
SILHOUETTE = Bundle(
    "silhouette",
    {"distance": Array("uint8", ("n_frames", None, None)), "scale": Array("float", ())},
    doc="per frame, each pixel's distance outside the actor's silhouette (0 inside), uint8 in pixels of the "
        "field's resolution (scale x the frame's; full-resolution px = value / scale, saturating at 255); area_px (n_frames,) "
        "its area and bottom_px (n_frames,) its lowest image row, full-resolution px",
)
CAMERA = Model(CameraModel, doc="calibrated camera")
LENS = Model(LensEstimate, doc="a focal length estimate (px, with its sd) found before the take is solved, or none")
BODY = Model(Body, doc="bone lengths {bone: metres}")
SUIT = Model(SuitSpec, doc="suit colours")
COLORS = Model(ColorModel, doc="suit colours in a colour space")
MOTION = Bundle("motion", {"joints": JOINTS3D, "fps": Array("float", ())}, doc="3D motion of the 16 joints")
ROTATIONS = Bundle(
    "rotations",
    {
        "local_quat": Array("float", ("n_frames", N_JOINTS, 4)),
        "root_position": Array("float", ("n_frames", 3)),
        "offsets": Array("float", (N_JOINTS, 3)),
        "end_offsets": Array("float", (N_JOINTS, 3)),
        "fps": Array("float", ()),
    },
    doc="joint rotations relative to parents (BVH semantics)",
)
TRUTH = Bundle("truth", doc="ground truth of a rendered video (tbha_graph.mocap.synth.groundtruth), or {} when there is none")
SIDES = Bundle(
    "sides", {"sides": Array("int", ("n_frames", N_JOINTS))},
    doc="depth side per (frame, joint): -1 in front of its parent, +1 behind, 0 root/torso",
)
_PER_FRAME = Array("float", ("n_frames",))
ERRORS = Bundle(
    "errors",
    {"mpjpe_mm": _PER_FRAME, "error_2d_px": _PER_FRAME, "reprojection_px": _PER_FRAME, "fps": Array("float", ())},
    doc="per-frame errors (NaN where unavailable): mpjpe_mm, mpjpe_root_mm, pa_mpjpe_mm, error_2d_px (tracked points), placed_2d_px (untracked), reprojection_px; fps",
)
SMPL_PARAMS = Bundle(
    "smpl",
    {
        "poses": Array("float", ("n_frames", 72)),  # 24 SMPL joints x 3 (axis-angle, radians)
        "trans": Array("float", ("n_frames", 3)),
        "betas": Array("float", (None,)),
        "mocap_framerate": Array("float", ()),
    },
    doc="SMPL parameters, AMASS layout: poses (n, 72) rad, trans (n, 3) m, betas (B,), gender, mocap_framerate",
)
JOINTS3D_EXPORT = Bundle("joints3d", doc="joints3d.npz: joints, tracked, joint_names, fps, K, R, t")
METRICS = Json(doc="flat dict of named figures")
REPORT = Json(doc="a node's report: what it did and measured (JSON)")


def report_port(doc: str) -> Json:
    """A ``REPORT`` port with a node's own description of what its report holds."""
    return Json(doc=doc)


BVH_FILE = File(kind="bvh", suffix=".bvh", doc="a BVH motion file")
FBX_FILE = File(kind="fbx", suffix=".fbx", doc="an FBX motion file (export.fbx)")
GLB_FILE = File(kind="glb", suffix=".glb", doc="a binary glTF 2.0 file (export.gltf)")
IMAGE = File(kind="image", suffix=".png", doc="a PNG picture")
MESH = File(kind="mesh", suffix=".obj", doc="an OBJ mesh file")
