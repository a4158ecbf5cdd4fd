"""``io.ground_truth``: read a ``ground_truth.npz`` (as written by ``synth.render_suit_video``), or give
``{}`` when there is none (a user's own video: every consumer treats ``{}`` as "no ground truth").

Keys, units and frames are documented in :mod:`tbha_graph.mocap.synth.groundtruth`. Required here:
``joints3d_world`` (n, 16, 3) metres world frame and ``fps`` (); the other documented keys are checked
when present: ``joints3d_cam`` (n, 16, 3) m, ``joints2d`` (n, 16, 2) px, ``patch_centers_world``
(n, 15, 3) m, ``patch2d`` (n, 15, 2) px, ``patch_visible`` (n, 15) bool, ``K``/``R`` (3, 3), ``t`` (3,),
``width``/``height`` () px, ``joint_names`` (16,) (must equal the skeleton's joint order).

With ``video`` given, the truth must record that video's sha256, size and frame count (``video_sha256``,
``video_bytes``, ``video_frames``, written by the renderer): a truth is never applied to another video
(:mod:`tbha_graph.mocap.io.video_identity`).

``start``/``stop`` cut the per-frame arrays to the frame range decoded by ``io.video`` (give both nodes
the same values), so frame ``i`` of the truth stays frame ``i`` of the motion.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, model_validator

from ...core.errors import NodeError
from ...core.npzfile import read_npz
from ...core.node import InputPath, node
from ..bundles.truth import PER_FRAME_SHAPES, check_ground_truth
from ..ports import TRUTH
from .video_identity import check_truth_video

class GroundTruthParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    path: InputPath | None = Field(
        None, description="ground_truth.npz of a rendered video; null = no ground truth (a real video)"
    )
    video: InputPath | None = Field(
        None, description="the video being captured: the truth must record its sha256, size and frame count "
                          "(a mismatch is an error); null = not checked"
    )
    start: int = Field(0, ge=0, description="first frame to keep (inclusive): the same as io.video's start",
                       json_schema_extra={"unit": "frame"})
    stop: int | None = Field(None, ge=1, description="frame to stop before (exclusive), None = to the end: the same as io.video's stop",
                             json_schema_extra={"unit": "frame"})

    @model_validator(mode="after")
    def _range(self) -> "GroundTruthParams":
        if self.stop is not None and self.stop <= self.start:
            raise ValueError(f"stop ({self.stop}) must be greater than start ({self.start})")
        return self


def _read_npz(path: Path) -> dict[str, np.ndarray]:
    return read_npz(path, "ground truth", hint="use an intact ground_truth.npz written by synth.render_suit_video, "
                    "check the path (relative paths are resolved from the pipeline file's folder), or set path to null")


def slice_frames(truth: dict[str, np.ndarray], start: int = 0, stop: int | None = None, name: str = "ground truth") -> dict[str, np.ndarray]:
    """The per-frame arrays of ``truth`` cut to frames ``[start, stop)`` (``stop`` beyond the end is clamped)."""
    n = truth["joints3d_world"].shape[0]
    if start >= n:
        raise NodeError(f"{name}: start frame {start} is beyond its {n} frames", hint=f"use a start below {n}")
    stop = n if stop is None else min(int(stop), n)
    return {k: (v[start:stop] if k in PER_FRAME_SHAPES else v) for k, v in truth.items()}


def load_ground_truth(path: str | Path, start: int = 0, stop: int | None = None) -> dict[str, np.ndarray]:
    """Read and check ``path`` (a ground_truth.npz), cut to frames ``[start, stop)``."""
    path = Path(path).expanduser()
    truth = check_ground_truth(_read_npz(path), name=f"ground truth {path}")
    return slice_frames(truth, start, stop, name=f"ground truth {path}")


@node("io.ground_truth", version=2, outputs={"truth": TRUTH}, params=GroundTruthParams)
def ground_truth(ctx) -> dict:
    """Read a rendered video's ground truth (ground_truth.npz), or output {} when path is null.

    With ``video`` set, the truth must belong to that video (the sha256, size and frame count it
    records); a truth of another video is an error, never a misleading accuracy figure.

    Output ``truth``: the npz's arrays (per-frame ones cut to [start, stop)), see
    tbha_graph.mocap.synth.groundtruth for keys and units; {} means "no ground truth".
    """
    p: GroundTruthParams = ctx.params
    if p.path is None:
        return {"truth": {}}
    if p.video is not None:
        path = Path(p.path).expanduser()
        truth = check_ground_truth(_read_npz(path), name=f"ground truth {path}")
        check_truth_video(truth, p.video, name=f"ground truth {path}")
        return {"truth": slice_frames(truth, p.start, p.stop, name=f"ground truth {path}")}
    return {"truth": load_ground_truth(p.path, p.start, p.stop)}
