"""``viz.overlay``: the input video with the capture drawn on it, written as an H.264 mp4.

Layers, bottom to top (colours in :mod:`tbha_graph.mocap.viz.style`):

* the 3D motion reprojected with the camera (optional ``motion`` + ``camera``): magenta skeleton;
* the 2D tracks: yellow bones between tracked joints, tracked joints as filled dots; a lost joint as a
  hollow circle where the 3D motion puts it (its reprojection, when the motion is connected), else at the
  tracker's prediction: what the tracker did not see is never drawn as if it had been;
* ground truth (optional ``truth``): thin green crosses at the truth's ``joints2d`` (rescaled to the
  video size), wider than the dots so they show where the tracks are right;
* a legend (top left) and a frame counter with the time (bottom left);
* on doubtful frames: an orange frame border and the reasons (top right). With ``doubtful`` connected
  (``evaluate.metrics``' ``errors``) every reason of metrics.json's ``doubtful_ranges`` (the tracker's, unfilled
  gaps, high reprojection, the actor not seen); without it the tracker's own (the tracks' ``doubtful``); see
  :mod:`tbha_graph.mocap.evaluate.doubtful`.

Frames are streamed one at a time (never the whole video in memory) and written with
:func:`tbha_graph.mocap.io.video_writer.open_video_writer` (H.264 with PyAV, else mp4v with a logged note).
Frame ``i`` of the tracks/motion/truth is frame ``i`` of the clip (``clip.start + i`` of the file).
"""
from __future__ import annotations

from typing import Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.errors import NodeError
from ...core.node import node, optional
from ..bundles.truth import truth_joints2d
from ..io.video import iter_frames
from ..io.video_writer import open_video_writer
from ..ports import CAMERA, ERRORS, MOTION, TRACKS2D, TRUTH, VIDEO, VIDEO_FILE, VideoClip
from ..skeleton import N_JOINTS
from . import draw, style


class OverlayParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    dot_radius: int | None = Field(None, ge=1, le=50, description="joint dot radius; None = from the frame height (5 px at 480 px)",
                                   json_schema_extra={"unit": "px"})
    line_width: int | None = Field(None, ge=1, le=20, description="bone line width; None = from the frame height (2 px at 480 px)",
                                   json_schema_extra={"unit": "px"})
    legend: bool = Field(True, description="draw the legend and the frame counter")
    draw_truth: bool = Field(True, description="draw the ground truth's joints when a truth is connected")
    codec: Literal["auto", "h264", "mp4v"] = Field("auto", description="video codec: auto = H.264 when PyAV is installed, else mp4v")
    preset: Literal["ultrafast", "superfast", "veryfast", "medium"] = Field(
        "ultrafast", description="libx264's speed preset (H.264 only): on the sample ultrafast encodes 2.2x faster "
        "than superfast for a file 25 % larger (1.3 MB for 210 frames); the overlay is for looking, not archiving")


def _check_frames(n: int, array: np.ndarray, what: str, tail: tuple[int, ...]) -> np.ndarray:
    a = np.asarray(array)
    if a.shape != (n, *tail):
        hint = ("give io.ground_truth the start/stop of io.video" if "truth" in what
                else "connect data computed from this same video clip (same io.video start/stop)")
        raise NodeError(f"{what} has shape {a.shape} but the video clip has {n} frames: expected {(n, *tail)}", hint=hint)
    return a


