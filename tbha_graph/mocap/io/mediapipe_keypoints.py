"""Node ``io.mediapipe_keypoints`` (2D tracks) from MediaPipe Pose files; the readers shared with ``io.mediapipe_world``.

MediaPipe Pose gives 33 landmarks per frame (:data:`~tbha_graph.mocap.io.keypoint_layouts.MEDIAPIPE_POSE`):

* image landmarks: ``x``, ``y`` normalised to [0, 1] by the image width and height (x right, y down, from
  the top-left corner), ``z`` depth relative to the hips' midpoint in roughly the scale of ``x`` (smaller =
  closer to the camera; not used here), ``visibility`` in [0, 1];
* world landmarks: ``x``, ``y``, ``z`` metres, origin at the centre between the hips, axes aligned with the
  camera: x to the image right, y down, z away from the camera (MediaPipe's model card and maintainers).

Accepted files (what people save from ``mediapipe.solutions.pose`` results):

**JSON** (``.json``)::

    {"fps": 30, "width": 640, "height": 480,              # optional; else the node's params
     "frames": [{"frame": 0,                              # consecutive integers (any start)
                 "landmarks": [{"x": .., "y": .., "z": .., "visibility": ..}, ... 33],
                 "world_landmarks": [{"x": .., "y": .., "z": .., "visibility": ..}, ... 33]},   # optional
                ...]}

A frame where nothing was detected has ``"landmarks": []`` (or ``null``): all its joints are untracked.
A top-level list is read as the ``frames`` list.

**CSV** (``.csv``), one row per landmark, header row required::

    frame,landmark,x,y,z,visibility[,world_x,world_y,world_z]

``landmark`` is the index 0-32 or the MediaPipe name (``left_shoulder``); every frame lists all 33 landmarks;
``visibility`` may be left out (then 1). A frame without a detection keeps its 33 rows with empty values.
Width, height and fps come from the node's params.

Frame numbers must be consecutive: a gap (a dropped frame) is refused, naming the first missing frame,
since every later frame would be mistimed.

Output ``tracks`` (TRACKS2D): the 16 joints in pixels (mapping: :mod:`~tbha_graph.mocap.io.keypoint_layouts`),
``tracked`` = confidence >= ``threshold``, ``confidence``; untracked points hold a prediction (linear
interpolation between the nearest tracked frames of the joint; a joint never visible, e.g. the legs in a
portrait, keeps the detector's own off-image guesses). Output ``motion`` (MOTION, ``io.mediapipe_world``):
world landmarks turned to the project's world frame (y up, the actor facing +z when facing the camera):
``(x, y, z)_world = (x, -y, -z)_mediapipe``, plus ``root_height`` metres so the hips are not at the floor.
The heading is the camera's (MediaPipe gives no ground plane): a tilted camera tilts the motion.
"""
from __future__ import annotations

import csv
import io
import json
import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pydantic import ConfigDict, Field

from ...core.errors import NodeError
from ...core.node import InputPath, node
from ..ports import TRACKS2D
from ..skeleton import JOINT_NAMES
from .keypoint_layouts import MEDIAPIPE_POSE, TorsoFractions, fill_untracked, joints16_from_landmarks

N_LANDMARKS = MEDIAPIPE_POSE.size
#: numbers as written by programs (int()/float() alone also take '1_0', '¹', 'infinity')
_INT = re.compile(r"[-+]?[0-9]+")
_DECIMAL = re.compile(r"[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?|[-+]?(?:nan|inf|infinity)", re.IGNORECASE)


