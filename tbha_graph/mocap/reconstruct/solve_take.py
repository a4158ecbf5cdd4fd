"""``reconstruct.solve_take``: camera, floor and motion estimated together from the whole take.

One camera films a person of known bone lengths; the 2D tracks of the suit's points are all there is.
This node finds, for the whole take at once (model and residuals: :mod:`.take_model`):

* the focal length (square pixels, principal point at the image centre) — observable because the body's
  depth extent and its motion towards and away from the camera change its perspective, with bone lengths
  fixed; a fronto-parallel T-pose alone gives only focal ÷ distance;
* the floor (its normal and height in the camera frame), hence the camera's height and tilt;
* per frame the root position and every bone's direction (bone lengths exact by construction);
* optionally the bone lengths, around the body's (``free_lengths``; off by default: measured no better on the
  sample). Where each tracked point sits on the body is the suit's (or the detector's calibrated offsets), not
  estimated: one camera cannot tell a point farther out of the body from a body nearer the camera (freed, the
  solve put the sample 92 mm off instead of 51, round 15).

Method. Levenberg–Marquardt on the whole take's block normal equations (:func:`.take_solver.normal_equations`:
frame blocks banded, globals by a Schur complement, so each step costs time linear in the frames) over
residuals divided by their standard deviations: robust (soft-L1) reprojection of every tracked point,
joint-acceleration smoothness (tighter for the torso's joints, ``sigma_acc_torso``: the image fixes the
body's depth only weakly, and the hips do not jerk), near-rigid torso, knee/elbow hinge limits, floor
contact (planted ankles — found from the image, where a planted ankle stands still — at rest height within
a 3 cm roll band and not sliding; no ankle below the floor), a weak pose prior (head along the neck) and a
twist prior (the pelvis faces where the thorax faces, ``sigma_twist`` about 11 degrees: walking twists them
5-15 degrees apart; without it a pelvis tipped to its mirror depth side costs nothing). On the take's
opening T-pose (the frames :func:`..tpose.find_tpose` finds in the image, as the tracker does) the limbs are
held straight, the arms along the shoulder line (``sigma_tpose``, :func:`.take_model.tpose_residual`: an arm held
out sideways keeps nearly the same image as it swings 20-30 degrees into depth, and bones a few percent off the
actor's make it swing), in the pose solves at the chosen focal length only, as the silhouette: in the focal
choice, with bones a few percent off, the arms held out moved the focal length instead (held_131_01_full_turn's
700.8 -> 715.9 px, truth 700, and that take 142 -> 203 mm). Measured on the 16 renders of ``bench/solver_sweep.py``,
each solved three times: the T-pose frames 27.2 -> 18.2 mm, each aligned on its own; seq-MPJPE 100.7 -> 100.0 mm,
the three solver renders and the sample 62.9 -> 60.8, the six held-out takes 119.0 -> 118.5; root-relative
76.1 -> 75.5: within the search's scatter, the T-pose excepted.

1. **Starts.** For each starting focal length (``focal_grid`` × image width, a weak log-normal prior
   around ``focal_prior_width`` × width), or the given ``focal_px``: a first skeleton from the seed's
   geometry (T-pose camera by PnP, the torso's *points* fitted by PnP per frame, limbs by ray-sphere with
   depth sides chosen over time, :func:`.temporal_ray_sphere.solve_temporal`).
2. **Subsample.** On ``calib_frames`` frames spread over the take: LM, the depth-side search, LM again.
3. **Depth sides.** A limb can lie in front of or behind its parent with the same image. For each group of
   bones (pelvis, thorax, each limb bone, head) and each run of frames where the bone points out of the
   image plane, the mirrored run and the current one are re-optimised together (all windows of a group in
   one problem) and the mirror kept where it ends cheaper (:func:`.take_solver.search_sides_lm`); then each
   piece of a run cut where the bone dips towards the image plane without crossing it is decided the same way on
   its own (``side_split_cos``, :func:`.take_solver.dip_pieces`); at the full frame rate ``side_search_passes`` > 1
   goes over the groups again where kept mirrors changed the body.
4. **Focal length.** The start with the lowest cost on the subsample wins. Its depth sides are then re-solved
   at the other starts' focal lengths, on the subsample too (``cross_seed``: each frame's body moved in depth
   so its image stays, :func:`moved_in_depth`), only to test whether the take determines the focal length:
   such a cross seed within ``RIVAL_COST`` (15 %) of the best cost at a clearly different focal length is a
   warning (the take cannot tell them apart), never the choice. Measured on the sample and three renders, the
   cross seeds came within 1 % of the best or below it at 0.7-2x its focal length on all four: with these
   priors and tracks the cost is flat over the focal length, the choice among starts is luck, and the
   warning asks for ``focal_px``. Choosing on the subsample rather than on the whole take gave the same
   choices at a third of the time. These starts run under the weaker priors (``select_sigma_twist``, no
   torso acceleration prior): measured on four renders, the tighter ones pulled the choice 20-100 % off.
   The winner then goes to every frame (interpolated), LM with focal and floor free; with the focal length
   chosen (or given), the pose is solved at it under the full priors: LM, the depth-side search, LM.
   A take longer than ``window_frames`` (300) finds its camera and floor on every k-th frame (at most 300),
   then solves the pose in overlapping windows of 300 frames with them held (:func:`solve_windows`): memory
   stays that of one window and time grows linearly (``bench/solver_speed.py``).
   **Silhouette** (optional ``silhouette`` input, ``segment.silhouette``; used in the pose solves at the chosen focal length only, so the
   focal length is chosen as without it): the suit's patches are on the body's front, so with the actor's
   back to the camera only the head is tracked and the priors alone placed the body (measured: it drifted
   0.5-1.5 m in depth and kept facing sideways). With the silhouette four more residuals per frame
   (:func:`.take_model.sil_residuals`, :func:`.take_model.bottom_residual`): every joint and bone midpoint not
   pinned by tracked points projected inside the outline (``sigma_sil``; on tracked ones the silhouette's small
   defects only pulled: the hop given its focal length 48 -> 52 mm); the floor point below the lower ankle at
   most 8 px higher in the image than the outline's lowest row (else a body farther away and smaller, its head
   on the same pixel, fits inside as well); the lower ankle within 0.1 m of its standing height; and on frames where the head is tracked but
   no torso patch is, the thorax and pelvis facing at least 154 degrees away from the camera and the spine within
   20 degrees of the vertical (:func:`.take_model.upright_residual`; the floor's normal when the problem is made;
   without it the back-turned spines leaned 31 degrees, median, the truth's 13). On frames where fewer
   than 3 of the torso's 7 points are tracked, two more: the model covers the outline (:func:`.take_model.cover_residuals`:
   32 samples of its contour each within about 0.1 m of a projected bone; the inside term alone let a leg swing
   into depth, or the torso stay side-on inside a back view's wider outline); and before the pose solve each
   head-only frame's body is moved along its root's ray to the depth where its lower foot stands on the outline's
   lowest row (:func:`.take_model.seat_on_outline`; started from the last pose seen, the solve kept a body walking
   away 1.2 m short; on every torso-unseen frame instead of the head-only ones it placed side views 0.6 m too far).
   After the depth-side search, the lean search (:func:`.take_solver.search_leans_lm`, ``lean_search``): the upper
   body turned about the hips around the hip line by -16, -8, 8, 16 degrees in windows of 30 then 15 frames, the
   cheapest kept (a torso leaning back with the hips a little lower projects nearly as one upright; round 21: the
   16 renders 93.7 -> 91.3 mm, fresh draws 89.2 -> 86.8). Then the turn search (:func:`.take_solver.search_turns_lm`): on each run of
   torso-unseen frames, whole and in pieces of 24 and 12 frames, the body turned about the vertical by 90, 180,
   270 degrees and to the mirror of its heading about the viewing direction, the cheapest
   kept (a side view facing left or right, or a turn one way round or the other, gives nearly the same outline;
   each pass's candidates re-optimised for 6 steps; measured on ``bench/labelling.py``'s six takes: mean seq-MPJPE
   170.5 -> 156.0 mm, 186.2 -> 168.7 given the focal length).
   **A detector's data** (optional): with the ``keypoints`` input (``detect.mediapipe_pose`` on the same video,
   as ``pipelines/default.yaml`` wires it), on frames where no torso patch is seen each joint whose suit point is lost
   is pulled to the detector's keypoint (:func:`.take_model.keypoint_residual`, ``sigma_kp``; each left/right
   pair as labelled or swapped, whichever fits: a detector labels a back-turned actor's sides either way);
   measured with ``bench/solver_sweep.py --repeats 3`` against ``--no-keypoints``: the 16 renders' mean 116.5 -> 101.5 mm
   (Pose run only where no torso patch is seen, as default.yaml does; round 8, on every frame: 119.2 -> 101.6).
   Tracks from ``detect.mediapipe_pose`` (``pipelines/mediapipe.yaml``) carry its torso ``facing``, which the
   torso is kept near (:func:`.take_model.facing_residual`, ``sigma_facing``; MediaPipe renders' mean PA-MPJPE
   88.1 -> 77.8 mm); so do its keypoints beside a suit's tracks (``default.yaml``, where the suit's patches make
   its left and right right: the 16 renders' mean 101.0 [99.6-103.4] -> 98.4 [90.9-104.7] mm, better on 10 takes,
   worse on 2, root-relative 75.4 -> 71.6, ``bench/solver_sweep.py --repeats 5``).
5. **World frame.** y up = the floor normal, origin on the floor below the hips on the first frame, z the
   actor's forward on the first frame made horizontal (the actor faces +z in the T-pose).

Outputs: ``motion`` (world, metres), ``camera`` (K, R, t in that world), ``sides`` (depth side per frame and
joint, for ``viz.depth_sides``) and ``report`` (camera figures with uncertainties from the Jacobian, costs,
warnings).
"""
from __future__ import annotations

