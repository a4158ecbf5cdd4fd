"""What the 2D trackers share: reading their inputs, the start frame, the passes, the output bundle.

A tracker identifies the 16 joints in the segmenter's per-colour candidates. It starts at the first
frame where the posture rules (:mod:`.posture`) identify every joint, tracks forwards from there to the
end and backwards from there to the first frame, one frame at a time (:class:`FrameTracker`), and
returns a TRACKS2D bundle: ``points`` (n, 16, 2) px, ``tracked`` (n, 16) bool (False: the patch was
not seen; ``points`` then holds the tracker's estimate), ``fps``, ``width``, ``height``, ``frame_index``,
and from trackers that flag them ``doubtful`` (n,) uint8: why each frame's labelling is doubtful (bits of
:data:`DOUBT`; 0 = not doubtful).
"""
from __future__ import annotations

from typing import Callable, Protocol

import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from ...core.errors import NodeError
from ..bundles.colors import ColorModel
from ..skeleton import JOINT_INDEX, JOINT_NAMES, N_JOINTS
from .posture import PostureResult, find_start


class StartParams(BaseModel):
    """Params shared by the trackers: how the start frame is found."""

    model_config = ConfigDict(extra="forbid")

    init_frames: int = Field(
        90, ge=1, description="look for the start T-pose in this many first frames", json_schema_extra={"unit": "frame"}
    )
    min_separation: float = Field(
        4.0, ge=0, description="same-coloured patches must be at least this far apart vertically in the start frame",
        json_schema_extra={"unit": "px"},
    )
    max_missing: int = Field(
        1, ge=0, le=4, description="when no frame of the opening shows every patch (one washed out by a strong light), "
        "start from one missing at most this many: placed by the T-pose template, not tracked, until seen",
    )


class FrameTracker(Protocol):
    """One tracking direction: ``step`` takes a frame's candidates per class (list over classes of
    (k, 2) px arrays, or (k, 3) with the blob areas in px² when the tracker asked for them) and returns
    ``points`` (16, 2) px and ``tracked`` (16,) bool. A tracker may have ``start_unseen(joints)``: those
    joints were not seen in the start frame (placed by the T-pose template)."""

    def step(self, candidates: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]: ...


def class_joints(model: ColorModel, names: np.ndarray) -> list[list[int]]:
    """Joint indices wearing each detection class; checks the detections match the colour model."""
    got = [str(n) for n in np.asarray(names).reshape(-1)]
    if got != model.names:
        raise NodeError(
            f"the detections' colours {got} differ from the colour model's {model.names}",
            hint="connect the tracker's 'colors' to the same color.* node the segmenter used",
        )
    out = []
    for c in model.classes:
        unknown = [j for j in c.joints if j not in JOINT_INDEX]
        if unknown:
            raise NodeError(f"colour model: class {c.name!r} names unknown joint(s) {unknown}")
        out.append([JOINT_INDEX[j] for j in c.joints])
    covered = sorted(j for js in out for j in js)
    if covered != list(range(N_JOINTS)):
        lacking = [JOINT_NAMES[j] for j in range(N_JOINTS) if j not in covered]
        raise NodeError(f"colour model: no colour class for joint(s) {lacking}", hint="check the suit spec")
    return out


