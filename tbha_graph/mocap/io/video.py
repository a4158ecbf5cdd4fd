"""``io.video``: open a video file as a :class:`~tbha_graph.mocap.ports.VideoClip`, and stream its frames.

The node only checks the file and describes it (path, content hash, frame range, fps, size after
downscaling); it never loads the video. Consumers stream frames with :func:`iter_frames`, which
decodes with ``cv2.VideoCapture`` one frame at a time.

Frames are BGR ``uint8`` arrays of shape ``(height, width, 3)`` (size after ``scale``, then the lens's
distortion taken out when the ``lens`` param names a lens file: :mod:`.lens_file`), pixels from the top-left
corner. Frame indices are those of the file (``start`` .. ``stop - 1``).
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Iterator, Literal

import cv2
import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from ...core.errors import NodeError
from ...core.filehash import file_content_hash
from ...core.node import InputPath, node, optional
from ..ports import VIDEO, VIDEO_FILE, VideoClip
from .avi_cut import avi_cut_frame
from .lens_file import read_lens_file, undistort, view_kept
from .mp4_times import frame_times, uneven_frame_times

_OPEN_HINT = "check that the file is a video OpenCV can decode (e.g. .mp4 with mp4v/H.264, .avi with MJPG)"


class VideoParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    path: InputPath | None = Field(
        None, description="video file to read (relative paths: from the pipeline file's folder); "
        "leave null when the 'file' input is connected (e.g. to a renderer)",
    )
    start: int = Field(0, ge=0, description="first frame to use (inclusive)", json_schema_extra={"unit": "frame"})
    stop: int | None = Field(
        None, ge=1, description="frame to stop before (exclusive); None or beyond the end = to the end",
        json_schema_extra={"unit": "frame"},
    )
    scale: float = Field(1.0, gt=0, le=1, description="downscale factor applied to every frame (1 = full size)")
    fps: float | None = Field(
        None, gt=0, description="frame rate to use when the file does not state one (or to override it)",
        json_schema_extra={"unit": "Hz"},
    )
    lens: InputPath | None = Field(
        None, description="lens.json of pipelines/checkerboard.yaml for this camera (or its Gyroflow lens profile, or "
        "a ROS camera_info YAML): its distortion is removed from every frame as it is read (a wide-angle or action "
        "camera); null: the frames as they are",
    )
    lens_view: Literal["calibrated", "width"] = Field(
        "calibrated", description="with a lens file: the straightened frames keep the calibrated focal length "
        "(calibrated: a fisheye's or wide lens's sides fall outside them, lens.json's view_kept_pct), or the focal "
        "length that keeps the filmed frame's whole width (width: the actor smaller in the middle)",
    )

    @model_validator(mode="after")
    def _range(self) -> "VideoParams":
        if self.stop is not None and self.stop <= self.start:
            raise ValueError(f"stop ({self.stop}) must be greater than start ({self.start})")
        return self


def scaled_size(width: int, height: int, scale: float) -> tuple[int, int]:
    """Frame size ``(width, height)`` in pixels after downscaling by ``scale`` (at least 1 px each)."""
    return max(1, int(round(width * scale))), max(1, int(round(height * scale)))


def _open(path: Path) -> cv2.VideoCapture:
    cap = cv2.VideoCapture(str(path))
    if not cap.isOpened():
        cap.release()
        raise NodeError(
            f"video {path}: OpenCV cannot open it (not a video, an unsupported codec, or an empty or unfinished file)",
            hint=_OPEN_HINT,
        )
    return cap


def probe_video(path: str | Path, start: int = 0, stop: int | None = None, scale: float = 1.0,
                fps: float | None = None, lens: str | Path | None = None, lens_view: str = "calibrated") -> VideoClip:
    """Check a video file and describe the frame range ``[start, stop)`` as a :class:`VideoClip`; ``lens``: a
    lens file (:func:`.lens_file.read_lens_file`, with ``lens_view``) whose distortion :func:`iter_frames` removes
    from every frame.

    Reads the first frame of the range to prove the file decodes. Raises :class:`NodeError` naming the
    file when it does not exist, is not a video, has no frames, or ``start`` lies beyond its end.
    ``stop`` beyond the end is clamped to the end.
    """
    path = Path(path).expanduser().resolve()
    if not path.exists():
        raise NodeError(f"video {path} does not exist", hint="check the path (relative paths are resolved from the pipeline file's folder)")
    if not path.is_file():
        raise NodeError(f"video {path} is not a file", hint="give the path of a video file")
    cap = _open(path)
    try:
        count = int(cap.get(cv2.CAP_PROP_FRAME_COUNT))
        rate = float(cap.get(cv2.CAP_PROP_FPS))
        ok, frame = cap.read()
        if not ok or frame is None:
            raise NodeError(f"video {path} has no frames (or its first frame cannot be decoded)", hint=_OPEN_HINT)
        if count <= 0:  # container does not state its length: count by decoding (rare)
            count = 1
            while cap.grab():
                count += 1
        if start >= count:
            raise NodeError(
                f"video {path}: start frame {start} is beyond the end (the video has {count} frames, 0..{count - 1})",
                hint=f"use a start below {count}",
            )
        cut = avi_cut_frame(path)
        if cut is not None and start >= cut:
            _checked(None, path, start, True, frame, "the start frame", cut)  # raises
        if start > 0:
            cap.set(cv2.CAP_PROP_POS_FRAMES, start)
            ok, frame = cap.read()
            if not ok or frame is None:
                raise NodeError(f"video {path}: frame {start} (the start frame) cannot be decoded", hint=_OPEN_HINT)
        height, width = frame.shape[:2]
    finally:
        cap.release()
    if fps is None:
        if not (math.isfinite(rate) and rate > 0):
            raise NodeError(f"video {path} does not state its frame rate", hint="set the io.video param 'fps'")
        fps = rate
    stop = count if stop is None else min(int(stop), count)
    w, h = scaled_size(width, height, scale)
    return VideoClip(
        path=str(path), sha256=file_content_hash(path), start=int(start), stop=int(stop), scale=float(scale),
        fps=float(fps), width=w, height=h, lens=read_lens_file(lens, width, height, (w, h), lens_view) if lens is not None else None,
    )


def iter_frames(clip: VideoClip, start: int | None = None, stop: int | None = None) -> Iterator[tuple[int, np.ndarray]]:
    """Yield ``(frame_index, frame)`` for the clip's frames (or the sub-range ``[start, stop)`` of file
    frame indices inside it), one at a time; ``frame`` is BGR ``uint8`` ``(clip.height, clip.width, 3)``,
    downscaled with ``cv2.INTER_AREA`` when ``clip.scale < 1``.

    Raises :class:`NodeError` naming the file and the frame number where decoding fails.
    """
    if isinstance(clip, dict):
        clip = VideoClip.model_validate(clip)
    first = clip.start if start is None else max(int(start), clip.start)
    last = clip.stop if stop is None else min(int(stop), clip.stop)
    if first >= last:
        return
    path, cap = _open_clip(clip)
    cut = avi_cut_frame(path)
    try:
        if first > 0:
            cap.set(cv2.CAP_PROP_POS_FRAMES, first)
        for index in range(first, last):
            ok, frame = cap.read()
            yield index, _checked(clip, path, index, ok, frame, f"frames {first}..{last - 1} were requested", cut)
    finally:
        cap.release()


def _open_clip(clip: VideoClip) -> tuple[Path, cv2.VideoCapture]:
    """The clip's file and an open capture of it, or a NodeError when the file is gone."""
    path = Path(clip.path)
    if not path.is_file():
        raise NodeError(f"video {path} does not exist any more", hint="re-run io.video with the video's current path")
    return path, _open(path)


