"""The streaming tight-suit renderer: motion + camera + suit -> an mp4 file and its ground truth.

Frames are rendered one at a time and written as they are made (the video is never held in memory):
resample the motion at the video frame rate (linear interpolation), build the body volumes for a
chunk of frames at once, ray-cast them into a depth buffer (:mod:`.raster`), paint the patches and
shade (:mod:`.shading`) over a precomputed background with contact shadows (:mod:`.background`), then
apply optics blur, exposure flicker and sensor noise (:mod:`.sensor`). Motion blur averages
``motion_blur_samples`` sub-frames spread evenly over the shutter time (centred on the frame time);
the ground truth is always the pose at the frame time itself. Everything is deterministic for a
given ``seed``.
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable, Iterable, Literal

import cv2
import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.atomic import commit, discard, temp_path
from ...core.errors import NodeError
from ...core.node import InputPath
from ..camera import Camera
from ..suit import SuitSpec
from .background import contact_shadows, hex_rgb, make_background
from .body import BodyShape, build_body, patch_centres
from ..io.video_identity import video_identity
from .groundtruth import ground_truth, patch_visibility
from .raster import NEAR, Raster
from .sensor import Sensor
from .shading import Lighting, Shader
from .timeline import MotionSampler

CHUNK = 32  # frames whose body geometry is built in one vectorised call


class RenderParams(BaseModel):
    """Parameters of ``synth.render_suit_video``."""

    model_config = ConfigDict(extra="forbid")

    width: int = Field(640, ge=16, le=4096, multiple_of=2, description="video width", json_schema_extra={"unit": "px"})
    height: int = Field(480, ge=16, le=4096, multiple_of=2, description="video height", json_schema_extra={"unit": "px"})
    fps: float = Field(30.0, gt=0, le=240, description="video frame rate (the motion is resampled)", json_schema_extra={"unit": "1/s"})
    seed: int = Field(0, ge=0, description="seed of the background texture, exposure flicker and sensor noise")
    lighting: Lighting = Field(default_factory=Lighting, description="key/fill/ambient light and suit sheen")
    background: Literal["plain", "room"] = Field("room", description="'room': tiled floor and wall; 'plain': one colour")
    background_color: str = Field("#7d848c", pattern=r"^#?[0-9a-fA-F]{6}$", description="colour of the plain background, sRGB hex")
    shadows: bool = Field(True, description="soft contact shadows on the floor (room background)")
    noise_sigma: float = Field(2.0, ge=0, le=50, description="Gaussian sensor noise", json_schema_extra={"unit": "8-bit levels"})
    exposure_jitter: float = Field(0.01, ge=0, le=0.2, description="frame-to-frame exposure gain std (fraction)")
    optics_blur_px: float = Field(0.6, ge=0, le=10, description="lens blur, Gaussian sigma", json_schema_extra={"unit": "px"})
    motion_blur_samples: int = Field(1, ge=1, le=16, description="sub-frames averaged per frame (1 = no motion blur)")
    shutter: float = Field(0.5, gt=0, le=1, description="exposure time as a fraction of the frame interval")
    suit: InputPath | None = Field(None, description="suit spec YAML (default suit if unset and the suit port is unconnected)")
    body: BodyShape = Field(default_factory=BodyShape, description="sizes of the body volumes")


def fit_camera(camera: Camera, width: int, height: int) -> Camera:
    """The camera rescaled to a ``width`` x ``height`` image (intrinsics scaled; same aspect ratio)."""
    if (camera.width, camera.height) == (width, height):
        return camera
    sx, sy = width / camera.width, height / camera.height
    if abs(sx - sy) > 1e-3 * max(sx, sy):
        raise NodeError(
            f"camera image is {camera.width}x{camera.height} but the video is {width}x{height} (another aspect ratio)",
            hint="set the renderer's width/height to the camera's size, or place the camera with that size",
        )
    K = camera.K.copy()
    K[0, 0] *= sx
    K[1, 1] *= sy
    K[0, 2] = (K[0, 2] + 0.5) * sx - 0.5
    K[1, 2] = (K[1, 2] + 0.5) * sy - 0.5
    return Camera(K=K, R=camera.R, t=camera.t, width=width, height=height, dist=camera.dist)


def check_motion(joints: np.ndarray, fps: float) -> None:
    """Refuse motion the renderer cannot draw, naming the frame."""
    if joints.ndim != 3 or joints.shape[1:] != (16, 3) or joints.shape[0] < 1:
        raise NodeError(f"motion joints have shape {joints.shape}, expected (n_frames, 16, 3) with n_frames >= 1")
    if not np.isfinite(fps) or fps <= 0:
        raise NodeError(f"motion fps is {fps}, expected a positive number of frames per second")
    bad = np.flatnonzero(~np.isfinite(joints).all(axis=(1, 2)))
    if bad.size:
        raise NodeError(
            f"motion frame {int(bad[0])} has non-finite joint positions ({bad.size} such frames)",
            hint="fill gaps in the motion before rendering",
        )


def render_video(
    joints: np.ndarray,
    motion_fps: float,
    camera: Camera,
    suit: SuitSpec,
    params: RenderParams,
    path: Path,
    progress: Callable[..., Iterable] | None = None,
) -> dict[str, np.ndarray]:
    """Render ``joints`` (n, 16, 3) world metres at ``motion_fps`` into the mp4 file ``path`` (written
    atomically), as seen by ``camera``. Returns the ground truth (see :mod:`.groundtruth`)."""
    joints = np.asarray(joints, dtype=np.float64)
    check_motion(joints, float(motion_fps))
    p = params
    cam = fit_camera(camera, p.width, p.height)
    if np.any(cam.dist) or abs(cam.K[0, 1]) > 1e-9:
        raise NodeError(
            "the renderer draws an ideal pinhole camera: the camera's lens distortion and skew must be zero",
            hint="place the camera with synth.camera, or zero 'dist' and K[0][1]",
        )
    sampler = MotionSampler(joints, motion_fps)
    n = sampler.n_frames(p.fps)
    times = np.arange(n) / p.fps
    world = sampler.at(times)
    z = cam.to_camera(world)[..., 2]
    close = np.flatnonzero((z < NEAR + 0.3).any(axis=1))
    if close.size:
        raise NodeError(
            f"at video frame {int(close[0])} a joint is {z[close[0]].min():.2f} m from the camera plane (behind or too close)",
            hint="move the camera back (synth.camera eye) or choose another part of the clip",
        )
    S = p.motion_blur_samples
    offsets = (np.arange(S) / (S - 1) - 0.5) * p.shutter / p.fps if S > 1 else np.zeros(1)

    raster = Raster(cam.K, cam.width, cam.height)
    shader = Shader(raster, p.lighting, cam.R, hex_rgb(suit.suit_color), suit.patch_rgb(), suit.patch_radius)
    rng = np.random.default_rng([int(p.seed), 0])
    bg, floor_xz = make_background(cam, p.background, p.background_color, p.lighting.direction, rng)
    sensor = Sensor(cam.height, cam.width, p.seed, p.noise_sigma, p.exposure_jitter, p.optics_blur_px)
    shadows = p.shadows and p.background == "room"

    patch_world = np.empty((n, 15, 3))
    visible = np.zeros((n, 15), dtype=bool)
    path = Path(path)
    tmp = temp_path(path)
    writer = cv2.VideoWriter(str(tmp), cv2.VideoWriter_fourcc(*"mp4v"), float(p.fps), (cam.width, cam.height))
    if not writer.isOpened():
        raise NodeError(f"cannot open {tmp} for writing an mp4v video", hint="check the folder is writable")
    frames = range(n) if progress is None else progress(range(n), total=n, desc="render")
    acc = np.zeros((cam.height, cam.width, 3), dtype=np.float32) if S > 1 else None
    try:
        for i in frames:
            if i % CHUNK == 0:
                # ground truth at the frame times themselves
                exact = world[i : i + CHUNK]
                g_exact = build_body(exact, p.body)
                patch_world[i : i + CHUNK] = patch_centres(exact, g_exact)[0]
                g_exact_cam = g_exact.transformed(cam.R, cam.t)
                visible[i : i + CHUNK] = patch_visibility(g_exact_cam, cam.to_camera(patch_world[i : i + CHUNK]), cam)
                # what is drawn: the same, or the sub-frames spread over the shutter time
                if S == 1:
                    jw, geom_cam, pc = exact, g_exact_cam, patch_world[i : i + CHUNK]
                else:
                    jw = sampler.at((times[i : i + CHUNK, None] + offsets[None, :]).reshape(-1))
                    geom = build_body(jw, p.body)
                    pc = patch_centres(jw, geom)[0]
                    geom_cam = geom.transformed(cam.R, cam.t)
                pc_cam = cam.to_camera(pc)
            for s in range(S):
                k = (i % CHUNK) * S + s
                raster.draw_body(geom_cam, k)
                frame = bg.copy()
                if shadows:
                    contact_shadows(frame, floor_xz, jw[k], cam)
                shader.shade_into(frame, pc_cam[k])
                if acc is not None:
                    if s == 0:
                        acc[:] = frame
                    else:
                        acc += frame
            if acc is not None:
                frame = (acc * np.float32(1.0 / S) + np.float32(0.5)).astype(np.uint8)
            writer.write(sensor(frame))
        writer.release()
        if not tmp.is_file() or tmp.stat().st_size == 0:
            raise NodeError(f"OpenCV wrote no video to {tmp}", hint="the mp4v encoder may be missing from this OpenCV build")
        commit(tmp, path)
    finally:
        writer.release()
        discard(tmp)
    gt = ground_truth(world, patch_world, visible, cam, p.fps, suit)
    gt.update(video_identity(path, frames=n))  # the truth applies to this video only (io.ground_truth checks it)
    return gt