import time

import numpy as np
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field

from ...core.errors import NodeError
from ...core.node import node, optional
from ..bundles.lens import LensEstimate
from ..bundles.tracks import read_tracks
from ..calibrate.pnp import solve_pnp_planar
from ..camera import Camera
from ..ports import BODY, CAMERA, LENS, MOTION, SIDES, SILHOUETTE, TRACKS2D, report_port
from ..runs import runs_of
from ..skeleton import JOINT_NAMES, N_JOINTS, PARENTS, TORSO_JOINTS, torso_unseen
from ..body import DEFAULT_ANKLE_HEIGHT, body_lengths, lengths_to_body, tpose_on_floor
from ..tpose import find_tpose
from .take_model import (ANKLES, DEFAULT_POINT_OFFSETS, TORSO_PAIRS, SilhouetteField, TakeData, TakeProblem, Weights,
                         bone_directions, fronts, pack_initial, point_positions, seat_on_outline, unit)
from .take_solver import levenberg_marquardt
from .take_solver import search_sides_lm as search_sides
from .take_solver import search_leans_lm, search_turns_lm
from .temporal_ray_sphere import TemporalRaySphereParams, solve_temporal


class SolveTakeParams(BaseModel):
    model_config = ConfigDict(extra="forbid")

    focal_px: float | None = Field(None, gt=0, description="known focal length (held fixed); None: estimated from the take", json_schema_extra={"unit": "px"})
    focal_grid: list[float] = Field([0.8, 1.1, 1.5], min_length=1, description="starting focal lengths tried, as multiples of the image width")
    focal_prior_width: float = Field(1.2, gt=0, description="centre of the weak focal-length prior, as a multiple of the image width")
    focal_prior_log_sd: float = Field(0.35, gt=0, description="standard deviation of log(focal) in that prior (0.35: x/÷ 1.4)")
    lens_sd_floor_pct: float = Field(0.5, ge=0, description="uncertainty added to a room-lines focal length's own (its bootstrap) "
                                     "before it is the solve's focal prior: the principal point off the image centre, lens "
                                     "distortion and not quite perpendicular room lines are not in the bootstrap (raise it for "
                                     "a lens that bends straight lines); the take's own pull on the focal length is biased "
                                     "by about 1 % (renders), so it should not outweigh the room's lines",
                                     json_schema_extra={"unit": "%"})
    tpose_frames: int = Field(10, ge=1, description="opening T-pose frames used to place the first skeleton")
    calib_frames: int = Field(70, ge=20, description="frames (spread over the take) used to solve focal, floor and point offsets")
    max_iterations: int = Field(12, ge=1, description="Levenberg-Marquardt iterations on the whole take")
    calib_iterations: int = Field(10, ge=1, description="Levenberg-Marquardt iterations per start on the frame subsample")
    sigma_px: float = Field(2.0, gt=0, description="sd of a tracked point about where the model puts it: the tracks' noise "
                            "(0.66 px on the sample) plus the patch model's error. At 1 px the solve fits both and lets a "
                            "wrong depth basin win on its closer fit (131_01: the truth's minimum 25 cost units worse in "
                            "reprojection, 60 better in the priors); measured on 16 renders' mean seq-MPJPE, room's focal "
                            "length: 1 / 1.5 / 2 / 3 px 138.3 / 133.2 / 124.6 / 132.0 mm (true focal length: 1 / 2 px "
                            "142.9 / 126.8); single draws, each uncertain by ~15 mm: over 3 repeats (bench/solver_sweep.py "
                            "--repeats 3, no hang) 1 / 2 px 136.1 / 126.8 mm", json_schema_extra={"unit": "px"})
    sigma_acc: float = Field(30.0, gt=0, description="typical joint acceleration (smoothness prior)", json_schema_extra={"unit": "m/s^2"})
    sigma_torso: float = Field(0.05, gt=0, description="torso distances (shoulders, hip joints, hips, chest, neck) around the rest pose's, metres")
    sigma_pelvis: float | None = Field(None, gt=0, description="the hips joint's distance in front of the plane through the hip "
                                       "joints and the chest (take_model.pelvis_depth) around pelvis_depth_m, metres; None: off. "
                                       "Measured at 0.01 (bench/solver_sweep.py --repeats 3, 2026-11-28): the pose better "
                                       "(all16_rootrel 68.5 -> 63.6 mm, T-pose 19.2 -> 14.2, the sample's PA 26.0 -> 21.7), "
                                       "seq-MPJPE not (all16 91.3 -> 93.2 within the repeats' spread); off until its effect "
                                       "on the floor's height is understood (docs/solver-log.md)")
    pelvis_depth_m: float = Field(-0.03, ge=-0.2, le=0.2, description="with sigma_pelvis: where the hips joint sits in front of the "
                                  "plane through the hip joints and the chest, metres (negative: behind it; the renders' CMU "
                                  "skeletons: -28 to -35 mm)")
    sigma_balance: float | None = Field(0.05, gt=0, description="the hips farther across the floor than balance_band_m from "
                                        "the segment between the ankles costs ((distance - band) / sigma_balance)², metres "
                                        "(take_model.balance_residual); None: off. With the band 0.2 (bench/solver_sweep.py "
                                        "--repeats 3, 2026-11-28): all16 90.2 -> 88.2 mm, on fresh draws 88.6 -> 85.9; the "
                                        "sample unchanged (its hips stay within the band); pipelines/mediapipe.yaml: band 0.15")
    balance_band_m: float = Field(0.2, ge=0, le=1.0, description="with sigma_balance: how far across the floor the hips may "
                                  "be from the ankles' segment at no cost, metres (the renders' CMU takes: at most 0.21; 0.15: all16 88.1 / 88.6 mm, "
                                  "the held-out full turn worse)")
    sigma_hip: float | None = Field(0.05, gt=0, description="with a silhouette, on frames where only the head is tracked (the back "
                                    "to the camera): a thigh swung behind the pelvis's frontal plane, (dot of the thigh's direction "
                                    "with the pelvis's front + hip_back_cos) / sigma_hip where negative "
                                    "(take_model.hip_extension_residual: a hip extends 20-30 degrees; the image cannot tell a knee "
                                    "raised in front of someone facing away from a thigh swung as far behind, and the hang prior "
                                    "picks the lower); None: off. bench/solver_sweep.py --repeats 3 (docs/solver-log.md round 31): "
                                    "all16 84.9 -> 85.1 and 85.3 -> 84.6 mm, the four takes that do not turn 57.4 -> 56.0 and "
                                    "55.9 -> 52.8 (131_01 79.3 -> 73.6 and 77.2 -> 64.0); on every frame instead +0.9 / -0.1, the "
                                    "turning takes swinging by up to 26 mm")
    hip_back_cos: float = Field(0.6, ge=0, le=1.0, description="with sigma_hip: how far behind the frontal plane a thigh may swing "
                                "at no cost (sine of the angle: 0.6, 37 degrees; the renders' CMU takes reach 0.27; at 0.4, "
                                "on every frame, all16 +3.0 / +0.0 mm)")
    sigma_twist: float = Field(0.2, gt=0, description="pelvis-thorax twist prior: difference of their unit forward vectors (0.2: about 11 degrees; walking twists 5-15)")
    sigma_acc_torso: float | None = Field(5.0, gt=0, description="torso joints' (hips, spine, shoulders, hip joints) acceleration prior, tighter than the limbs' (walking moves the hips at 2-3 m/s^2): it steadies the body's depth, which the image fixes only weakly; None: sigma_acc", json_schema_extra={"unit": "m/s^2"})
    ankle_height: float = Field(DEFAULT_ANKLE_HEIGHT, ge=0, le=0.3, description="ankle joint height above the floor when standing", json_schema_extra={"unit": "m"})
    points: Literal["suit", "joints"] = Field("suit", description="what the tracks mark: 'suit' patches on the body "
                                              "surface (modelled off the joint centres) or 'joints' (detector keypoints)")
    point_offsets: list[list[float]] | None = Field(
        None, description="where each tracked point sits off its joint: 16 rows (along, out) metres, joint order; None: "
                          "the tracks' own 'point_offsets' if they carry them (a detector's calibrated offsets), else the "
                          "suit's defaults (points: suit) or zeros (points: joints)")
    confidence_power: float = Field(0.0, ge=0, le=4, description="each tracked point's weight times the tracks' "
                                    "confidence to this power (0: off; detector keypoints carry one, e.g. MediaPipe's visibility)")
    free_lengths: bool = Field(False, description="refine the bone lengths from the take around the body's (3 % prior); measured on the sample: no better, so off")
    side_search: bool = Field(True, description="re-decide limbs' depth sides over time segments by total cost")
    lean_search: bool = Field(True, description="after the depth-side search, re-decide the upper body's lean towards or "
                              "away from the camera (the chest and all above it turned about the hips by -16, -8, 8, 16 "
                              "degrees, in windows of 30 then 15 frames, the cheapest kept; take_solver.search_leans_lm): "
                              "the image shows a lean only through the spine's foreshortening. Measured (round 21, "
                              "bench/solver_sweep.py --repeats 3, without / with): all16 93.7 / 91.3 mm, on fresh draws "
                              "(--seed-offset 10) 89.2 / 86.8, better on the front-facing, the turning and the held-out "
                              "takes in both; the solve about 30 % slower")
    side_search_passes: int = Field(1, ge=1, le=5, description="passes of the depth-side search over the groups of bones at "
                                    "the full frame rate; a pass after the first re-decides a group only where mirrors "
                                    "kept since changed the body. Measured (round 15): exact 2D of the sample's walk, "
                                    "focal given, 1 / 2 passes 40.7 / 35.4 mm (200 frames), 26.9 / 19.0 (90); 16 renders "
                                    "x 3 solves (bench/solver_sweep.py --repeats 3) 100.0 / 97.9 mm (ranges 97.2-101.7 / "
                                    "97.1-98.9: within the scatter), the sample 50.9 / 53.2, turning takes 113.1 / 109.9; "
                                    "the solve 55 % slower; hence one by default")
    side_split_cos: float | None = Field(0.6, gt=0, le=1, description="after each group's whole runs, the depth-side "
                                         "search also decides the pieces of a bone's out-of-plane run on their own, cut "
                                         "where the bone comes back towards the image plane (a local minimum of |cos| to "
                                         "the viewing ray at most this) without crossing it: where the truth crosses, a "
                                         "solve that kept one side shows only a dip (take_solver.dip_pieces); None: whole "
                                         "runs only. Measured (round 28, bench/solver_sweep.py --repeats 3, None / 0.6): "
                                         "all16 90.7 / 86.6 mm, fresh draws (--seed-offset 10) 85.9 / 85.0, turning takes "
                                         "102.2 / 96.4 and 94.9 / 94.6; the solve about 30 % slower. Worse on MediaPipe's "
                                         "keypoints (pipelines/mediapipe.yaml turns it off)")
    side_search_iterations: int = Field(3, ge=1, le=10, description="LM steps each depth-side candidate (a window as it "
                                        "is and mirrored) gets before their costs are compared")
    sigma_hang: float | None = Field(1.0, gt=0, description="with a silhouette, on frames where only the head is tracked "
                                     "(the actor's back to the camera): each limb bone kept near straight down with this sd "
                                     "(unit vectors; None: off). No limb patch is seen there and the outline alone let the "
                                     "limbs flail (131_01 left/right: 200-330 mm off their root). 16 renders' mean "
                                     "seq-MPJPE (bench/solver_sweep.py): off 124.6, 0.3 122.0, 0.5 120.6, 1 112.7, 2 118.7 mm "
                                     "(single draws); over 3 repeats (--repeats 3) off 126.8, 0.7 120.3, 1 116.5, 1.5 121.7 mm")
    select_sigma_px: float = Field(1.0, gt=0, description="tracking sd while the focal length is chosen from the take alone "
                                   "(no room lines, no focal_px): the choice leans on the fit; measured on 16 renders at 2 px "
                                   "the four solver takes' mean went 87.6 -> 150.8 mm", json_schema_extra={"unit": "px"})
    select_sigma_twist: float = Field(0.5, gt=0, description="twist prior while the focal length is chosen (no torso acceleration prior then): measured on 4 renders, the tighter pose priors pull the choice 20-100 % off")
    window_frames: int = Field(300, ge=60, description="a take longer than this is solved, once the camera is found, in "
                               "overlapping windows of this many frames with the camera held: memory stays that of one "
                               "window, time grows linearly; the camera then comes from every k-th frame (at most this many)")
    window_overlap: int = Field(30, ge=6, description="frames two neighbouring windows share (cross-faded)")
    cross_seed: bool = Field(True, description="re-solve the best start's depth sides at the other starts' focal lengths, "
                             "to warn when the take does not determine the focal length (never changes the choice)")
    sigma_kp: float = Field(4.0, gt=0, description="with a keypoints input (a detector's on the same video): each keypoint where "
                            "the suit's point is lost, pixels (left/right taken as labelled or swapped, whichever fits); "
                            "only on frames where no torso patch is seen (on every lost point walk 131_01 went 107 -> 208 mm); 16 renders x 3 "
                            "draws (Pose on every frame, another numpy build): 101.6 mm mean at 4, 102.7 at 2.5, 106.5 at 6, "
                            "119.2 without; as default.yaml runs it: 101.5 at 4, 116.5 without")
    sigma_tpose: float | None = Field(0.1, gt=0, description="on the take's opening T-pose (the frames the tracker finds it on, "
                                      "mocap.tpose.find_tpose): each limb bone's direction minus the T-pose's "
                                      "(arms along the shoulder line and straight, legs straight), unit vectors (0.1: about 6 degrees); "
                                      "None: off. Not used in choosing the focal length. 16 renders x 3 solves: the T-pose frames 27.2 -> 18.2 mm "
                                      "(each aligned on its own), the whole takes within the search's scatter")
    sigma_facing: float = Field(0.3, gt=0, description="with tracks that carry a detector's torso facing (detect.mediapipe_pose): "
                                "each front's unit vector minus the detector's, soft-L1 beyond 2 sd (0.3: about 17 degrees); "
                                "four MediaPipe renders x 3 draws, mean PA-MPJPE: 88.1 mm without, 78.5 / 77.8 / 83.7 at 0.2 / 0.3 / 0.5")
    sigma_sil: float = Field(4.0, gt=0, description="with a silhouette input: a joint or bone midpoint projected outside "
                             "the actor's silhouette, beyond 2 px, costs (distance / sigma_sil)² (soft-L1 beyond 2 sigmas)",
                             json_schema_extra={"unit": "px"})