def _checked(clip: VideoClip | None, path: Path, index: int, ok: bool, frame, requested: str,
             cut: int | None = None) -> np.ndarray:
    """Frame ``index`` as :func:`iter_frames` yields it (downscaled when ``clip.scale < 1``), or a NodeError naming
    the file and the frame when it did not decode, lies at or after ``cut`` (an AVI's first frame whose data the file
    does not hold entirely, :func:`.avi_cut.avi_cut_frame`: OpenCV decodes such a frame damaged and says nothing) or
    has another size than ``clip``'s (``clip`` None: only the first two checks)."""
    if cut is not None and index >= cut:
        raise NodeError(
            f"video {path}: the file ends inside frame {cut}'s data ({requested}): a truncated copy",
            hint=f"copy the file again, or set io.video 'stop' to {cut} to use the frames before it" if cut > 0
            else "copy the file again: not one frame of it is whole",
        )
    if not ok or frame is None:
        raise NodeError(
            f"video {path}: decoding failed at frame {index} ({requested})",
            hint="the file may be truncated or corrupt; re-encode it or set io.video 'stop' to end before this frame",
        )
    if clip is None:
        return frame
    if clip.scale < 1.0:
        frame = cv2.resize(frame, (clip.width, clip.height), interpolation=cv2.INTER_AREA)
    elif frame.shape[1] != clip.width or frame.shape[0] != clip.height:
        raise NodeError(
            f"video {path}: frame {index} is {frame.shape[1]}x{frame.shape[0]}, expected {clip.width}x{clip.height}",
            hint="the file changed since io.video read it; re-run io.video",
        )
    return frame if clip.lens is None else undistort(frame, clip.lens)