def start_frame(centres, areas, joints_of, params: StartParams, fps: float) -> tuple[int, np.ndarray, list[int]]:
    """Row of the start frame, the 16 joints' pixels there and the joints not seen there (placed by the T-pose
    template, :mod:`.posture`); NodeError naming what is wrong otherwise."""
    found = find_start(centres, areas, joints_of, params.init_frames, params.min_separation, params.max_missing)
    if not isinstance(found, PostureResult):
        return found
    n = min(params.init_frames, len(centres))
    used = [c for c, joints in enumerate(joints_of) if joints]
    seen = np.isfinite(np.asarray(centres[:n], dtype=np.float64)[..., 0]).any(axis=(0, 2))
    n_seen = int(seen[used].sum())
    what = []
    if found.missing:
        what.append("patches not found: " + "; ".join(found.missing))
    if found.problems:
        what.append("posture: " + "; ".join(found.problems))
    raise NodeError(
        f"no start T-pose in the first {n} frames ({n / fps:.1f} s): in the closest frame, " + ". ".join(what),
        hint="the actor must stand facing the camera in a T-pose, every patch visible, at the start of the video; "
        "otherwise check the suit file matches the suit worn (--set colors.suit=my_suit.yaml; "
        "python -m tbha_graph.mocap.color.sample_suit samples its real colours from the take), the light (a patch "
        "washed out to white, or too dark: colors.min_luma), or raise init_frames"
        + (f". Only {n_seen} of the suit's {len(used)} colours {'appears' if n_seen == 1 else 'appear'} at all in those "
           "frames: if the video shows someone without the suit, use pipelines/mediapipe.yaml (MediaPipe Pose: ordinary "
           "clothes)" if n_seen <= len(used) // 2 else ""),
    )


def run_passes(candidates: Callable[[int], list[np.ndarray]], n: int, start: int, points0: np.ndarray,
               make: Callable[[np.ndarray], FrameTracker], unseen: list[int] = ()) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Track from ``start`` (joints at ``points0`` (16, 2); ``unseen`` joints placed there, not seen) forwards
    to row n-1 and backwards to row 0.

    ``candidates(row)`` gives a frame's candidates per class; ``make(points0)`` a fresh tracker.
    Returns points, tracked and ``doubt`` (n,) uint8: each frame's :data:`DOUBT` bits (a tracker that
    sets a ``doubt`` attribute after each step reports them; others report none)."""
    points = np.full((n, N_JOINTS, 2), np.nan)
    tracked = np.zeros((n, N_JOINTS), bool)
    doubt = np.zeros(n, np.uint8)
    points[start] = points0
    tracked[start] = True
    tracked[start, list(unseen)] = False
    for rows in (range(start + 1, n), range(start - 1, -1, -1)):
        tr = make(points0)
        if len(unseen) and hasattr(tr, "start_unseen"):
            tr.start_unseen(list(unseen))
        for t in rows:
            points[t], tracked[t] = tr.step(candidates(t))
            doubt[t] = int(getattr(tr, "doubt", 0))
    return points, tracked, doubt


#: Why a frame's labelling is doubtful: bit of each reason in a tracks bundle's ``doubtful`` (n,) uint8.
DOUBT: dict[str, int] = {"few patches": 1, "lost joints": 2, "ambiguous identity": 4, "high residual": 8}


def doubt_names(bits: int) -> list[str]:
    """The reasons set in ``bits`` (see :data:`DOUBT`)."""
    return [name for name, b in DOUBT.items() if int(bits) & b]


def frame_candidates(centres: np.ndarray, areas: np.ndarray | None = None) -> Callable[[int], list[np.ndarray]]:
    """``candidates(row)``: per class, the (k, 2) px centres of the filled slots of that frame; with
    ``areas`` (n, C, K) px², (k, 3) arrays of x, y, area."""

    def get(t: int) -> list[np.ndarray]:
        row = centres[t]
        if areas is None:
            return [row[c][np.isfinite(row[c, :, 0])] for c in range(row.shape[0])]
        out = []
        for c in range(row.shape[0]):
            ok = np.isfinite(row[c, :, 0])
            out.append(np.column_stack([row[c][ok], areas[t, c][ok]]))
        return out

    return get


def tracks_bundle(points, tracked, det: dict, doubt=None) -> dict[str, np.ndarray]:
    """The TRACKS2D bundle; with ``doubt`` (n,) also ``doubtful`` (n,) uint8 (bits of :data:`DOUBT`)."""
    n = len(points)
    out = {
        "points": np.asarray(points, dtype=np.float64),
        "tracked": np.asarray(tracked, dtype=bool),
        "fps": np.asarray(float(det["fps"])),
        "width": np.asarray(int(det["width"])),
        "height": np.asarray(int(det["height"])),
        "frame_index": np.asarray(det.get("frame_index", np.arange(n)), dtype=np.int64),
    }
    if doubt is not None:
        out["doubtful"] = np.asarray(doubt, dtype=np.uint8)
    return out