def tpose_camera(points: np.ndarray, tracked: np.ndarray, lengths: np.ndarray, f: float, centre: np.ndarray,
                 width: int, height: int, n_tpose: int, ankle_height: float) -> Camera:
    """A camera of focal ``f`` px posed by PnP of the bone-length T-pose (all joints, world z = 0 plane) on the
    mean of the first ``n_tpose`` frames' points ``(n, 16, 2)``."""
    k = min(n_tpose, points.shape[0])
    img = np.nanmean(np.where(tracked[:k, :, None], points[:k], np.nan), axis=0)
    ok = np.isfinite(img).all(axis=1)
    if ok.sum() < 6:
        raise NodeError(f"only {int(ok.sum())} joints are tracked on the first {k} frames: no T-pose to start from",
                        hint="the take must open with a T-pose facing the camera (or set focal_px and trim the take)")
    world = tpose_on_floor(lengths, ankle_height)
    K = np.array([[f, 0.0, centre[0]], [0.0, f, centre[1]], [0.0, 0.0, 1.0]])
    R, t = solve_pnp_planar(world[ok], img[ok], K, np.zeros(5))
    return Camera(K=K, R=R, t=t, width=width, height=height)


def rest_points(lengths: np.ndarray, offsets: np.ndarray, ankle_height: float) -> tuple[np.ndarray, np.ndarray]:
    """The rest T-pose on the floor ``(16, 3)`` (world frame, facing +z) and its tracked points ``(16, 3)``."""
    rest = tpose_on_floor(lengths, ankle_height)
    return rest, point_positions(rest[None], offsets)[0]


def torso_track(cam: Camera, pixels: np.ndarray, lengths: np.ndarray, offsets: np.ndarray, fps: float,
                ankle_height: float, cutoff: float = 3.0) -> np.ndarray:
    """Camera-frame torso joints ``(n, 7, 3)`` (:data:`.temporal_ray_sphere.TORSO`): the rest torso's *points*
    (where its patches sit, not its joints) fitted to the tracked torso ``pixels`` ``(n, 16, 2)`` by PnP on
    each frame (from the previous pose, the first from ``cam``), the pose low-passed, the joints placed
    with that pose."""
    import cv2
    from scipy.spatial.transform import Rotation

    from .temporal_ray_sphere import TORSO, lowpass

    idx = np.array(TORSO)
    rest, pts = rest_points(lengths, offsets, ankle_height)
    centre = rest[idx].mean(axis=0)
    obj = np.ascontiguousarray(pts[idx] - centre)
    K = np.ascontiguousarray(cam.K)
    rvec = cv2.Rodrigues(np.ascontiguousarray(cam.R))[0]
    tvec = np.ascontiguousarray((cam.R @ centre + cam.t).reshape(3, 1))
    n = pixels.shape[0]
    rv, tv = np.empty((n, 3)), np.empty((n, 3))
    for k in range(n):
        ok, r, t = cv2.solvePnP(obj, np.ascontiguousarray(pixels[k, idx]), K, None, rvec.copy(), tvec.copy(),
                                useExtrinsicGuess=True, flags=cv2.SOLVEPNP_ITERATIVE)
        if ok and np.isfinite(r).all() and np.isfinite(t).all() and t[2, 0] > 0:
            rvec, tvec = r, t
        rv[k], tv[k] = rvec[:, 0], tvec[:, 0]
    q = Rotation.from_rotvec(rv).as_quat()
    flip = np.cumprod(np.where(np.einsum("ij,ij->i", q[1:], q[:-1]) < 0, -1.0, 1.0))
    q[1:] *= flip[:, None]
    q = lowpass(q, fps, cutoff)
    R = Rotation.from_quat(q / np.linalg.norm(q, axis=1, keepdims=True)).as_matrix()
    t = lowpass(tv, fps, cutoff)
    return np.einsum("nij,kj->nki", R, rest[idx] - centre) + t[:, None, :]


def contacts_from_image(points: np.ndarray, tracked: np.ndarray, fps: float) -> np.ndarray:
    """Planted ankles ``(n, 2)`` bool from the image alone (so neither the focal length nor the depth sides can
    bias them): a planted foot does not move in the world, and the camera is still, so its ankle point stays
    put in the image. Planted = tracked and moving under 0.5 % of the body's image height per frame at 30 fps (about 1 cm)
    (both neighbouring steps), for at least 3 frames."""
    from ..skeleton import JOINT_INDEX

    ank = points[:, ANKLES]  # (n, 2, 2)
    n = points.shape[0]
    body = np.nanmedian(np.linalg.norm(points[:, JOINT_INDEX["head"]] - 0.5 * (ank[:, 0] + ank[:, 1]), axis=-1))
    thr = 0.005 * max(float(body), 1.0) * 30.0 / fps
    speed = np.full((n, 2), np.inf)
    if n > 1:
        step = np.linalg.norm(np.diff(ank, axis=0), axis=-1)
        speed[1:] = step
        speed[:-1] = np.minimum(speed[:-1], step) if n > 1 else speed[:-1]
        speed[1:-1] = np.maximum(step[1:], step[:-1])
    still = (speed < thr) & tracked[:, ANKLES]
    out = np.zeros_like(still)
    for a in range(2):  # runs of at least 3 frames
        run = 0
        for k in range(n + 1):
            if k < n and still[k, a]:
                run += 1
                continue
            if run >= 3:
                out[k - run:k, a] = True
            run = 0
    return out