#: In :func:`iter_frames_at`, frames up to this many apart are reached by decoding the ones between (``grab``), farther
#: ones by seeking: a seek decodes from the last keyframe and costs about as much as decoding 25 frames (640x480 mp4v:
#: 25 frames spread over the bundled sample's 210 took 0.29 s seeking each, 0.08 s decoding through)
SEEK_GAP = 24


def iter_frames_at(clip: VideoClip, indices) -> Iterator[tuple[int, np.ndarray]]:
    """Yield ``(frame_index, frame)`` for the file frame ``indices`` (sorted, unique, inside the clip) as
    :func:`iter_frames` does, from one open file: each frame reached by decoding through from the one before when
    it is at most :data:`SEEK_GAP` frames on, else by seeking. The same frames as :func:`iter_frames` gives."""
    if isinstance(clip, dict):
        clip = VideoClip.model_validate(clip)
    picks = [int(i) for i in indices]
    if not picks:
        return
    if any(b <= a for a, b in zip(picks, picks[1:])) or picks[0] < clip.start or picks[-1] >= clip.stop:
        raise ValueError(f"frame indices must be sorted, unique and within {clip.start}..{clip.stop - 1}: {picks[:5]}...")
    path, cap = _open_clip(clip)
    cut = avi_cut_frame(path)
    try:
        at = 0  # the next frame the capture decodes
        for index in picks:
            if index - at > SEEK_GAP:
                cap.set(cv2.CAP_PROP_POS_FRAMES, index)
                at = index
            while at < index:
                if not cap.grab():
                    _checked(clip, path, at, False, None, f"on the way to frame {index}", cut)  # raises
                at += 1
            ok, frame = cap.read()
            at += 1
            yield index, _checked(clip, path, index, ok, frame, f"frame {index} was requested", cut)
    finally:
        cap.release()


@node(
    "io.video",
    version=4,
    inputs={"file": optional(VIDEO_FILE, "a video produced upstream (instead of the path param)")},
    outputs={"video": VIDEO},
    params=VideoParams,
)
def video(ctx, file) -> dict:
    """Open a video file: check it decodes and describe its frames (streamed later by consumers).

    The file is the ``path`` param, or the ``file`` input when connected (a rendered video).
    Output ``video``: a VideoClip (absolute path, sha256 of the content, frame range [start, stop),
    fps, frame size in pixels after downscaling by ``scale``). Warns when an MP4/QuickTime file's frame times
    over the range are uneven (a variable frame rate or dropped frames, :mod:`.mp4_times`): the capture spaces
    frames evenly.
    """
    p: VideoParams = ctx.params
    if (file is None) == (p.path is None):
        raise NodeError(
            "give the video either as the 'path' param or through the 'file' input, not both or neither",
            hint=f"e.g. --set {ctx.node_id}.path=my_take.mp4",
        )
    clip = probe_video(file if file is not None else p.path, start=p.start, stop=p.stop, scale=p.scale, fps=p.fps,
                       lens=p.lens, lens_view=p.lens_view)
    if clip.lens is not None:
        kept = view_kept(np.array(clip.lens.K), np.array(clip.lens.dist), clip.lens.model, clip.width, clip.height,
                         clip.lens.focal_px)
        ctx.log(f"lens file {Path(clip.lens.source).name} ({clip.lens.model}): frames straightened to a "
                f"{clip.lens.focal_px:.0f} px pinhole camera, showing {100 * kept:.0f} % of the filmed frame"
                + (" (lens_view=width keeps its whole width)" if p.lens_view == "calibrated" and kept < 0.95 else ""))
    times = frame_times(clip.path)
    uneven = uneven_frame_times(times, clip.start, clip.stop) if times is not None and len(times) >= clip.stop else None
    if uneven is not None:
        ctx.warn(uneven_message(Path(clip.path), uneven, clip.fps))
    return {"video": clip}


def uneven_message(path: Path, u: dict, fps: float) -> str:
    """What a user is told about a video whose frame times are uneven (:func:`.mp4_times.uneven_frame_times`)."""
    rate = max(1, round(1e3 / u["median_ms"]))
    gaps = u["gaps"]
    dropped = (f"; {len(gaps)} frame(s) follow a gap of a missing frame or more (frame {', '.join(map(str, gaps[:5]))}"
               f"{', ...' if len(gaps) > 5 else ''})") if gaps else ""
    return (f"video {path.name}: its frame times are uneven (a variable frame rate, as phones record in dim light): "
            f"{u['off']} of {u['intervals']} intervals between frames differ from {u['median_ms']:.1f} ms by more than 10 % "
            f"({u['min_ms']:.1f}-{u['max_ms']:.1f} ms){dropped}. The capture spaces the frames evenly at {fps:.3g} fps, "
            f"so the motion's timing and speeds are off where they differ: convert the video to a constant rate first, "
            f"e.g. ffmpeg -i {path.name} -vf fps={rate} -c:v libx264 -crf 18 {path.stem}_cfr.mp4")
