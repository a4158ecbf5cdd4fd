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
* ``patch_visible`` (n, 15) bool: the patch centre is inside the image, its patch faces the camera,
  and it is not hidden by the body (depth buffer of the rendered frame, 1.5 cm tolerance).
* ``K`` (3, 3) pixels; ``R`` (3, 3) and ``t`` (3,) metres: world -> camera, ``Xc = R @ Xw + t``.
* ``fps`` () float frames/s; ``width``, ``height`` () int pixels.
* ``joint_names`` (16,) str; ``suit`` () str: the suit spec as JSON (:class:`tbha_graph.mocap.suit.SuitSpec`).
* ``bone_lengths`` (16,) float64 metres: median over frames of |joint - parent| (root 0).
"""
from __future__ import annotations

import numpy as np

from ..camera import Camera
from ..skeleton import JOINT_NAMES, measure_bone_lengths
from ..suit import SuitSpec
from .body import PATCH_ALLOWED
from .raster import Raster

VISIBILITY_TOLERANCE = 0.015  # metres of depth between a patch centre and the visible surface


def patch_visibility(raster: Raster, centres_cam: np.ndarray, dirs_cam: np.ndarray) -> np.ndarray:
    """(15,) bool: which patch centres (camera frame (15, 3) m, outward directions (15, 3)) are seen in
    the frame currently held by ``raster``."""
    c = np.asarray(centres_cam, dtype=np.float64)
    z = c[:, 2]
    ok = z > 1e-6
    zs = np.where(ok, z, 1.0)
    u = np.rint(raster.K[0, 0] * c[:, 0] / zs + raster.K[0, 2]).astype(np.int64)
    v = np.rint(raster.K[1, 1] * c[:, 1] / zs + raster.K[1, 2]).astype(np.int64)
    ok &= (u >= 0) & (u < raster.width) & (v >= 0) & (v < raster.height)
    ok &= np.sum(dirs_cam * -c, axis=1) > 0  # faces the camera (camera at the origin)
    uc, vc = np.clip(u, 0, raster.width - 1), np.clip(v, 0, raster.height - 1)
    depth = raster.depth[vc, uc]
    prim = raster.prim[vc, uc]
    on_patch = PATCH_ALLOWED[np.arange(c.shape[0]), np.where(prim >= 0, prim, 0)] & (prim >= 0)
    return ok & on_patch & (depth >= z - VISIBILITY_TOLERANCE)


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