def _is_number(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def _not_utf8(path: Path, e: UnicodeDecodeError) -> NodeError:
    line = path.read_bytes()[: e.start].count(b"\n") + 1
    return NodeError(f"{path}:{line}: not UTF-8 text (byte {e.object[e.start]:#04x})", hint="save the file as UTF-8")


@dataclass
class MediaPipeTake:
    """A MediaPipe Pose file, read: ``image`` (n, 33, 4) x, y (normalised), z, visibility (NaN rows where
    nothing was detected), ``world`` (n, 33, 4) metres + visibility or None, ``first_frame`` the first
    frame number, and the ``fps``, ``width``, ``height`` the file gives (None when absent)."""

    image: np.ndarray
    world: np.ndarray | None
    first_frame: int
    fps: float | None
    width: int | None
    height: int | None


def _landmark_rows(items, path: Path, frame: int, key: str) -> np.ndarray:
    """(33, 4) from a list of landmark dicts (or [x, y, z, visibility] lists)."""
    if not isinstance(items, list) or len(items) != N_LANDMARKS:
        got = len(items) if isinstance(items, list) else type(items).__name__
        raise NodeError(f"{path}: frame {frame}: '{key}' has {got} landmarks, expected {N_LANDMARKS} (MediaPipe Pose)",
                        hint="save results.pose_landmarks.landmark (33 entries) for every frame, [] when nothing was detected")
    out = np.empty((N_LANDMARKS, 4))
    for i, lm in enumerate(items):
        try:
            if isinstance(lm, dict):
                vals = [lm["x"], lm["y"], lm.get("z", 0.0), lm.get("visibility", 1.0)]
            else:
                vals = (list(lm) + [1.0] * (4 - len(lm)))[:4]
            bad = [v for v in vals if not _is_number(v)]
            if bad:  # true, "0.5", null: not what a detector writes; numpy would quietly take some of them
                raise ValueError(f"{bad[0]!r} is not a number")
            out[i] = vals
        except (KeyError, TypeError, ValueError) as e:
            raise NodeError(f"{path}: frame {frame}: '{key}' landmark {i} ({MEDIAPIPE_POSE.landmarks[i]}) is not "
                            f"{{x, y, z, visibility}} numbers: {e}") from None
    return out


def _check_consecutive(frames: np.ndarray, path: Path) -> None:
    if frames.size == 0:
        raise NodeError(f"{path}: no frames", hint="the file must hold at least one frame")
    d = np.diff(frames)
    bad = np.flatnonzero(d != 1)
    if bad.size:
        k = int(bad[0])
        a, b = int(frames[k]), int(frames[k + 1])
        if b <= a:
            raise NodeError(f"{path}: frame {b} comes after frame {a}: frames must be in increasing order, each once")
        raise NodeError(f"{path}: frame {a + 1} is missing (frame {a} is followed by frame {b})",
                        hint="write every frame, with empty landmarks where nothing was detected")


def read_mediapipe_json(path: str | Path) -> MediaPipeTake:
    """Read a MediaPipe Pose JSON file (layout in the module docstring); NodeError on bad input."""
    path = Path(path)
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as e:
        raise NodeError(f"{path}:{e.lineno}:{e.colno}: invalid JSON: {e.msg}") from None
    except UnicodeDecodeError as e:
        raise _not_utf8(path, e) from None
    except OSError as e:
        raise NodeError(f"cannot read {path}: {e}") from None
    meta = doc if isinstance(doc, dict) else {}
    frames = doc.get("frames") if isinstance(doc, dict) else doc
    if not isinstance(frames, list):
        raise NodeError(f"{path}: expected a 'frames' list (or a top-level list of frames)",
                        hint='layout: {"fps":..,"width":..,"height":..,"frames":[{"frame":0,"landmarks":[...33]}]}')
    numbers = []
    image = np.full((len(frames), N_LANDMARKS, 4), np.nan)
    world = np.full((len(frames), N_LANDMARKS, 4), np.nan)
    any_world = False
    for k, fr in enumerate(frames):
        if not isinstance(fr, dict):
            raise NodeError(f"{path}: frames[{k}] is not an object with 'frame' and 'landmarks'")
        num = fr.get("frame", k if not numbers else numbers[-1] + 1)
        if not isinstance(num, int) or isinstance(num, bool):
            raise NodeError(f"{path}: frames[{k}]: 'frame' must be an integer, got {num!r}")
        numbers.append(num)
        lms = fr.get("landmarks", fr.get("pose_landmarks"))
        if lms:
            image[k] = _landmark_rows(lms, path, num, "landmarks")
        wl = fr.get("world_landmarks", fr.get("pose_world_landmarks"))
        if wl:
            world[k] = _landmark_rows(wl, path, num, "world_landmarks")
            any_world = True
    _check_consecutive(np.asarray(numbers), path)
    _check_finite(image, path, numbers[0], "landmarks")
    if any_world:
        _check_finite(world, path, numbers[0], "world_landmarks")
    return MediaPipeTake(image, world if any_world else None, numbers[0], _num(meta.get("fps"), path, "fps"),
                         _int(meta.get("width"), path, "width"), _int(meta.get("height"), path, "height"))


def _num(v, path: Path, key: str) -> float | None:
    if v is None:
        return None
    if not isinstance(v, (int, float)) or isinstance(v, bool) or not math.isfinite(v) or v <= 0:
        raise NodeError(f"{path}: '{key}' must be a positive number, got {v!r}")
    return float(v)


def _int(v, path: Path, key: str) -> int | None:
    f = _num(v, path, key)
    if f is not None and f != int(f):
        raise NodeError(f"{path}: '{key}' must be a whole number of pixels, got {v!r}")
    return None if f is None else int(f)


def _check_finite(arr: np.ndarray, path: Path, first: int, key: str) -> None:
    """NaN/inf inside a detected frame (a row that is not entirely missing) is refused."""
    detected = ~np.isnan(arr[..., :2]).all(axis=(1, 2))
    bad = detected[:, None] & ~np.isfinite(arr).all(axis=2)
    if bad.any():
        f, i = np.argwhere(bad)[0]
        raise NodeError(f"{path}: frame {first + int(f)}: '{key}' landmark {int(i)} ({MEDIAPIPE_POSE.landmarks[i]}) "
                        "is NaN or infinite", hint="write detected landmarks as finite numbers, or [] for a frame without a detection")


def read_mediapipe_csv(path: str | Path) -> MediaPipeTake:
    """Read a MediaPipe Pose CSV file (layout in the module docstring); NodeError on bad input."""
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError as e:
        raise _not_utf8(path, e) from None
    except OSError as e:
        raise NodeError(f"cannot read {path}: {e}") from None
    with io.StringIO(text, newline="") as f:
        reader = csv.reader(f)
        header = [h.strip().lower() for h in next(reader, [])]
        need = ("frame", "landmark", "x", "y")
        missing = [h for h in need if h not in header]
        if missing:
            raise NodeError(f"{path}:1: header lacks column(s) {', '.join(missing)} (has: {', '.join(header) or 'nothing'})",
                            hint="header: frame,landmark,x,y,z,visibility[,world_x,world_y,world_z]")
        col = {h: i for i, h in enumerate(header)}
        has_world = all(k in col for k in ("world_x", "world_y", "world_z"))
        names = {n: i for i, n in enumerate(MEDIAPIPE_POSE.landmarks)}
        rows: list[tuple[int, int, list[float]]] = []
        for line_no, row in enumerate(reader, start=2):
            if not row or all(not c.strip() for c in row):
                continue
            if len(row) < len(header):
                raise NodeError(f"{path}:{line_no}: {len(row)} values, the header has {len(header)}")
            if not _INT.fullmatch(row[col["frame"]].strip()):
                raise NodeError(f"{path}:{line_no}: frame {row[col['frame']]!r} is not an integer")
            frame = int(row[col["frame"]])
            lm = row[col["landmark"]].strip()
            idx = int(lm) if _INT.fullmatch(lm) else names.get(lm.lower(), -1)
            if not 0 <= idx < N_LANDMARKS:
                raise NodeError(f"{path}:{line_no}: landmark {lm!r} is not 0-{N_LANDMARKS - 1} or a MediaPipe Pose name",
                                hint=f"names: {', '.join(MEDIAPIPE_POSE.landmarks[:3])}, ...")
            keys = ["x", "y", "z", "visibility"] + (["world_x", "world_y", "world_z"] if has_world else [])
            vals = []
            for k in keys:
                if k not in col:
                    vals.append(0.0 if k == "z" else 1.0)
                    continue
                text = row[col[k]].strip()
                if not text:
                    vals.append(math.nan)
                    continue
                if not _DECIMAL.fullmatch(text):
                    raise NodeError(f"{path}:{line_no}: {k} = {row[col[k]]!r} is not a number")
                vals.append(float(text))
            rows.append((frame, idx, vals))
    if not rows:
        raise NodeError(f"{path}: no landmark rows after the header")
    frame_ids = np.array([r[0] for r in rows])
    lm_ids = np.array([r[1] for r in rows])
    vals = np.array([r[2] for r in rows])
    frames = np.unique(frame_ids)
    _check_consecutive(frames, path)
    first = int(frames[0])
    counts = np.bincount(frame_ids - first, minlength=frames.size)
    bad = np.flatnonzero(counts != N_LANDMARKS)
    if bad.size:
        fr = first + int(bad[0])
        raise NodeError(f"{path}: frame {fr} has {int(counts[bad[0]])} landmark rows, expected {N_LANDMARKS} (MediaPipe Pose)",
                        hint="write all 33 landmark rows of every frame (empty x, y values for a frame without a detection)")
    flat = (frame_ids - first) * N_LANDMARKS + lm_ids
    if np.unique(flat).size != flat.size:
        dup = int(np.flatnonzero(np.bincount(flat) > 1)[0])
        raise NodeError(f"{path}: frame {first + dup // N_LANDMARKS} lists landmark {dup % N_LANDMARKS} twice")
    data = np.empty((frames.size * N_LANDMARKS, vals.shape[1]))
    data[flat] = vals
    data = data.reshape(frames.size, N_LANDMARKS, -1)
    data[np.isnan(data[..., :2]).all(axis=(1, 2))] = np.nan  # frames without a detection
    image = data[..., :4]
    _check_finite(image, path, first, "landmarks")
    world = None
    if has_world:
        world = np.concatenate([data[..., 4:7], data[..., 3:4]], axis=-1)
        _check_finite(world, path, first, "world_landmarks")
    return MediaPipeTake(image, world, first, None, None, None)


def read_mediapipe(path: str | Path) -> MediaPipeTake:
    """Read a MediaPipe Pose file by its extension (``.json`` or ``.csv``)."""
    path = Path(path)
    if not path.is_file():
        raise NodeError(f"MediaPipe keypoint file {path} does not exist", hint="check the path (relative to the pipeline file)")
    suffix = path.suffix.lower()
    if suffix == ".json":
        return read_mediapipe_json(path)
    if suffix == ".csv":
        return read_mediapipe_csv(path)
    raise NodeError(f"{path}: unknown MediaPipe keypoint file type {suffix!r}", hint="use .json or .csv (layouts in `tbha-graph nodes io.mediapipe_keypoints`)")


class MediaPipeParams(TorsoFractions):
    model_config = ConfigDict(extra="forbid")

    path: InputPath = Field(description="MediaPipe Pose keypoints, .json or .csv (layout in the node doc)")
    fps: float | None = Field(None, gt=0, le=1000, description="frame rate; required when the file gives none", json_schema_extra={"unit": "1/s"})
    width: int | None = Field(None, gt=0, le=65536, description="image width; required when the file gives none", json_schema_extra={"unit": "px"})
    height: int | None = Field(None, gt=0, le=65536, description="image height; required when the file gives none", json_schema_extra={"unit": "px"})
    threshold: float = Field(0.5, ge=0, le=1, description="visibility below which a joint is untracked")


def _take_meta(take: MediaPipeTake, p: MediaPipeParams) -> tuple[float, int, int]:
    fps = p.fps or take.fps
    width = p.width or take.width
    height = p.height or take.height
    missing = [k for k, v in (("fps", fps), ("width", width), ("height", height)) if not v]
    if missing:
        raise NodeError(f"{p.path}: the file gives no {', '.join(missing)}",
                        hint=f"set the param(s): {', '.join(f'--set <node>.{k}=...' for k in missing)}")
    return float(fps), int(width), int(height)


def tracks_from_mediapipe(take: MediaPipeTake, fps: float, width: int, height: int, threshold: float = 0.5,
                          fractions: TorsoFractions | None = None, where: str = "MediaPipe file") -> dict[str, np.ndarray]:
    """A TRACKS2D bundle (pixels) from a read MediaPipe take (see the module docstring)."""
    img = take.image
    detected = ~np.isnan(img).all(axis=(1, 2))
    if not detected.any():
        raise NodeError(f"{where}: no frame has a detected pose", hint="check the detector ran on the right video")
    px = img[..., :2] * np.array([width, height])
    vis = np.where(detected[:, None], img[..., 3], 0.0)
    px = np.where(detected[:, None, None], px, 0.0)
    pts, conf = joints16_from_landmarks(px, vis, MEDIAPIPE_POSE, fractions, threshold)
    tracked = conf >= threshold
    # MediaPipe places every landmark, off-image ones too: a joint never visible keeps the detector's guess
    return {
        "points": fill_untracked(pts, tracked, np.repeat(detected[:, None], pts.shape[1], axis=1)),
        "tracked": tracked, "confidence": conf,
        "fps": np.array(fps), "width": np.array(width), "height": np.array(height), "joint_names": np.array(JOINT_NAMES),
    }


@node("io.mediapipe_keypoints", version=1, outputs={"tracks": TRACKS2D}, params=MediaPipeParams)
def mediapipe_keypoints(ctx):
    """2D joint tracks (pixels) from a MediaPipe Pose keypoint file (.json or .csv)."""
    p = ctx.params
    take = read_mediapipe(p.path)
    fps, width, height = _take_meta(take, p)
    return {"tracks": tracks_from_mediapipe(take, fps, width, height, p.threshold, p, str(p.path))}
