"""Ground truth of a rendered video: the ``ground_truth`` bundle of ``synth.render_suit_video``.

Keys (one ``.npz``, ``allow_pickle=False``; ``n`` = number of video frames, frame ``i`` at time ``i / fps``):

* ``joints3d_world`` (n, 16, 3) float64, metres, world frame (y up; the actor faces +z in the T-pose):
  the 16 skeleton joints (order of :data:`tbha_graph.mocap.skeleton.JOINT_NAMES`) at each frame time.
* ``joints3d_cam`` (n, 16, 3) float64, metres, camera frame (x right, y down, z forward): ``R @ X + t``.
* ``joints2d`` (n, 16, 2) float64, pixels from the top-left corner (pixel centres at integers):
  the joints projected with ``K``; joints are inside the body, so this is where the tracker should
  report a joint, not the patch centre.
* ``patch_centers_world`` (n, 15, 3) float64, metres, world frame: centre of each coloured patch on
  the suit surface (order of :data:`tbha_graph.mocap.skeleton.PATCHED_JOINTS`).
* ``patch2d`` (n, 15, 2) float64, pixels: the patch centres projected.
* ``patch_visible`` (n, 15) bool: the patch centre projects inside the image and is not hidden by any
  body volume (including its own, so a patch facing away is not visible): the depth test done exactly
  along the ray through the centre, against the primitives the frame was rendered from.
* ``K`` (3, 3) pixels; ``R`` (3, 3) and ``t`` (3,) metres: world -> camera, ``Xc = R @ Xw + t``.
* ``fps`` () float frames/s; ``width``, ``height`` () int pixels.
* ``joint_names`` (16,) str; ``suit`` () str: the suit spec as JSON (:class:`tbha_graph.mocap.suit.SuitSpec`).
* ``bone_lengths`` (16,) float64 metres: median over frames of |joint - parent| (root 0).
* ``video_sha256`` () str, ``video_bytes`` () int, ``video_frames`` () int: the rendered video this truth
  belongs to (added by the renderer; ``io.ground_truth`` refuses the truth for any other video).
"""
from __future__ import annotations

import numpy as np

from ..camera import Camera
from ..skeleton import JOINT_NAMES, measure_bone_lengths
from ..suit import SuitSpec
from .body import BodyGeometry, primitive_roots

VISIBILITY_TOLERANCE = 0.001  # metres: a surface this close in front of a patch centre does not hide it


def patch_visibility(geom_cam: BodyGeometry, centres_cam: np.ndarray, camera: Camera) -> np.ndarray:
    """(n, 15) bool: which patch centres (camera frame (n, 15, 3) metres) are seen by the camera.

    A centre is seen when it projects inside the image and the ray from the camera to it enters no
    body volume before reaching it: the depth-buffer test done exactly at the centre's sub-pixel position,
    on the same primitives (``geom_cam``, camera frame, (n, ...)) the rasteriser draws. A centre on the
    far side of its own volume (a patch facing away) is hidden by that volume.
    """
    c = np.asarray(centres_cam, dtype=np.float64)
    dist = np.linalg.norm(c, axis=-1)  # (n, 15)
    d = c / dist[..., None]
    o = np.zeros_like(c)
    first = np.full(dist.shape, np.inf)
    for k in range(geom_cam.a.shape[-2]):
        t_in, _ = primitive_roots(o, d, geom_cam.a[:, None, k], geom_cam.b[:, None, k], geom_cam.M[:, None, k])
        first = np.minimum(first, np.where(t_in > 0, t_in, np.inf))
    inside = camera.in_image(camera.project_camera(c)) & (c[..., 2] > 0)
    return inside & (first >= dist - VISIBILITY_TOLERANCE)


def ground_truth(
    joints_world: np.ndarray,
    patch_world: np.ndarray,
    visible: np.ndarray,
    camera: Camera,
    fps: float,
    suit: SuitSpec,
) -> dict[str, np.ndarray]:
    """Assemble the ground-truth bundle (keys in the module docstring)."""
    jw = np.asarray(joints_world, dtype=np.float64)
    pw = np.asarray(patch_world, dtype=np.float64)
    return {
        "joints3d_world": jw,
        "joints3d_cam": camera.to_camera(jw),
        "joints2d": camera.project(jw),
        "patch_centers_world": pw,
        "patch2d": camera.project(pw),
        "patch_visible": np.asarray(visible, dtype=bool),
        "K": camera.K.copy(),
        "R": camera.R.copy(),
        "t": camera.t.copy(),
        "fps": np.array(float(fps)),
        "width": np.array(int(camera.width)),
        "height": np.array(int(camera.height)),
        "joint_names": np.array(JOINT_NAMES),
        "suit": np.array(suit.model_dump_json()),
        "bone_lengths": np.median(measure_bone_lengths(jw), axis=0),
    }