def detect_contacts(P: np.ndarray, nf: np.ndarray, d: float, fps: float, ankle_height: float) -> np.ndarray:
    """Planted ankles ``(n, 2)`` bool: within 4 cm of their rest height and moving under 0.35 m/s."""
    h = P[:, ANKLES] @ nf + d - ankle_height
    v = np.zeros_like(h)
    if P.shape[0] > 1:
        step = np.linalg.norm(np.diff(P[:, ANKLES], axis=0), axis=-1) * fps
        v[1:] = step
        v[0] = step[0]
        v[1:-1] = np.minimum(step[1:], step[:-1])
    low = h < np.minimum(0.04, np.percentile(h, 20, axis=0) + 0.03)
    return low & (v < 0.35)


#: The pose solves at the chosen focal length (whole take or windows) stop once an iteration lowers the cost by
#: less than this fraction: measured on the sample and three renders, their last iterations gained under
#: 0.3 % each and moved the joints no closer to the truth (sample 51.9 -> 50.9 mm, 131_01 156 -> 139, the
#: others unchanged) at 10 % of the solve's time
POSE_TOL = 1e-3


#: The floor's normal is kept near the room's (when the room's lines lie on the floor), at least this uncertain, degrees
FLOOR_SD_FLOOR_DEG = 0.5

#: Search the body's turning direction on the torso-unseen runs in the final pose solve
#: (:func:`.take_solver.search_turns_lm`)
TURN_SEARCH = True

#: The arms' level (elbows and wrists within this many 2D neck-hips lengths of shoulder height) of the frames held to
#: the T-pose (``sigma_tpose``; :func:`..tpose.find_tpose`): stricter than the tracker's 0.3, so that the prior holds
#: a T-pose held, not the start of leaving it (on the renders the looser run ends on a frame whose arms are already
#: 11 degrees down; this one 1-2 frames earlier, 6 degrees at most)
TPOSE_PRIOR_LEVEL = 0.15

#: A start or cross seed whose subsample cost is within this fraction of the best start's, at a clearly
#: different focal length (over 10 %), makes the focal length "ambiguous" (a warning)
RIVAL_COST = 0.15


def globals_vector(f: float, d: float, free_offsets: bool, free_lengths: bool = False,
                   length_updates: np.ndarray | None = None) -> np.ndarray:
    """Globals ``[log f, floor tangent (2), floor offset, point offsets (32, if free), bone length log-updates
    (15, if free)]`` at a start."""
    lu = np.zeros(N_JOINTS - 1) if length_updates is None else np.asarray(length_updates, dtype=np.float64)
    return np.concatenate([[np.log(f), 0.0, 0.0, d], np.zeros(2 * N_JOINTS if free_offsets else 0),
                           lu if free_lengths else np.zeros(0)])


def rest_pair_distances(lengths: np.ndarray, ankle_height: float) -> np.ndarray:
    rest = tpose_on_floor(lengths, ankle_height)
    return np.linalg.norm(rest[TORSO_PAIRS[:, 0]] - rest[TORSO_PAIRS[:, 1]], axis=-1)


def point_offsets_of(p: SolveTakeParams) -> np.ndarray:
    """Offsets ``(16, 2)`` (along, out) metres of the tracked points from their joints (see ``point_offsets``)."""
    if p.point_offsets is not None:
        offs = np.asarray(p.point_offsets, dtype=np.float64)
        if offs.shape != DEFAULT_POINT_OFFSETS.shape or not np.isfinite(offs).all() or np.abs(offs).max() > 0.3:
            raise NodeError(f"point_offsets must be {DEFAULT_POINT_OFFSETS.shape[0]} rows of (along, out) metres, each "
                            f"within 0.3 m; got shape {offs.shape}", hint="one row per joint, in the joint order")
        return offs
    return DEFAULT_POINT_OFFSETS.copy() if p.points == "suit" else np.zeros_like(DEFAULT_POINT_OFFSETS)


def first_skeleton(points, tracked, lengths, f, centre, width, height, fps, p: SolveTakeParams):
    """A first skeleton for focal ``f``: camera by PnP of the T-pose, torso by PnP of its points per frame, limbs
    by ray-sphere with depth sides chosen over time. Returns ``(joints (n, 16, 3) camera frame, camera)``."""
    cam = tpose_camera(points, tracked, lengths, f, centre, width, height, p.tpose_frames, p.ankle_height)
    offsets = point_offsets_of(p)
    torso = torso_track(cam, points, lengths, offsets, fps, p.ankle_height)
    P, _, _ = solve_temporal(points, cam, lengths, fps, TemporalRaySphereParams(), torso=torso)
    return P, cam


def detector_hints(facing: np.ndarray | None = None, keypoints: np.ndarray | None = None,
                   kp_weight: np.ndarray | None = None) -> dict | None:
    """A detector's per-frame data for the solver, as :class:`.take_model.TakeData` takes it: ``facing`` ``(n, 2, 3)``
    the torso's fronts (camera axes), ``keypoints`` ``(n, 16, 2)`` px with ``kp_weight`` ``(n, 16)``; None if none."""
    out = {}
    if facing is not None:
        out["facing"] = np.asarray(facing, dtype=np.float64)
    if keypoints is not None:
        out["keypoints"] = np.nan_to_num(np.asarray(keypoints, dtype=np.float64))
        out["kp_weight"] = np.clip(np.nan_to_num(np.asarray(kp_weight, dtype=np.float64)), 0.0, 1.0)
    return out or None


def detector_keypoints(keypoints: dict, tr) -> tuple[np.ndarray, np.ndarray]:
    """A detector's ``TRACKS2D`` value (``keypoints`` input) as the solver takes it: points ``(n, 16, 2)`` px and
    weights ``(n, 16)`` (tracked times its confidence, if it gives one), checked against the suit's tracks ``tr``
    (:class:`.bundles.tracks.Tracks2D`: same frames and image size, else a NodeError)."""
    kt = read_tracks(keypoints)
    if kt.n_frames != tr.n_frames or (kt.width, kt.height) != (tr.width, tr.height):
        raise NodeError(f"the keypoints have {kt.n_frames} frames of {kt.width}x{kt.height} px, the tracks "
                        f"{tr.n_frames} of {tr.width}x{tr.height}", hint="connect a detector run on the same video")
    conf = keypoints.get("confidence") if isinstance(keypoints, dict) else None
    conf = 1.0 if conf is None else np.nan_to_num(np.asarray(conf, dtype=np.float64))
    return kt.points, kt.tracked * conf


def torso_facing_hint(tracks: dict, keypoints: dict | None = None) -> np.ndarray | None:
    """The torso facing ``(n, 2, 3)`` the solver keeps near (:class:`.take_model.TakeData` ``facing``): the tracks'
    own (a detector's tracks, ``pipelines/mediapipe.yaml``), else the keypoints input's (a detector beside a suit's
    tracks, ``default.yaml``), else None."""
    facing = tracks.get("facing") if isinstance(tracks, dict) else None
    if facing is None and isinstance(keypoints, dict):
        facing = keypoints.get("facing")
    return None if facing is None else np.asarray(facing, dtype=np.float64)


def detector_pose3d(motion: dict, n_frames: int) -> np.ndarray:
    """A detector's own 3D joints ``(n_frames, 16, 3)`` from its ``MOTION`` port value (``detect.mediapipe_pose``'s
    ``motion``), NaN on the frames where it tracked no joint (it did not run there or saw no one)."""
    joints = np.asarray(motion["joints"], dtype=np.float64)
    if joints.shape != (n_frames, N_JOINTS, 3):
        raise NodeError(f"the pose3d input's joints have shape {joints.shape}, expected ({n_frames}, {N_JOINTS}, 3)",
                        hint="connect the 3D motion found on the same video as the tracks (detect.motion)")
    found = np.asarray(motion.get("tracked", np.ones(joints.shape[:2], dtype=bool)), dtype=bool).any(axis=1)
    return np.where(found[:, None, None], joints, np.nan)


def hints_on(hints: dict | None, rows) -> dict | None:
    """The detector ``hints`` on the frames ``rows``."""
    return None if hints is None else {k: v[rows] for k, v in hints.items()}


#: A run of at least this many frames with nothing of the actor seen (:func:`unseen_frames`) is a warning
UNSEEN_WARN_FRAMES = 10


def unseen_frames(tracked: np.ndarray, silhouette: SilhouetteField | None, hints: dict | None) -> np.ndarray:
    """``(n,)`` bool: frames where nothing of the actor is seen: no point tracked (``tracked`` ``(n, 16)``), no detector
    keypoint weighed (``hints["kp_weight"]``, if any) and, with a ``silhouette``, an empty one (all-zero field). The
    solve's motion there comes from its priors alone (acceleration): extrapolated from the frames either side."""
    out = ~np.asarray(tracked, dtype=bool).any(axis=1)
    if hints is not None and "kp_weight" in hints:
        out &= ~(np.asarray(hints["kp_weight"]) > 0).any(axis=1)
    if silhouette is not None:
        out &= ~silhouette.seen()
    return out


def facing_away(weight: np.ndarray) -> np.ndarray:
    """Frames ``(n,)`` where the head's point is tracked but none of the torso's (weights ``(n, 16)``): the suit's
    patches are on the body's front, so there the torso faces away from the camera."""
    from ..skeleton import JOINT_INDEX

    return (weight[:, TORSO_JOINTS] <= 0).all(axis=1) & (weight[:, JOINT_INDEX["head"]] > 0)


