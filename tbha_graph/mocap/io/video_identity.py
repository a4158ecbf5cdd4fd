"""Binding a ground truth to the video it belongs to.

A ground truth is only true for one video. The renderer records that video's identity in the truth
bundle (``video_sha256`` (), ``video_bytes`` () and ``video_frames`` ()); ``io.ground_truth`` given the
``video`` that is being captured compares them and refuses a truth that belongs to another video, so an
own take can never be scored against the bundled sample's truth.
"""
from __future__ import annotations

import hashlib
from pathlib import Path

import numpy as np

from ...core.errors import NodeError

IDENTITY_KEYS = ("video_sha256", "video_bytes", "video_frames")


def file_sha256(path: str | Path, chunk: int = 1 << 20) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        while True:
            b = f.read(chunk)
            if not b:
                return h.hexdigest()
            h.update(b)


def video_identity(path: str | Path, frames: int) -> dict[str, np.ndarray]:
    """The arrays a ground truth records about its video: sha256 (hex), size in bytes, frame count."""
    path = Path(path)
    return {"video_sha256": np.array(file_sha256(path)), "video_bytes": np.array(path.stat().st_size, dtype=np.int64),
            "video_frames": np.array(int(frames), dtype=np.int64)}


def check_truth_video(truth: dict[str, np.ndarray], video: str | Path, name: str = "ground truth") -> None:
    """Raise :class:`NodeError` unless ``truth`` records ``video`` as its video (size and sha256) and its
    frame count equals the truth's."""
    video = Path(video)
    way_out = ("a take of your own has no ground truth: pass --var ground_truth=null (the quality figures that need "
               "no truth are still reported); to score a rendered take give the ground_truth.npz rendered with it")
    missing = [k for k in IDENTITY_KEYS if k not in truth]
    if missing:
        raise NodeError(f"{name} does not record which video it belongs to (no {', '.join(missing)}), so it cannot be "
                        f"checked against {video}",
                        hint="re-render it with synth.render_suit_video (pipelines/synthetic.yaml), which records the video's "
                             "sha256, size and frame count; or " + way_out)
    want_sha, want_bytes, want_frames = str(truth["video_sha256"]), int(truth["video_bytes"]), int(truth["video_frames"])
    n = int(np.shape(truth["joints3d_world"])[0])
    if want_frames != n:
        raise NodeError(f"{name} has {n} frames but records a video of {want_frames} frames: the file is inconsistent",
                        hint="re-render it with synth.render_suit_video")
    try:
        size = video.stat().st_size
    except OSError as e:
        raise NodeError(f"cannot read the video {video} to check the ground truth against it: {e.strerror or e}") from None
    sha = file_sha256(video) if size == want_bytes else None
    if size != want_bytes or sha != want_sha:
        raise NodeError(
            f"{name} belongs to another video: it records a video of {want_frames} frames, {want_bytes:,} bytes, sha256 "
            f"{want_sha[:12]}…; {video} has {size:,} bytes{'' if sha is None else f', sha256 {sha[:12]}…'}",
            hint=way_out)