class OverlayLayers:
    """Everything drawn on the frames, checked once: ``points``/``tracked`` (n, 16, 2)/(n, 16) of the
    tracks, optional ``reprojected`` (n, 16, 2) px and ``truth2d`` (n, 16, 2) px; ``lost_at`` (n, 16, 2) px
    where each lost joint's ring goes (the reprojection where finite, else the tracker's prediction); ``doubtful``
    (n,) reason bits (:data:`tbha_graph.mocap.evaluate.doubtful.REASONS`) from ``errors`` (``evaluate.metrics``'
    per-frame errors: every reason) if given, else from the tracks (the tracker's reasons), or None."""

    def __init__(self, n: int, clip: VideoClip, tracks: dict, motion: dict | None, camera, truth: dict | None, draw_truth: bool,
                 errors: dict | None = None):
        self.points = _check_frames(n, tracks["points"], "tracks 'points'", (N_JOINTS, 2)).astype(np.float64)
        self.tracked = _check_frames(n, tracks["tracked"], "tracks 'tracked'", (N_JOINTS,)).astype(bool)
        if (motion is None) != (camera is None):
            raise NodeError("viz.overlay: 'motion' and 'camera' are connected together (the motion is drawn by "
                            "projecting it with the camera); only one of them is connected",
                            hint="connect both inputs, or neither")
        self.reprojected = None
        if motion is not None:
            joints = _check_frames(n, motion["joints"], "motion 'joints'", (N_JOINTS, 3)).astype(np.float64)
            cam = camera.camera()
            with np.errstate(divide="ignore", invalid="ignore"):
                proj = cam.project(joints)
            self.reprojected = np.where((cam.to_camera(joints)[..., 2] > 1e-9)[..., None], proj, np.nan)
        self.lost_at = self.points
        if self.reprojected is not None:
            self.lost_at = np.where(np.isfinite(self.reprojected).all(-1, keepdims=True), self.reprojected, self.points)
        self.doubtful = None
        if errors and "doubtful" in errors:
            self.doubtful = _check_frames(n, errors["doubtful"], "errors 'doubtful'", ()).astype(np.int64)
        elif "doubtful" in tracks and np.shape(tracks["doubtful"]) == (n,):
            self.doubtful = np.asarray(tracks["doubtful"], dtype=np.int64)
        self.truth2d = None
        if truth and draw_truth:
            gt = truth_joints2d(truth, clip.width, clip.height)
            if gt is not None:
                self.truth2d = _check_frames(n, gt, "ground truth 'joints2d'", (N_JOINTS, 2))

    def legend(self) -> list[tuple[str, str, tuple[int, int, int]]]:
        lost = "lost joint (where the 3D puts it)" if self.reprojected is not None else "lost joint (predicted)"
        entries = [("dot", "tracked joint", style.TRACKS_BGR), ("ring", lost, style.TRACKS_BGR)]
        if self.reprojected is not None:
            entries.append(("line", "3D motion reprojected", style.REPROJECTED_BGR))
        if self.truth2d is not None:
            entries.append(("cross", "ground truth", style.TRUTH_BGR))
        return entries


def draw_overlay(frame: np.ndarray, i: int, layers: OverlayLayers, sizes: draw.Sizes) -> np.ndarray:
    """Draw frame ``i``'s layers on ``frame`` (BGR uint8, modified in place and returned); no legend."""
    if layers.reprojected is not None:
        # wider than the tracks' bones: a magenta rim shows around them where 3D and 2D agree
        draw.draw_bones(frame, layers.reprojected[i], style.REPROJECTED_BGR, sizes.line + 2)
    seen = layers.tracked[i]
    draw.draw_bones(frame, np.where(seen[:, None], layers.points[i], np.nan), style.TRACKS_BGR, sizes.line)
    draw.draw_dots(frame, np.where(seen[:, None], layers.points[i], layers.lost_at[i]), seen, style.TRACKS_BGR, sizes.dot, sizes.line)
    if layers.truth2d is not None:  # thin crosses on top, reaching beyond the dots: visible where the tracks are right
        draw.draw_markers(frame, layers.truth2d[i], style.TRUTH_BGR, 2 * sizes.dot + 8, 1)
    if layers.doubtful is not None and layers.doubtful[i]:
        from ..evaluate.doubtful import reason_names

        draw.draw_flag(frame, "doubtful: " + ", ".join(reason_names(int(layers.doubtful[i]))), style.DOUBTFUL_BGR, sizes)
    return frame


@node(
    "viz.overlay",
    version=2,
    inputs={
        "video": VIDEO,
        "tracks": TRACKS2D,
        "motion": optional(MOTION, "3D motion to reproject and draw (needs 'camera')"),
        "camera": optional(CAMERA, "camera of the motion"),
        "truth": optional(TRUTH, "ground truth (io.ground_truth); {} = none"),
        "doubtful": optional(ERRORS, "evaluate.metrics' per-frame errors: their doubtful frames and reasons (all of "
                             "metrics.json's doubtful_ranges) framed in orange; without it, the tracker's"),
    },
    outputs={"video": VIDEO_FILE},
    params=OverlayParams,
)
def overlay(ctx, video, tracks, motion, camera, truth, doubtful):
    """Draw the 2D tracks (filled dots: tracked; hollow: lost, where the 3D puts them), the reprojected 3D skeleton and the
    ground truth on the video, with a legend and frame counter; writes an H.264 mp4 (same size, fps
    and frame count as the input clip)."""
    p: OverlayParams = ctx.params
    clip = video if isinstance(video, VideoClip) else VideoClip.model_validate(video)
    n = clip.n_frames
    layers = OverlayLayers(n, clip, tracks, motion, camera, truth, p.draw_truth, doubtful)
    sizes = draw.Sizes.for_frame(clip.height, p.dot_radius, p.line_width)
    entries = layers.legend()
    path = ctx.output_path("overlay.mp4")
    with open_video_writer(path, clip.fps, clip.width, clip.height, p.codec, preset=p.preset, note=ctx.log) as writer:
        for i, (index, frame) in enumerate(ctx.progress(iter_frames(clip), total=n, desc="overlay")):
            draw_overlay(frame, i, layers, sizes)
            if p.legend:
                draw.draw_legend(frame, entries, sizes)
                draw.draw_counter(frame, f"frame {index}  ({i + 1}/{n})  {i / clip.fps:.2f} s", sizes)
            writer.write(frame)
    return {"video": path}