def make_problem(points, weight, lengths, centre, fps, P, cam_or_floor, p: SolveTakeParams,
                 focal_prior=None, contact=None, held_globals: np.ndarray | None = None,
                 silhouette: SilhouetteField | None = None, floor_prior=None,
                 hints: dict | None = None) -> tuple[TakeProblem, float]:
    """A :class:`TakeProblem` around joints ``P`` and a floor ``(normal (3,), offset)`` (or a camera whose world
    y is up); contacts detected from ``P`` unless given; the actor's ``silhouette`` on these frames, if any;
    ``floor_prior`` ``(up (3,) camera frame, sd radians)``, the floor's normal as the room shows it, if known;
    ``hints`` a detector's per-frame data on these frames, if any (:func:`detector_hints`: the torso's ``facing``,
    ``keypoints`` and their ``kp_weight``, as :class:`.take_model.TakeData` takes them).
    Returns the problem and the floor offset."""
    if isinstance(cam_or_floor, Camera):
        nf, d = cam_or_floor.R[:, 1], float(-cam_or_floor.R[:, 1] @ cam_or_floor.t)
    else:
        nf, d = cam_or_floor
    if contact is None:
        contact = detect_contacts(P, nf, d, fps, p.ankle_height)
    contact = np.asarray(contact, dtype=bool)
    data = TakeData(points, weight, lengths, centre, fps, p.ankle_height, contact,
                    rest_pair_distances(lengths, p.ankle_height), silhouette=silhouette,
                    away=None if silhouette is None else facing_away(weight), up=nf, **(hints or {}))
    w = Weights(sigma_px=p.sigma_px, sigma_acc=p.sigma_acc, sigma_twist=p.sigma_twist, sigma_torso=p.sigma_torso,
                sigma_pelvis=p.sigma_pelvis, pelvis_depth=p.pelvis_depth_m, sigma_balance=p.sigma_balance,
                balance_band=p.balance_band_m, sigma_hip=p.sigma_hip, hip_back_cos=p.hip_back_cos, sigma_acc_torso=p.sigma_acc_torso,
                sigma_sil=p.sigma_sil, sigma_hang=p.sigma_hang, sigma_facing=p.sigma_facing, sigma_kp=p.sigma_kp,
                sigma_tpose=Weights.sigma_tpose if p.sigma_tpose is None else p.sigma_tpose)  # None: no T-pose data
    offsets = point_offsets_of(p)
    return TakeProblem(data, bone_directions(P), nf, w, offsets, fixed_globals=held_globals, free_offsets=False,
                       focal_prior=focal_prior, free_lengths=p.free_lengths, floor_prior=floor_prior), d


def solve_frames(points, weight, lengths, centre, fps, P0, floor, g_start, p, iterations, focal_prior,
                 side_search: bool, contact: np.ndarray | None = None, hold_globals: bool = False, tol: float = 1e-5,
                 silhouette: SilhouetteField | None = None, floor_prior=None, hints: dict | None = None,
                 side_passes: int = 1):
    """Whole-take solve from joints ``P0``: LM, then (optionally) the depth-side search and LM again; the globals
    ``g_start`` held when ``hold_globals`` (a window of a long take: camera and floor known); the actor's
    ``silhouette`` and a detector's ``hints`` on these frames, if any. Returns ``(problem, x, cost, normal
    equations, flips kept)``."""
    def start(P, fl, g):
        prob, _ = make_problem(points, weight, lengths, centre, fps, P, fl, p, focal_prior, contact,
                               g if hold_globals else None, silhouette, floor_prior, hints)
        x = pack_initial(P, prob.ref)
        return prob, (x if hold_globals else np.concatenate([g, x]))

    prob, x = start(P0, floor, g_start)
    x, cost, _, ne = levenberg_marquardt(prob, x, iterations, tol)
    kept = 0
    if side_search:
        g = prob.globals_of(x).copy()
        P = prob.solution(x)[4]
        P, kept = search_sides(prob, P, g, iterations=p.side_search_iterations, passes=side_passes,
                                split_cos=p.side_split_cos)
        if p.lean_search:  # the upper body's lean towards or away from the camera, window by window
            P, leans = search_leans_lm(prob, P, g)
            kept += leans
        if silhouette is not None and TURN_SEARCH:  # the final pose solve: the turn where the torso is unseen
            P, turns = search_turns_lm(prob, P, g, torso_unseen(weight))
            kept += turns
        nf, d = prob.floor(g)
        g[1:3] = 0.0
        prob, x = start(P, (nf, d), g)
        x, cost, _, ne = levenberg_marquardt(prob, x, iterations, tol)
    return prob, x, cost, ne, kept


