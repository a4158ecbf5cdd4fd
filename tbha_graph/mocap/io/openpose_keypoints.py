"""Node ``io.openpose_keypoints``: 2D joint tracks from OpenPose's ``--write_json`` output.

OpenPose writes one JSON file per frame into a folder, named ``<video name>_<frame, 12 digits>_keypoints.json``::

    {"version": 1.3, "people": [{"person_id": [-1], "pose_keypoints_2d": [x0, y0, c0, x1, y1, c1, ...], ...}, ...]}

``pose_keypoints_2d`` is flat ``[x, y, confidence] * N``; the layout is detected from ``N``: 25 =
``BODY_25``, 18 = ``COCO`` (:mod:`~tbha_graph.mocap.io.keypoint_layouts`). A part OpenPose did not find is
``0, 0, 0``. Coordinates are pixels from the top-left corner by default (``--keypoint_scale 0``); files
written with ``--keypoint_scale 3`` ([0, 1]) or ``4`` ([-1, 1]) are read with ``coordinates`` set to
``unit`` or ``signed_unit``.

Frames: the frame number is the 12-digit number in each file name (files without one are ordered by name
and numbered from 0). Numbers must be consecutive: a gap is refused, naming the missing frame. A frame with
no person has all joints untracked. With several people, ``person`` picks one: ``"largest"`` (default: the
largest box around its confident parts) or an index into ``people``.

OpenPose files carry neither the frame rate nor the image size: they are params (``fps``, ``width``,
``height``). Output ``tracks`` (TRACKS2D): 16 joints in pixels, ``tracked`` = confidence >= ``threshold``,
``confidence``; untracked points hold a linear interpolation between the joint's nearest tracked frames
(a joint never above the threshold: between the frames where OpenPose found it at all; never found: error).
"""
from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import ConfigDict, Field, field_validator

from ...core.errors import NodeError
from ...core.node import InputPath, node
from ..ports import TRACKS2D
from ..skeleton import JOINT_NAMES
from .keypoint_layouts import OPENPOSE_LAYOUTS, Layout, TorsoFractions, fill_untracked, joints16_from_landmarks

_FRAME_NO = re.compile(r"(\d{12})(?=_keypoints\.json$)")


def list_frames(folder: Path) -> list[tuple[int, Path]]:
    """``(frame number, path)`` of every ``*.json`` in ``folder``, in frame order; NodeError on gaps."""
    if not folder.is_dir():
        raise NodeError(f"OpenPose folder {folder} does not exist or is not a folder",
                        hint="give the folder OpenPose wrote with --write_json (relative to the pipeline file)")
    files = sorted(p for p in folder.iterdir() if p.suffix.lower() == ".json" and p.is_file())
    if not files:
        raise NodeError(f"{folder}: no .json files", hint="OpenPose writes <name>_000000000000_keypoints.json per frame")
    numbered = [(_FRAME_NO.search(p.name), p) for p in files]
    if all(m is not None for m, _ in numbered):
        frames = sorted((int(m.group(1)), p) for m, p in numbered)
    else:
        frames = list(enumerate(files))
    nums = np.array([f for f, _ in frames])
    d = np.diff(nums)
    if (d == 0).any():
        k = int(np.flatnonzero(d == 0)[0])
        raise NodeError(f"{folder}: two files for frame {nums[k]}: {frames[k][1].name} and {frames[k + 1][1].name}")
    if (d != 1).any():
        k = int(np.flatnonzero(d != 1)[0])
        raise NodeError(f"{folder}: frame {nums[k] + 1} is missing (after {frames[k][1].name} comes {frames[k + 1][1].name})",
                        hint="OpenPose writes a file for every frame; restore the missing file(s)")
    return frames


def _person_keypoints(doc, path: Path, frame: int) -> list[list[float]]:
    if not isinstance(doc, dict) or not isinstance(doc.get("people"), list):
        raise NodeError(f"{path}: frame {frame}: expected an object with a 'people' list (OpenPose --write_json output)")
    out = []
    for k, person in enumerate(doc["people"]):
        kp = person.get("pose_keypoints_2d", person.get("pose_keypoints")) if isinstance(person, dict) else None
        if not isinstance(kp, list):
            raise NodeError(f"{path}: frame {frame}: people[{k}] has no 'pose_keypoints_2d' list")
        out.append(kp)
    return out


def _box_size(kp: np.ndarray) -> float:
    ok = kp[:, 2] > 0
    if ok.sum() < 2:
        return 0.0
    span = kp[ok, :2].max(axis=0) - kp[ok, :2].min(axis=0)
    return float(span[0] * span[1])


def read_openpose(folder: str | Path, person: int | str = "largest") -> tuple[np.ndarray, Layout, int]:
    """Read an OpenPose JSON folder: keypoints ``(n, N, 3)`` (x, y, confidence; all 0 where no person),
    the detected :class:`Layout`, and the first frame number. NodeError naming the file on bad input."""
    folder = Path(folder)
    frames = list_frames(folder)
    layout: Layout | None = None
    layout_file = ""
    rows: list[np.ndarray | None] = []
    for num, path in frames:
        try:
            doc = json.loads(path.read_text(encoding="utf-8"))
        except json.JSONDecodeError as e:
            raise NodeError(f"{path}:{e.lineno}:{e.colno}: invalid JSON: {e.msg}") from None
        except UnicodeDecodeError as e:
            raise NodeError(f"{path}: not UTF-8 text (byte {e.start}: {e.object[e.start]:#04x})", hint="save the file as UTF-8") from None
        people = _person_keypoints(doc, path, num)
        arrs = []
        for k, kp in enumerate(people):
            if len(kp) % 3 or len(kp) // 3 not in OPENPOSE_LAYOUTS:
                known = ", ".join(f"{n} ({lay.name})" for n, lay in OPENPOSE_LAYOUTS.items())
                raise NodeError(f"{path}: frame {num}: people[{k}] has {len(kp)} values = {len(kp) / 3:g} keypoints; "
                                f"expected 3 values (x, y, confidence) for each of {known} keypoints",
                                hint="only OpenPose's BODY_25 and COCO body models are supported")
            if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in kp):  # numpy takes true, "1.5"
                raise NodeError(f"{path}: frame {num}: people[{k}] pose_keypoints_2d holds non-numbers")
            a = np.asarray(kp, dtype=np.float64).reshape(-1, 3)
            if not np.isfinite(a).all():
                i = int(np.flatnonzero(~np.isfinite(a).all(axis=1))[0])
                raise NodeError(f"{path}: frame {num}: people[{k}] keypoint {i} is NaN or infinite",
                                hint="OpenPose writes 0, 0, 0 for a part it did not find")
            lay = OPENPOSE_LAYOUTS[a.shape[0]]
            if layout is None:
                layout, layout_file = lay, path.name
            elif lay is not layout:
                raise NodeError(f"{path}: frame {num}: {lay.name} keypoints ({lay.size}), but {layout_file} has "
                                f"{layout.name} ({layout.size}): one folder must hold one layout")
            arrs.append(a)
        if not arrs:
            rows.append(None)
            continue
        if person == "largest":
            rows.append(max(arrs, key=_box_size))
        elif isinstance(person, int) and person < len(arrs):
            rows.append(arrs[person])
        else:
            rows.append(None)
    if layout is None:
        raise NodeError(f"{folder}: no frame has a person in it", hint="check OpenPose ran on the right video")
    out = np.zeros((len(rows), layout.size, 3))
    for i, r in enumerate(rows):
        if r is not None:
            out[i] = r
    return out, layout, frames[0][0]


class OpenPoseParams(TorsoFractions):
    model_config = ConfigDict(extra="forbid")

    path: InputPath = Field(description="folder of OpenPose JSON files (one per frame, --write_json)")
    fps: float = Field(gt=0, le=1000, description="frame rate of the video OpenPose ran on", json_schema_extra={"unit": "1/s"})
    width: int = Field(gt=0, le=65536, description="image width of that video", json_schema_extra={"unit": "px"})
    height: int = Field(gt=0, le=65536, description="image height of that video", json_schema_extra={"unit": "px"})
    threshold: float = Field(0.3, ge=0, le=1, description="confidence below which a joint is untracked")
    person: int | Literal["largest"] = Field("largest", description="which person: 'largest' box, or an index into 'people'")
    coordinates: Literal["pixels", "unit", "signed_unit"] = Field(
        "pixels", description="keypoint_scale OpenPose wrote with: pixels (0), unit [0,1] (3), signed_unit [-1,1] (4)")

    @field_validator("person")
    @classmethod
    def _person(cls, v):
        if isinstance(v, int) and v < 0:
            raise ValueError("person index must be >= 0")
        return v


def tracks_from_openpose(kp: np.ndarray, layout: Layout, fps: float, width: int, height: int, threshold: float = 0.3,
                         coordinates: str = "pixels", fractions: TorsoFractions | None = None,
                         where: str = "OpenPose folder") -> dict[str, np.ndarray]:
    """A TRACKS2D bundle (pixels) from OpenPose keypoints ``(n, N, 3)`` (see the module docstring)."""
    xy = kp[..., :2].copy()
    conf = kp[..., 2].copy()
    size = np.array([width, height], dtype=np.float64)
    if coordinates == "unit":
        xy = xy * size
    elif coordinates == "signed_unit":
        xy = (xy + 1.0) * 0.5 * size
    missing = (conf <= 0) & (kp[..., 0] == 0) & (kp[..., 1] == 0)
    conf[missing] = 0.0
    pts, c16 = joints16_from_landmarks(xy, conf, layout, fractions, threshold)
    tracked = c16 >= threshold
    seen = c16 > 0
    if not seen.any(axis=0).all():
        j = int(np.flatnonzero(~seen.any(axis=0))[0])
        raise NodeError(f"{where}: OpenPose never found joint {JOINT_NAMES[j]!r} (confidence 0 in every frame), so "
                        "there is no position to give it", hint="film the whole body, or check the OpenPose output")
    return {
        "points": fill_untracked(pts, tracked, seen), "tracked": tracked, "confidence": c16,
        "fps": np.array(float(fps)), "width": np.array(int(width)), "height": np.array(int(height)),
        "joint_names": np.array(JOINT_NAMES), "layout": np.array(layout.name),
    }


@node("io.openpose_keypoints", version=1, outputs={"tracks": TRACKS2D}, params=OpenPoseParams)
def openpose_keypoints(ctx):
    """2D joint tracks (pixels) from a folder of OpenPose JSON files (BODY_25 or COCO, auto-detected)."""
    p = ctx.params
    kp, layout, _ = read_openpose(p.path, p.person)
    ctx.log(f"{kp.shape[0]} frames, {layout.name} layout")
    return {"tracks": tracks_from_openpose(kp, layout, p.fps, p.width, p.height, p.threshold, p.coordinates, p, str(p.path))}