def joints_from_directions(root: np.ndarray, dirs: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """Joints ``(n, 16, 3)`` from root positions ``(n, 3)``, unit bone directions ``(n, 15, 3)`` and bone lengths
    ``(15,)`` (bone b ends at joint b + 1)."""
    P = np.empty((root.shape[0], N_JOINTS, 3))
    P[:, 0] = root
    for j in range(1, N_JOINTS):  # joint order has parents first
        P[:, j] = P[:, PARENTS[j]] + lengths[j - 1] * dirs[:, j - 1]
    return P


def solve_windows(points, weight, lengths, centre, fps, P0, floor, g, p: SolveTakeParams, contact,
                  window: int, overlap: int, progress=None,
                  silhouette: SilhouetteField | None = None, hints: dict | None = None,
                  pose3d: np.ndarray | None = None) -> tuple[np.ndarray, int, int, list]:
    """The final solve of a long take in overlapping windows of ``window`` frames, camera and floor held
    (globals ``g``, floor ``(normal, offset)``): LM, the depth-side search, LM on each window in turn, started
    from ``P0`` ``(n, 16, 3)`` with its first ``overlap`` frames from the previous window's solution (so depth
    sides carry on), which it replaces over the overlap by a linear cross-fade of root positions and bone
    directions (the actor's ``silhouette`` and a detector's ``hints``, if any, on each window's frames; with a
    detector's 3D ``pose3d`` ``(n, 16, 3)``, each window's second start where no torso patch is seen,
    :func:`cheaper_of_two_starts`). Memory is that of one window; time is linear in the frames. Returns joints
    ``(n, 16, 3)`` (camera frame, metres), the mirrors kept, the number of windows and each window's second start
    (:func:`cheaper_of_two_starts`' second value); ``progress`` (optional) wraps the windows' iterable as ``ctx.progress`` does."""
    n = P0.shape[0]
    P = P0.copy()
    L = np.linalg.norm(P0[0, 1:] - P0[0, PARENTS[1:]], axis=-1)
    step = window - overlap
    wins, a = [], 0
    while True:
        b = n if n - a <= window + step // 2 else a + window  # a short remainder joins the last window
        wins.append((a, b))
        if b == n:
            break
        a = b - overlap
    kept, prev_end, starts = 0, 0, []  # frames [a, prev_end) hold the previous window's solution (the overlap)
    for a, b in (progress(wins, total=len(wins), desc="pose windows") if progress else wins):
        rows = slice(a, b)

        def solve(P_start, rows=rows):
            return solve_frames(points[rows], weight[rows], lengths, centre, fps, P_start, floor, g, p,
                                p.max_iterations, None, p.side_search, contact[rows], hold_globals=True,
                                tol=POSE_TOL, silhouette=None if silhouette is None else silhouette.subset(rows),
                                hints=hints_on(hints, rows), side_passes=p.side_search_passes)

        (prob, x, _, _, k), start = cheaper_of_two_starts(solve, solve(P[rows]), None if pose3d is None else pose3d[rows],
                                                         weight[rows], lengths)
        starts.append(start)
        kept += k
        Pw = prob.solution(x)[4]
        lo = prev_end - a
        if lo > 0:  # cross-fade from the previous window (w = 0) to this one (w = 1)
            w = (np.arange(lo) + 1.0) / (lo + 1.0)
            root = (1 - w)[:, None] * P[a:prev_end, 0] + w[:, None] * Pw[:lo, 0]
            dirs = unit((1 - w)[:, None, None] * bone_directions(P[a:prev_end])
                        + w[:, None, None] * bone_directions(Pw[:lo]))
            P[a:prev_end] = joints_from_directions(root, dirs, L)
        P[a + lo:b] = Pw[lo:]
        prev_end = b
    return P, kept, len(wins), starts


def moved_in_depth(P: np.ndarray, nf: np.ndarray, d: float, scale: float) -> tuple[np.ndarray, float]:
    """The body ``P`` ``(n, 16, 3)`` (camera frame) as seen at ``scale`` times the focal length: each frame's body
    moved, unchanged, to ``scale`` times its root's depth (x, y kept: the root's pixel stays, since
    u = f x / z, and the body's image keeps its size to first order; scaling the whole scene instead scales
    the image about its centre); the floor offset ``d`` moved with the roots' mean so the feet keep their
    height on average. Returns the joints and the floor offset."""
    shift = np.zeros_like(P[:, :1])
    shift[..., 2] = (scale - 1.0) * P[:, :1, 2]
    return P + shift, float(d - np.mean(shift[:, 0] @ nf))


def interpolate_joints(Psub: np.ndarray, sub: np.ndarray, n: int) -> np.ndarray:
    """Joints ``(n, 16, 3)`` on every frame from joints ``Psub`` on frames ``sub``: root positions and bone
    directions interpolated linearly (directions renormalised), bones kept at their lengths."""
    if len(sub) == n:
        return Psub.copy()
    frames = np.arange(n)
    root = np.stack([np.interp(frames, sub, Psub[:, 0, c]) for c in range(3)], axis=1)
    lengths = np.linalg.norm(Psub[0, 1:] - Psub[0, PARENTS[1:]], axis=-1)
    dirs = bone_directions(Psub)
    di = np.stack([np.stack([np.interp(frames, sub, dirs[:, b, c]) for c in range(3)], axis=1)
                   for b in range(N_JOINTS - 1)], axis=1)
    return joints_from_directions(root, unit(di), lengths)


def world_frame(P: np.ndarray, nf: np.ndarray, d: float) -> tuple[np.ndarray, np.ndarray]:
    """World -> camera ``(R (3, 3), t (3,))``: y = the floor normal (up), z = the actor's forward on the first
    frame made horizontal, origin on the floor below the first frame's hips."""
    thorax, pelvis = fronts(P[:1])
    fwd = thorax[0] + pelvis[0]
    z = fwd - (fwd @ nf) * nf
    if np.linalg.norm(z) < 1e-6:
        z = np.array([0.0, 0.0, -1.0]) - nf[2] * nf
    z = z / np.linalg.norm(z)
    y = nf
    x = np.cross(y, z)
    B = np.stack([x, y, z], axis=1)  # columns: world axes in camera coordinates
    origin = P[0, 0] - (P[0, 0] @ nf + d) * nf  # on the floor below the hips
    return B, origin


def solve_take_arrays(points: np.ndarray, tracked: np.ndarray, lengths: np.ndarray, width: int, height: int,
                      fps: float, p: SolveTakeParams, progress=None, confidence: np.ndarray | None = None,
                      silhouette: SilhouetteField | None = None, lens: LensEstimate | None = None,
                      hints: dict | None = None, pose3d: np.ndarray | None = None) -> dict:
    """The whole solve (see the module docstring) on 2D points ``(n, 16, 2)`` px; ``progress`` (optional, as
    ``ctx.progress``: wraps an iterable) shows the starts and the pose windows; ``silhouette`` (optional) the
    actor's outline on every frame; ``lens`` (optional) a focal length found before (``calibrate.vanishing_points``;
    ignored when it holds none): without ``p.focal_px`` the solve starts there and keeps it as a prior (its sd and
    ``p.lens_sd_floor_pct`` combined), and the floor's normal found with it (``up_cam``) as a prior too (sd at least
    :data:`FLOOR_SD_FLOOR_DEG`); ``hints`` (optional, :func:`detector_hints`) a detector's per-frame data: the thorax's
    and the pelvis's fronts (``sigma_facing``) and its keypoints where the suit's points are lost (``sigma_kp``); ``pose3d``
    ``(n, 16, 3)`` (optional; NaN rows where absent) a detector's own 3D joints, any frame and scale: on the frames
    where no torso patch is seen, the final pose solve is run a second time from its limbs' directions
    (:func:`limbs_from_pose`) and the cheaper solve kept (``report["pose3d_start_kept"]``; on a take longer than
    ``window_frames``, in each window). Returns a dict with
    ``joints`` (n, 16, 3) world metres, ``camera`` (:class:`Camera`), ``sides`` (n, 16) int8, ``report``.

    BLAS runs on one thread meanwhile: the solver's matrices are small (33 x 33 frame blocks, a band of 99),
    where threads cost more than they save (measured on the sample, 2 cores: the same wall time, 8.5 s, for
    half the CPU time, 8.4 s instead of 16.3 s; on a busy machine 2 threads were slower)."""
    import scipy.linalg  # noqa: F401 - load scipy's BLAS now, so the limit below reaches it too
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        return _solve_take(points, tracked, lengths, width, height, fps, p, progress, confidence, silhouette, lens, hints,
                           pose3d)


def take_inputs(points: np.ndarray, tracked: np.ndarray, fps: float, p: SolveTakeParams,
                confidence: np.ndarray | None = None, hints: dict | None = None) -> tuple[np.ndarray, dict | None]:
    """What every solve of a take weighs, from its tracked ``points`` ``(n, 16, 2)`` pixels and ``tracked``
    ``(n, 16)``: the points' weights ``(n, 16)`` (1 where tracked, times ``confidence`` ``(n, 16)`` to the power
    ``p.confidence_power`` when given) and the per-frame ``hints`` as the problem takes them (:func:`detector_hints`'
    keypoints kept only on frames where no torso patch is seen; the opening T-pose's frames, ``tpose`` ``(n,)`` bool,
    added when ``p.sigma_tpose`` is set and :func:`..tpose.find_tpose` finds them; None when there is nothing)."""
    if hints is not None and "keypoints" in hints:  # a detector's keypoints only where no torso patch is seen
        hints = {**hints, "kp_weight": hints["kp_weight"] * torso_unseen(tracked.astype(np.float64))[:, None]}
        if not hints["kp_weight"].any():  # none left: the problem is the one without keypoints
            hints = {k: v for k, v in hints.items() if k not in ("keypoints", "kp_weight")} or None
    if p.sigma_tpose is not None:  # the opening T-pose's frames: a per-frame prior carried like a detector's data
        found = find_tpose(points, tracked, fps, max_untracked=1, level=TPOSE_PRIOR_LEVEL)  # one patch may be lost
        if found is not None:
            tpose = np.zeros(points.shape[0], dtype=bool)
            tpose[found[0]:found[1] + 1] = True
            hints = {**(hints or {}), "tpose": tpose}
    weight = tracked.astype(np.float64)
    if p.confidence_power > 0 and confidence is not None:
        weight = weight * np.clip(np.nan_to_num(np.asarray(confidence, dtype=np.float64)), 0.0, 1.0) ** p.confidence_power
    return weight, hints


def limbs_from_pose(P: np.ndarray, pose: np.ndarray, frames: np.ndarray, lengths: np.ndarray) -> np.ndarray:
    """``P`` ``(n, 16, 3)`` (camera frame, metres) with the limbs and head on ``frames`` ``(n,)`` bool re-placed along
    the bone directions of a detector's own 3D ``pose`` ``(n, 16, 3)`` (any frame and scale, e.g. MediaPipe's world
    landmarks), each frame's ``pose`` turned onto ``P``'s torso first (:func:`..rigid.procrustes` over the torso
    joints); the root and torso stay, every bone keeps its length ``lengths`` ``(16,)``."""
    from ..rigid import procrustes

    out = P.copy()
    rows = np.flatnonzero(frames & np.isfinite(pose).all(axis=(1, 2)))
    if rows.size == 0:
        return out
    _, R, t = procrustes(pose[rows][:, TORSO_JOINTS], P[rows][:, TORSO_JOINTS])
    Q = np.einsum("nij,nkj->nki", R, pose[rows]) + t[:, None]
    for j in range(1, N_JOINTS):  # parents first
        if j in TORSO_JOINTS:
            continue
        u = Q[:, j] - Q[:, PARENTS[j]]
        u = u / np.maximum(np.linalg.norm(u, axis=-1, keepdims=True), 1e-9)
        out[rows, j] = out[rows, PARENTS[j]] + lengths[j] * u
    return out


def cheaper_of_two_starts(solve, first: tuple, pose3d: np.ndarray | None, weight: np.ndarray, lengths: np.ndarray):
    """``first`` (a :func:`solve_frames` result ``(problem, x, cost, normal equations, flips)``) or ``solve(P)``
    (the same solve from joints ``P`` ``(n, 16, 3)``), whichever ends cheaper, where ``P`` is ``first``'s answer with the
    limbs of a detector's own 3D ``pose3d`` ``(n, 16, 3)`` (NaN rows where it saw no one) on the frames where no torso
    patch is seen (``weight`` ``(n, 16)``; :func:`limbs_from_pose`). Returns the chosen result and
    ``(frames restarted, kept, first's cost, second's cost)``, or ``None`` when no frame needed a second start."""
    if pose3d is None:
        return first, None
    pose3d = np.asarray(pose3d, dtype=np.float64)
    rows = torso_unseen(weight) & np.isfinite(pose3d).all(axis=(1, 2))
    if not rows.any():
        return first, None
    second = solve(limbs_from_pose(first[0].solution(first[1])[4], pose3d, rows, lengths))
    kept = bool(second[2] < first[2])
    return (second if kept else first), (int(rows.sum()), kept, float(first[2]), float(second[2]))


def second_start_report(report: dict, starts: list) -> None:
    """``report`` updated with what :func:`cheaper_of_two_starts` did (``starts``: its second values, one per solve
    or window; None entries skipped): the frames restarted, whether any second start was kept, and the costs
    summed over the solves that had one."""
    starts = [s for s in starts if s is not None]
    if starts:
        report.update(pose3d_start_frames=sum(s[0] for s in starts), pose3d_start_kept=any(s[1] for s in starts),
                      pose_cost=round(sum(s[2] for s in starts), 1), pose_cost_pose3d=round(sum(s[3] for s in starts), 1))


def _solve_take(points, tracked, lengths, width, height, fps, p: SolveTakeParams, progress, confidence, sil,
                lens=None, hints=None, pose3d=None) -> dict:
    weight, hints = take_inputs(points, tracked, fps, p, confidence, hints)

    def hint(rows, tpose: bool = True):  # the detector's data on these frames (None without); without the T-pose's
        # frames where the focal length is chosen (held out sideways, arms of the wrong length move the focal instead)
        h = hints if tpose or hints is None else ({k: v for k, v in hints.items() if k != "tpose"} or None)
        return hints_on(h, rows)

    floor_prior = None
    n = points.shape[0]
    centre = np.array([(width - 1) / 2.0, (height - 1) / 2.0])
    report: dict = {"frames": n}
    if hints is not None and "kp_weight" in hints:  # frames placed by a detector's keypoints (no torso patch seen)
        report["keypoint_frames"] = int((hints["kp_weight"] > 0).any(axis=1).sum())
    if hints is not None and "tpose" in hints:  # frames held to the opening T-pose (sigma_tpose)
        report["tpose_prior_frames"] = int(np.sum(hints["tpose"]))
    warnings_out: list[str] = []
    unseen = unseen_frames(tracked, sil, hints)
    report["unseen_ranges"] = [[int(r[0]), int(r[-1])] for r in runs_of(unseen, min_len=1)]
    for r in runs_of(unseen, min_len=UNSEEN_WARN_FRAMES):
        warnings_out.append(f"nothing of the actor is seen on frames {r[0]}-{r[-1]} ({len(r) / fps:.1f} s: no patch, "
                            "no keypoint, no silhouette — out of the picture?): the 3D motion there is extrapolated "
                            "from the frames either side, not measured ('not seen' in doubtful_ranges)")
    # for each starting focal length (or the known one): a first skeleton; on a frame subsample spread over
    # the take, LM, the depth-side search and LM again; then every frame from that solution (interpolated),
    # LM with the focal length and floor free. The start whose whole-take cost is lowest wins.
    step = max(1, int(np.ceil(n / p.calib_frames)))
    sub = np.arange(0, n, step)
    if p.focal_px is not None:
        starts, focal_prior = [float(p.focal_px)], (float(p.focal_px), 1e-4)
        report["focal_source"] = "given"
        q, estimated = p, False
    elif lens is not None and lens.focal_px is not None:
        # a focal length from the room (calibrate.vanishing_points): one start there, kept as a prior; the take
        # alone leaves the focal length 10-50 % off (round 20: 25 % on average), the room's lines fix it to about 1 %
        f_room, sd_room = float(lens.focal_px), float(lens.focal_sd_pct or 0.0) / 100.0
        if lens.up_cam is not None:  # and the floor's normal, when the lines lie on it
            floor_prior = (np.asarray(lens.up_cam, dtype=np.float64),
                           np.radians(max(float(lens.up_sd_deg or 0.0), FLOOR_SD_FLOOR_DEG)))
            report["floor_source"] = "room lines"
        starts, focal_prior = [f_room], (f_room, float(np.hypot(sd_room, p.lens_sd_floor_pct / 100.0)))
        origin = "lens file" if lens.source.startswith("lens file") else "room lines"  # calibrate.vanishing_points says
        report["focal_source"] = f"{origin} {f_room:.0f} px ± {100 * sd_room:.1f} %, refined by the take"
        q, estimated = p, False  # solved as with a given focal length, which the prior lets move by a few %
    else:
        # weak prior: lenses of ordinary cameras have f ~ 0.8-1.9 x the image width (log-normal around 1.2 W)
        starts, focal_prior = [m * width for m in p.focal_grid], (p.focal_prior_width * width, p.focal_prior_log_sd)
        report["focal_source"] = "estimated from the take"
        # the focal length is chosen under the weaker priors (the torso's acceleration prior is metric, so it
        # scales with the focal length and pulls the choice); the pose is then solved at it with p's priors
        q, estimated = p.model_copy(update={"sigma_twist": p.select_sigma_twist, "sigma_acc_torso": None,
                                            "sigma_px": p.select_sigma_px}), True
    contact = contacts_from_image(points, tracked, fps)
    report["planted_pct"] = [round(float(c) * 100, 1) for c in contact.mean(axis=0)]
    best, sweep, kept1 = None, [], 0
    for f0 in (progress(starts, total=len(starts), desc="focal starts") if progress else starts):
        try:
            P0, cam = first_skeleton(points, tracked, lengths, f0, centre, width, height, fps, p)
        except (NodeError, ValueError):
            continue
        g0 = globals_vector(f0, float(-cam.R[:, 1] @ cam.t), False, p.free_lengths)
        prob_k, x_k, cost_k, _, kept = solve_frames(points[sub], weight[sub], lengths, centre, fps / step, P0[sub], cam,
                                                    g0, q, p.calib_iterations, focal_prior, p.side_search,
                                                    contact[sub], floor_prior=floor_prior, hints=hint(sub, False))
        f_end = float(np.exp(prob_k.globals_of(x_k)[0]))
        sweep.append([round(f0, 1), round(f_end, 1), round(cost_k, 1)])
        if best is None or cost_k < best[0]:
            best, kept1 = (cost_k, prob_k, x_k), kept
    if best is None:
        raise NodeError("no starting focal length gave a first skeleton",
                        hint="check that the take opens with a T-pose facing the camera, or set focal_px")
    report["focal_sweep"] = sweep
    cost, probs, xs = best
    if p.cross_seed and len(sweep) > 1:
        # the best start's depth sides tried at the other starts' focal lengths (each frame's body moved in depth
        # so that its image stays, :func:`moved_in_depth`), to tell whether the take determines the focal length:
        # a cross seed nearly as cheap is a rival (a warning below), never the choice — measured on four takes,
        # such ties went either way (131_01 would have gone to +100 %, 131_02 to -42 %)
        f_best, nf_b, d_b, _, P_b = probs.solution(xs)
        cross = []
        for f0, f_end, _ in sweep:
            if abs(np.log(f_end / f_best)) < np.log(1.05):
                continue
            P_k, d_k = moved_in_depth(P_b, nf_b, d_b, f_end / f_best)
            gs = np.concatenate([[np.log(f_end), 0.0, 0.0, d_k], probs.globals_of(xs)[4:]])
            prob_k, x_k, cost_k, _, _ = solve_frames(points[sub], weight[sub], lengths, centre, fps / step, P_k,
                                                     (nf_b, d_k), gs, q, p.calib_iterations,
                                                     focal_prior, False, contact[sub], floor_prior=floor_prior,
                                                     hints=hint(sub, False))
            cross.append([round(f_end, 1), round(float(np.exp(prob_k.globals_of(x_k)[0])), 1), round(cost_k, 1)])
        report["focal_cross_seeded"] = cross
        sweep = sweep + cross
    # the chosen start on every frame (interpolated from the subsample), LM with the focal length and floor free;
    # on a long take on every k-th frame (at most window_frames), the camera then held in windows
    whole = n <= p.window_frames
    k_cam = 1 if whole else int(np.ceil(n / p.window_frames))
    cam_rows = np.arange(0, n, k_cam)
    g_sub = probs.globals_of(xs)
    nf0, d0 = probs.floor(g_sub)
    P1 = interpolate_joints(probs.solution(xs)[4], sub, n)
    gs = np.concatenate([g_sub[:1], [0.0, 0.0, d0], g_sub[4:]])
    prob, x, cost, ne, _ = solve_frames(points[cam_rows], weight[cam_rows], lengths, centre, fps / k_cam, P1[cam_rows],
                                        (nf0, d0), gs, q, p.max_iterations, focal_prior, False, contact[cam_rows],
                                        floor_prior=floor_prior, hints=hint(cam_rows, False))
    kept2 = 0
    # uncertainty of the focal length (log f) from the normal equations, scaled by the fit's residual level
    dof = max(prob.residuals(x).size - x.size, 1)
    scale = max(2.0 * cost / dof, 1e-12)
    try:
        cov = ne.globals_covariance() * scale if ne is not None else np.full((4, 4), np.nan)
        focal_sd_pct = float(np.sqrt(max(cov[0, 0], 0.0)) * 100.0)
    except Exception:  # noqa: BLE001 - a singular system: the focal length is not determined
        focal_sd_pct = float("inf")
    if whole and (estimated or p.side_search):  # the pose at the chosen focal length under p's priors: LM,
        f_sel, nf_s, d_s, _, P_s = prob.solution(x)  # the depth-side search on the whole take, LM (focal held)
        g_s = np.concatenate([[np.log(f_sel), 0.0, 0.0, d_s], prob.globals_of(x)[4:]])
        if sil is not None:  # where only the head is seen, the body first set on the floor at the outline's lowest row
            P_s = seat_on_outline(P_s, f_sel, centre, nf_s, d_s, sil, facing_away(weight))
        prob, x, cost, ne, kept2 = solve_frames(points, weight, lengths, centre, fps, P_s, (nf_s, d_s), g_s, p,
                                                p.max_iterations, (f_sel, 1e-4), p.side_search, contact,
                                                tol=POSE_TOL, silhouette=sil, floor_prior=floor_prior, hints=hint(slice(None)),
                                                side_passes=p.side_search_passes)
        # a second start: the detector's own 3D limbs where no torso patch is seen (the back turned: the solve's own
        # answer there is often a dearer basin than one near the truth, bench/solver_landscape.py), the cheaper kept
        def again(P_2, first=(prob, x)):  # the same solve from P_2, the first's camera and floor held (only if needed)
            f_2, nf_2, d_2, _, _ = first[0].solution(first[1])
            g_2 = np.concatenate([[np.log(f_2), 0.0, 0.0, d_2], first[0].globals_of(first[1])[4:]])
            return solve_frames(points, weight, lengths, centre, fps, P_2, (nf_2, d_2), g_2, p, p.max_iterations,
                                (f_2, 1e-4), p.side_search, contact, tol=POSE_TOL, silhouette=sil,
                                floor_prior=floor_prior, hints=hint(slice(None)), side_passes=p.side_search_passes)

        (prob, x, cost, ne, kept2), start = cheaper_of_two_starts(again, (prob, x, cost, ne, kept2), pose3d, weight, lengths)
        second_start_report(report, [start])
    elif not whole:  # the same in windows, camera and floor held
        f_sel, nf_s, d_s, _, P_s = prob.solution(x)
        g_s = np.concatenate([[np.log(f_sel), 0.0, 0.0, d_s], prob.globals_of(x)[4:]])
        P_w = interpolate_joints(P_s, cam_rows, n)
        if sil is not None:
            P_w = seat_on_outline(P_w, f_sel, centre, nf_s, d_s, sil, facing_away(weight))
        P_w, kept2, report["windows"], starts = solve_windows(points, weight, lengths, centre, fps, P_w,
                                   (nf_s, d_s), g_s, p, contact, p.window_frames, p.window_overlap, progress, sil,
                                   hint(slice(None)), pose3d)
        second_start_report(report, starts)
        prob, _ = make_problem(points, weight, lengths, centre, fps, P_w, (nf_s, d_s), p, None, contact, g_s, sil,
                               hints=hint(slice(None)))
        x = pack_initial(P_w, prob.ref)
    f, nf, d, offs, P = prob.solution(x)
    terms = prob.term_costs(x)
    B, origin = world_frame(P, nf, d)
    K = np.array([[f, 0.0, centre[0]], [0.0, f, centre[1]], [0.0, 0.0, 1.0]])
    camera = Camera(K=K, R=B, t=origin, width=width, height=height)
    joints = camera.to_world(P)
    cam_centre = camera.center
    hips0 = joints[0, 0]
    axis_world = B.T @ np.array([0.0, 0.0, 1.0])
    sides = np.zeros((n, N_JOINTS), dtype=np.int8)
    par = np.where(PARENTS < 0, 0, PARENTS)
    sides[:, 1:] = np.where(P[:, 1:, 2] < P[:, par[1:], 2], -1, 1)
    reproj = np.linalg.norm(
        (f * point_positions(P, offs)[..., :2] / point_positions(P, offs)[..., 2:3] + centre) - points, axis=-1)
    report.update(
        focal_px=round(f, 2), focal_sd_pct=round(focal_sd_pct, 3),
        camera_height_m=round(float(cam_centre[1]), 4),
        camera_distance_m=round(float(np.hypot(cam_centre[0] - hips0[0], cam_centre[2] - hips0[2])), 4),
        camera_tilt_deg=round(float(np.degrees(np.arcsin(np.clip(-axis_world[1], -1, 1)))), 3),
        fit_px_median=round(float(np.median(reproj[tracked])), 4) if tracked.any() else None,
        fit_px_p95=round(float(np.percentile(reproj[tracked], 95)), 4) if tracked.any() else None,
        side_flips=int(kept1 + kept2),
        cost={k: round(v, 2) for k, v in terms.items()},
        bone_lengths_m={k: round(v, 4) for k, v in lengths_to_body(prob.lengths_of(prob.globals_of(x))).items()},
    )
    # a second start ending at a clearly different focal length at a similar cost: the take cannot tell them apart
    # the focal lengths the starts and cross seeds found about as cheap as the cheapest: how far the take leaves the
    # focal length open (the Jacobian's focal_sd_pct is the curvature at one minimum and understates it)
    cheapest = min(c for _, _, c in sweep)
    near = [f] + [fe for _, fe, c in sweep if c < (1 + RIVAL_COST) * cheapest]
    rivals = [fe for fe in near[1:] if abs(np.log(fe / f)) > np.log(1.1)]
    if estimated and len(starts) > 1:
        report["focal_fits_px_min"], report["focal_fits_px_max"] = round(min(near), 1), round(max(near), 1)
    if rivals:
        report["focal_rivals_px"] = [round(r, 1) for r in rivals]
        warnings_out.append(f"the focal length is ambiguous: {f:.0f} px fits, but so does {rivals[0]:.0f} px about as well "
                            f"(anything from {min(near):.0f} to {max(near):.0f} px); 3D positions scale with it — give the "
                            "camera's focal length (focal_px) if you know it")
    if not np.isfinite(focal_sd_pct) or focal_sd_pct > 5.0:
        warnings_out.append(f"the focal length is uncertain: {f:.0f} px ± {focal_sd_pct:.1f} % (1 sd); the take may "
                            "lack depth motion (walk towards or away from the camera, turn) — give focal_px if known")
    report["warnings"] = warnings_out
    return {"joints": joints, "camera": camera, "sides": sides, "report": report, "camera_frame_joints": P}


def silhouette_field(silhouette: dict, n_frames: int) -> SilhouetteField:
    """The solver's view of a ``SILHOUETTE`` port value (``segment.silhouette``) for a take of ``n_frames``
    frames; a silhouette of another length is an error (it was made from another video)."""
    dist = np.asarray(silhouette["distance"])
    if dist.shape[0] != n_frames:
        raise NodeError(f"the silhouette has {dist.shape[0]} frames, the tracks {n_frames}",
                        hint="connect the silhouette made from the same video as the tracks")
    bottom = silhouette.get("bottom_px")
    return SilhouetteField(dist, float(silhouette["scale"]), np.arange(n_frames),
                           None if bottom is None else np.asarray(bottom, dtype=np.float64))


@node(
    "reconstruct.solve_take",
    version=1,
    inputs={"tracks": TRACKS2D, "body": optional(BODY, "bone lengths; defaults if absent"),
            "silhouette": optional(SILHOUETTE, "the actor's silhouette per frame (segment.silhouette): joints kept inside "
                                   "it, the lower foot on the floor, the torso facing away where no torso patch is seen"),
            "lens": optional(LENS, "a focal length found before (calibrate.vanishing_points): the start and a prior, "
                             "unless focal_px is given"),
            "keypoints": optional(TRACKS2D, "a detector's 2D joints on the same video (detect.mediapipe_pose): where no "
                                  "torso patch is seen (the actor's back to the camera), each joint's keypoint (sigma_kp); "
                                  "its torso facing, if it carries one and the tracks do not (sigma_facing)"),
            "pose3d": optional(MOTION, "a detector's own 3D joints on the same video (detect.mediapipe_pose's motion: "
                               "MediaPipe's world landmarks): where no torso patch is seen, a second start of the final "
                               "pose solve takes its limbs' directions, and the cheaper of the two solves is kept")},
    outputs={
        "motion": MOTION,
        "camera": CAMERA,
        "report": report_port("camera figures (focal, height, distance, tilt, uncertainty), costs, warnings"),
        "sides": SIDES,
    },
    params=SolveTakeParams,
)
def solve_take(ctx, tracks, body, silhouette=None, lens=None, keypoints=None, pose3d=None):
    """Camera (focal, pose above the floor) and motion estimated together from the whole take's 2D tracks."""
    p: SolveTakeParams = ctx.params
    tr = read_tracks(tracks)
    if tr.fps is None or not np.isfinite(tr.fps) or tr.fps <= 0:
        raise NodeError("the tracks have no frame rate", hint="the tracking node must give 'fps'")
    if tr.n_frames < 3:
        raise NodeError(f"the take has {tr.n_frames} frames; the solver needs at least 3")
    lengths = body_lengths(body)
    if p.point_offsets is None and isinstance(tracks, dict) and tracks.get("point_offsets") is not None:
        # a detector's calibrated landmark offsets travel with its tracks (detect.mediapipe_pose)
        p = p.model_copy(update={"point_offsets": np.asarray(tracks["point_offsets"], dtype=np.float64).tolist()})
        ctx.log("point offsets from the tracks (the detector's calibrated offsets)")
    confidence = tracks.get("confidence") if isinstance(tracks, dict) else None
    if p.confidence_power > 0 and confidence is None:
        ctx.warn("confidence_power is set but the tracks carry no confidence: every tracked point weighs the same "
                 "(detectors such as detect.mediapipe_pose give one; suit trackers do not)")
    sil = None if silhouette is None else silhouette_field(silhouette, tr.n_frames)
    if lens is not None and lens.focal_px is not None and p.focal_px is None:
        if (lens.width, lens.height) != (tr.width, tr.height):
            raise NodeError(f"the lens estimate is for {lens.width}x{lens.height} px images, the tracks are "
                            f"{tr.width}x{tr.height}", hint="connect the lens found on the same video as the tracks")
    facing = torso_facing_hint(tracks, keypoints)
    if facing is not None:
        if facing.shape != (tr.n_frames, 2, 3):
            raise NodeError(f"the tracks' facing has shape {facing.shape}, expected ({tr.n_frames}, 2, 3)",
                            hint="facing: per frame the thorax's and the pelvis's front, camera axes")
        ctx.log(f"torso facing from the tracks on {100 * (np.linalg.norm(facing[:, 0], axis=-1) > 0.5).mean():.0f} % of frames "
                "(the detector's own 3D)")
    kp, kp_weight = None, None
    if keypoints is not None:
        kp, kp_weight = detector_keypoints(keypoints, tr)
        ctx.log(f"detector keypoints on {100 * torso_unseen(tr.tracked.astype(float)).mean():.0f} % of frames "
                "(no torso patch seen)")
    limbs3d = None if pose3d is None else detector_pose3d(pose3d, tr.n_frames)
    if limbs3d is not None:
        ctx.log(f"detector 3D pose on {100 * np.isfinite(limbs3d).all(axis=(1, 2)).mean():.0f} % of frames (a second "
                "start where no torso patch is seen)")
    t0 = time.perf_counter()
    out = solve_take_arrays(tr.points, tr.tracked, lengths, tr.width, tr.height, float(tr.fps), p,
                            progress=ctx.progress, confidence=confidence, silhouette=sil, lens=lens,
                            hints=detector_hints(facing, kp, kp_weight), pose3d=limbs3d)
    rep = out["report"]  # no timing in it: it is hashed into the keys of the nodes it feeds (evaluate.metrics)
    ctx.log(f"focal {rep['focal_px']:.0f} px (± {rep['focal_sd_pct']:.1f} %), camera {rep['camera_height_m']:.2f} m high, "
            f"{rep['camera_distance_m']:.2f} m away, tilt {rep['camera_tilt_deg']:.1f}°; {time.perf_counter() - t0:.1f} s")
    for w in rep["warnings"]:
        ctx.warn(w)
    motion = {"joints": out["joints"], "fps": np.asarray(tr.fps, dtype=np.float64), "tracked": tr.tracked.copy(),
              "joint_names": np.array(JOINT_NAMES)}
    return {"motion": motion, "camera": out["camera"].to_model(), "report": out["report"],
            "sides": {"sides": out["sides"], "joint_names": np.array(JOINT_NAMES), "fps": np.asarray(tr.fps, dtype=np.float64)}}
