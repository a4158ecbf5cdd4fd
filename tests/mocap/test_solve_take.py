"""reconstruct.solve_take and its model (take_model): the block normal equations equal the dense ones, a
noise-free take is recovered exactly (focal and joints), the depth-side mirror keeps the image, planted feet
are found from the image, and the node runs on the bundled sample's tracks."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tbha_graph.mocap.camera import Camera
from tbha_graph.mocap.reconstruct.solve_take import (SolveTakeParams, contacts_from_image, globals_vector,
                                                     moved_in_depth, rest_pair_distances, solve_take_arrays,
                                                     world_frame)
from tbha_graph.mocap.reconstruct.take_model import (DEFAULT_POINT_OFFSETS, TakeData, TakeProblem, Weights,
                                                     bone_directions, pack_initial, point_positions, unit)
from tbha_graph.mocap.reconstruct.take_solver import levenberg_marquardt, mirror, normal_equations
from tbha_graph.mocap.skeleton import JOINT_INDEX, PARENTS

ROOT = Path(__file__).resolve().parents[2]
TRUTH = ROOT / "data" / "sample" / "ground_truth.npz"


@pytest.fixture(scope="module")
def truth():
    with np.load(TRUTH, allow_pickle=False) as z:
        return {k: z[k] for k in ("joints3d_cam", "joints3d_world", "K", "R", "t", "bone_lengths", "fps", "width", "height")}


def synthetic(truth, n: int, f: float = 700.0, start: int = 60):
    """``n`` frames of the sample's true motion (camera frame) made exactly representable (each bone at its
    median length along its true direction), the exact 2D of the model's points at focal ``f``, the image
    centre, and the bone lengths ``(16,)``."""
    P = truth["joints3d_cam"][start:start + n].copy()
    L = np.r_[0.0, np.median(np.linalg.norm(P[:, 1:] - P[:, PARENTS[1:]], axis=-1), axis=0)]
    D = bone_directions(P)
    for j in range(1, 16):
        P[:, j] = P[:, PARENTS[j]] + L[j] * D[:, j - 1]
    w, h = int(truth["width"]), int(truth["height"])
    centre = np.array([(w - 1) / 2.0, (h - 1) / 2.0])
    Q = point_positions(P, DEFAULT_POINT_OFFSETS)
    return P, f * Q[..., :2] / Q[..., 2:3] + centre, centre, L


#: The node's params for tests of what it hands the solver (a few iterations, no search: the wiring, not the answer)
QUICK_NODE_PARAMS = {"focal_px": 700.0, "max_iterations": 2, "calib_iterations": 2, "side_search": False, "cross_seed": False}


def suit_tracks(truth, uv) -> dict:
    """A ``TRACKS2D`` port value of the 2D points ``uv`` ``(n, 16, 2)``, every point tracked, at the sample's size."""
    from tbha_graph.mocap.skeleton import JOINT_NAMES

    return {"points": uv, "tracked": np.ones(uv.shape[:2], bool), "fps": np.array(30.0),
            "width": np.array(int(truth["width"])), "height": np.array(int(truth["height"])),
            "joint_names": np.array(JOINT_NAMES)}


def solver_calls(monkeypatch, keyword: str) -> list:
    """The values of ``keyword`` that ``solve_take_arrays`` is called with from now on (appended per call; the
    solver still runs)."""
    from tbha_graph.mocap.reconstruct import solve_take as st

    seen, real = [], st.solve_take_arrays

    def recording(*args, **kwargs):
        seen.append(kwargs.get(keyword))
        return real(*args, **kwargs)

    monkeypatch.setattr(st, "solve_take_arrays", recording)
    return seen


def problem(truth, P, uv, centre, L, weights: Weights, free_offsets=False, focal_prior=None, free_lengths=False,
            silhouette=None, **hints):
    R = truth["R"]
    nf, d = R[:, 1], float(-R[:, 1] @ truth["t"])
    fps = float(truth["fps"])
    contact = contacts_from_image(uv, np.ones(uv.shape[:2], bool), fps)
    data = TakeData(uv, np.ones(uv.shape[:2]), L, centre, fps, 0.08, contact, rest_pair_distances(L, 0.08),
                    silhouette=silhouette, **hints)
    prob = TakeProblem(data, bone_directions(P), nf, weights, DEFAULT_POINT_OFFSETS.copy(), free_offsets=free_offsets,
                       focal_prior=focal_prior, free_lengths=free_lengths)
    return prob, d


@pytest.mark.parametrize("free_offsets,free_lengths,split,sil,priors", [(False, False, False, False, False), (True, False, False, False, False),
                                                                        (False, True, False, False, False), (False, False, True, False, False),
                                                                        (False, False, False, True, False), (False, False, False, False, True)])
def test_block_normal_equations_equal_the_dense_ones(truth, free_offsets, free_lengths, split, sil, priors, monkeypatch):
    from tbha_graph.mocap.reconstruct import take_solver

    monkeypatch.setattr(take_solver, "JACOBIAN_CHUNK", 4)  # the frame Jacobian in chunks of 4, 4 and 1 frames
    P, uv, centre, L = synthetic(truth, 9)
    silhouette = None
    if sil:  # stick-figure silhouettes 3 px right of the joints: every point a little outside (the focal's column too)
        from test_take_jacobian import thin_silhouettes

        silhouette = thin_silhouettes(700.0 * P[..., :2] / P[..., 2:3] + centre + [3.0, 0.0], ghost=-60.0)
    hints = {}
    if sil:  # with a detector's keypoints (left and right swapped on some frames) and torso facing: their rows too
        from tbha_graph.mocap.reconstruct.take_model import KP_PAIRS, fronts

        kp = 700.0 * P[..., :2] / P[..., 2:3] + centre + np.random.default_rng(3).normal(scale=4.0, size=(9, 16, 2))
        kp[::2][:, KP_PAIRS.ravel()] = kp[::2][:, KP_PAIRS[:, ::-1].ravel()]
        hints = {"keypoints": kp, "kp_weight": np.full((9, 16), 0.8),
                 "facing": np.stack(fronts(P), axis=1) + np.array([0.1, 0.0, -0.1]),
                 "tpose": np.arange(9) < 5}  # and the opening T-pose's rows after them (the focal's column too)
    prob, d = problem(truth, P, uv + 0.7, centre, L, Weights(support_band=-0.03 if sil else 0.1, upright_sin=0.02), free_offsets=free_offsets,
                      free_lengths=free_lengths, silhouette=silhouette, **hints)
    prob.d.away = np.arange(9) % 3 == 0 if sil else None
    prob.d.up = -truth["R"][:, 1] if sil else None  # the vertical: the upright term on the away frames
    if sil:  # limbs untracked on every other frame: the silhouette's term on their points; the torso too on every
        prob.d.weight[::2, 5:] = 0.0  # fourth: the cover term there (a second right leg the model lacks)
        prob.d.weight[::4, :5] = 0.0
    if split:  # two independent windows in one problem (the side search's batches): nothing links frame 3 to 4
        prob.d.breaks = np.r_[True, False, False, False, True, False, False, False, False]
        acc, _ = prob.coupled_terms(P, prob.n_ref)
        assert np.all(acc[2] == 0) and np.all(acc[3] == 0) and np.any(acc[4] != 0)
        prob.d.contact[:] = True
        assert not prob.slide_vectors(P, prob.n_ref)[1][4].any() and prob.slide_vectors(P, prob.n_ref)[1][5].all()
        prob.d.contact[:] = contacts_from_image(uv, np.ones(uv.shape[:2], bool), float(truth["fps"]))
    if priors:  # a known focal length and the room's floor normal (3 degrees off this floor's): both in the globals' rows
        tilted = truth["R"][:, 1] + np.array([0.0, 0.0, 0.05])
        prob.focal_prior = (700.0, 0.02)
        prob.floor_prior = (tilted / np.linalg.norm(tilted), np.radians(0.5))
    lu = 0.02 * np.random.default_rng(2).standard_normal(15)
    x = np.concatenate([globals_vector(660.0, d, free_offsets, free_lengths, lu), pack_initial(P, prob.ref)])
    x[prob.n_glob:] += 0.01 * np.random.default_rng(1).standard_normal(x.size - prob.n_glob)
    r0 = prob.residuals(x)
    J = np.empty((r0.size, x.size))
    for i in range(x.size):  # brute force, one unknown at a time (central differences)
        xp, xm = x.copy(), x.copy()
        xp[i] += 1e-6
        xm[i] -= 1e-6
        J[:, i] = (prob.residuals(xp) - prob.residuals(xm)) / 2e-6
    A = J.T @ J
    want = -np.linalg.solve(A + 0.1 * np.diag(np.diag(A)), J.T @ r0)
    if sil:
        assert prob.term_costs(x)["silhouette"] > 1.0
        from tbha_graph.mocap.reconstruct.take_model import SIL_PAIRS

        inside = prob.frame_terms(prob.joints_from_frames(prob.frames_of(x), L), prob.globals_of(x))
        s0 = prob.blocks["silhouette"].start
        assert np.abs(inside[:, s0:s0 + len(SIL_PAIRS)]).max() > 0.5  # the inside term active too
        assert prob.term_costs(x)["cover"] > 1.0
        assert prob.term_costs(x)["keypoints"] > 1.0 and prob.term_costs(x)["facing"] > 0.1
        assert prob.term_costs(x)["tpose"] > 1.0
    ne, cost = normal_equations(prob, x)
    got = ne.solve(0.1)
    assert cost == pytest.approx(0.5 * r0 @ r0, rel=1e-12)
    assert np.abs(got - want).max() < 2e-8 * np.abs(want).max()  # measured 1.3e-8 at most: the reference's differences


WEAK = Weights(sigma_acc=1e3, sigma_torso=1e3, sigma_hinge=1e3, sigma_floor=1e3, sigma_slide=1e3, sigma_pose=1e3,
               sigma_twist=1e3, sigma_pelvis=None)


def test_noise_free_take_is_recovered_exactly_with_its_focal_length(truth):
    """Exact 2D of 120 frames, the focal length given, priors negligible, from a start 2 cm off at the root and
    every bone turned by about 0.3 degrees: the image is fitted exactly and the median joint comes back to
    1.2 mm (measured); a few near-tangent limbs settle on their other depth side (max 39 mm), which the
    image alone cannot tell apart: the priors and the side search exist for that."""
    P, uv, centre, L = synthetic(truth, 120)
    prob, d = problem(truth, P, uv, centre, L, WEAK, focal_prior=(700.0, 1e-5))
    rng = np.random.default_rng(0)
    x = np.concatenate([globals_vector(700.0, d, False), pack_initial(P, prob.ref)])
    frames = x[prob.n_glob:].reshape(120, -1)
    frames[:, :3] += 0.02 * rng.standard_normal((120, 3))
    frames[:, 3:] += 0.005 * rng.standard_normal((120, frames.shape[1] - 3))
    x, cost, _, _ = levenberg_marquardt(prob, x, 40, tol=1e-14)
    f, _, _, _, got = prob.solution(x)
    assert abs(f / 700.0 - 1.0) < 1e-4
    assert cost < 0.09  # half sum of squares in units of 1 px, over 120 x 32 residuals: exact fit
    assert np.median(np.linalg.norm(got - P, axis=-1)) < 1.8e-3  # metres


def test_focal_length_from_a_noise_free_take(truth):
    """Exact 2D of the whole walk (200 frames, 0.9 m towards the camera), joints started at the truth, focal
    6 % off. Measured: 686 px for 700 (2.0 %): the take constrains the focal length only weakly (a head or
    wrist swinging to its other depth side absorbs the rest), far from the 0.1 % the issue asks for; this
    bound guards what is reached."""
    P, uv, centre, L = synthetic(truth, 200, start=10)
    prob, d = problem(truth, P, uv, centre, L, WEAK)
    x = np.concatenate([globals_vector(660.0, d, False), pack_initial(P, prob.ref)])
    x, _, _, _ = levenberg_marquardt(prob, x, 20, tol=1e-14)
    f = prob.solution(x)[0]
    assert abs(f / 700.0 - 1.0) < 0.03


def test_mirror_keeps_the_image_and_the_bones(truth):
    P, _, _, L = synthetic(truth, 20)
    frames = np.arange(5, 15)
    knee = 14  # right_knee: thigh mirrored, shin and ankle re-placed on their rays
    M = mirror(P, frames, (knee,), L)
    uv = lambda Q: Q[..., :2] / Q[..., 2:3]  # noqa: E731
    assert np.abs(uv(M) - uv(P)).max() < 1e-12
    assert not np.allclose(M[frames, knee], P[frames, knee])
    bones = np.linalg.norm(M[:, 1:] - M[:, PARENTS[1:]], axis=-1)
    assert np.abs(bones - L[1:]).max() < 0.05  # a child whose ray misses its sphere is put at the nearest point


def test_body_moved_in_depth_keeps_its_image_at_another_focal_length(truth):
    """The cross seeds' start: the sample's true body moved to 1.3x (0.75x) its depth is seen at 1.3x (0.75x)
    the focal length where it was: roots on their pixels exactly, joints within 0.15 (0.22) px median and
    3.7 (5.9) px at worst (perspective inside the body; measured), where scaling the whole scene moves them
    by up to 53 (44) px."""
    P, R, t = truth["joints3d_cam"], truth["R"], truth["t"]
    nf, d = R[:, 1], float(-R[:, 1] @ t)

    def image(Q, f):
        return f * Q[..., :2] / Q[..., 2:3]

    for scale, median_px, max_px in ((1.3, 0.15, 3.7), (0.75, 0.22, 5.9)):
        Q, dq = moved_in_depth(P, nf, d, scale)
        err = np.linalg.norm(image(Q, 700.0 * scale) - image(P, 700.0), axis=-1)
        assert err[:, 0].max() < 1e-6
        assert np.median(err) < 1.5 * median_px and err.max() < 1.5 * max_px
        assert np.allclose(np.linalg.norm(Q[:, 1:] - Q[:, PARENTS[1:]], axis=-1),
                           np.linalg.norm(P[:, 1:] - P[:, PARENTS[1:]], axis=-1))
        assert abs(np.mean((Q[:, 0] - P[:, 0]) @ nf + dq - d)) < 1e-9  # the roots' mean height kept


def test_planted_feet_come_from_the_image(truth):
    """Against the truth's own contacts (ankle under 1 cm/frame and near the floor): most frames agree."""
    P, uv, _, _ = synthetic(truth, 150)
    got = contacts_from_image(uv, np.ones(uv.shape[:2], bool), float(truth["fps"]))
    W = truth["joints3d_world"][60:210][:, [12, 15]]
    step = np.zeros((150, 2))
    step[1:] = np.linalg.norm(np.diff(W, axis=0), axis=-1)
    want = (step < 0.01) & (W[..., 1] < 0.12)
    assert (got == want).mean() > 0.8
    assert (got & ~want).mean() < 0.1  # few false contacts


def test_world_frame_puts_the_floor_at_y0(truth):
    P = truth["joints3d_cam"]
    R, t = truth["R"], truth["t"]
    B, origin = world_frame(P, R[:, 1], float(-R[:, 1] @ t))
    cam = Camera(K=truth["K"], R=B, t=origin, width=640, height=480)
    W = cam.to_world(P)
    assert np.abs(W[..., 1] - truth["joints3d_world"][..., 1]).max() < 1e-9  # same heights as the truth
    assert np.linalg.norm(W[0, 0, [0, 2]]) < 1e-9  # origin below the first hips


def test_solver_on_the_sample_tracks_given_the_focal_length(truth, tmp_path):
    """The node's solve on the bundled sample's 2D truth of the patches (the tracker's job done perfectly):
    with the true focal length the take's 3D comes out within the measured bounds."""
    with np.load(TRUTH, allow_pickle=False) as z:
        joints2d, patch2d = z["joints2d"], z["patch2d"]
    pts = joints2d.copy()
    pts[:, [i for i in range(16) if i != 3]] = patch2d  # every joint but the head has a patch
    tracked = np.ones(pts.shape[:2], bool)
    # sigma_px 1: these points have no tracking noise (the default, 2 px, is for real tracks: noise plus the patch
    # model's error; on these noise-free points it leans on the priors more than they deserve, 71.5 mm, camera 1.566 m)
    out = solve_take_arrays(pts[::2], tracked[::2], truth["bone_lengths"], 640, 480, float(truth["fps"]) / 2,
                            SolveTakeParams(focal_px=700.0, sigma_px=1.0))
    from tbha_graph.mocap.evaluate.measures import align_clip

    gt = truth["joints3d_world"][::2]
    aligned, _ = align_clip(out["joints"], gt, "rigid")
    seq = np.linalg.norm(aligned - gt, axis=-1).mean() * 1000
    assert seq < SAMPLE_SEQ_BOUND_MM
    # measured 1.447 m (2026-11-28); the floor's height comes from the planted ankles and is weakly fixed without a
    # silhouette: changes to the arithmetic alone have moved it between 1.434 and 1.52 m (rounds 25-27), so the bound
    # covers that spread rather than 1.5x of one measurement
    assert abs(out["report"]["camera_height_m"] - 1.45) < 0.062
    assert out["joints"][:, [12, 15], 1].min() > 0.08 - 0.003  # measured 0.5 mm below its resting height at worst


SAMPLE_SEQ_BOUND_MM = 72.0  # measured 47.1 mm (2026-11-28, sigma_px 1; 46.7-55.2 across arithmetic-only changes)


def test_long_take_in_windows_matches_the_whole_take_solve(truth):
    """A take longer than ``window_frames`` is solved in overlapping windows with the camera held: on the
    sample's patch truth (210 frames, focal given) in 3 windows of 80 frames ([0, 80), [60, 140), [120, 210))
    the error is about that of the whole-take solve (measured 75.2 vs 78.4 mm on 2026-11-29, 53.8 vs 52.7 when
    written: the windows start from every third frame's solve, so they end elsewhere in a flat valley, where any
    change to the model moves both by tens of mm, docs/solver-log.md round 31) and the cross-faded overlaps do not jerk
    (largest mean joint second difference there 14.2 mm per frame², the whole solve's largest anywhere 12.9,
    the truth's 15.6; windows pasted without the cross-fade jump by tens of mm)."""
    with np.load(TRUTH, allow_pickle=False) as z:
        pts, gt = z["joints2d"].copy(), z["joints3d_world"]
        pts[:, [i for i in range(16) if i != 3]] = z["patch2d"]
    tracked = np.ones(pts.shape[:2], bool)
    from tbha_graph.mocap.evaluate.measures import align_clip

    def solve(window):
        out = solve_take_arrays(pts, tracked, truth["bone_lengths"], 640, 480, float(truth["fps"]),
                                SolveTakeParams(focal_px=700.0, window_frames=window, window_overlap=20))
        aligned, _ = align_clip(out["joints"], gt, "rigid")
        acc = np.linalg.norm(np.diff(out["joints"], 2, axis=0), axis=-1).mean(axis=1) * 1000  # frame t + 1
        return out["report"], np.linalg.norm(aligned - gt, axis=-1).mean() * 1000, acc

    rep_whole, seq_whole, acc_whole = solve(1000)
    rep_win, seq_win, acc_win = solve(80)
    assert "windows" not in rep_whole and rep_win["windows"] == 3
    assert seq_win < seq_whole + 1.7
    overlaps = np.r_[59:80, 119:140]  # second differences centred on the overlaps' frames and their edges
    assert acc_win[overlaps].max() < 1.25 * acc_whole.max()


def test_twist_prior_measures_the_pelvis_turned_from_the_thorax(truth):
    """The twist residual is the difference of the pelvis's and the thorax's forward unit vectors over
    ``sigma_twist``: 0 for the true take's T-pose frame turned as a whole, 2 sin(a/2)/sigma for a pelvis turned
    by a against the thorax."""
    P, uv, centre, L = synthetic(truth, 3, start=0)
    prob, _ = problem(truth, P, uv, centre, L, Weights(sigma_twist=0.2))
    from tbha_graph.mocap.reconstruct.take_model import fronts
    th, pe = fronts(P)
    g = prob.globals_of(np.concatenate([globals_vector(700.0, 0.0, False), pack_initial(P, prob.ref)]))
    twist = prob.frame_terms(P, g)[:, prob.blocks["pose"]][:, 3:]
    assert np.allclose(twist, (pe - th) / 0.2)
    # turn the pelvis (hips' children below it) by 40 degrees about the spine
    Q = P.copy()
    up = P[:, 1] - P[:, 0]
    up /= np.linalg.norm(up, axis=1, keepdims=True)
    a = np.radians(40.0)
    from scipy.spatial.transform import Rotation
    for k in range(3):
        R = Rotation.from_rotvec(a * up[k]).as_matrix()
        for j in (10, 11, 12, 13, 14, 15):
            Q[k, j] = P[k, 0] + R @ (P[k, j] - P[k, 0])
    th2, pe2 = fronts(Q)
    got = np.linalg.norm(prob.frame_terms(Q, g)[:, prob.blocks["pose"]][:, 3:], axis=1)
    assert np.allclose(got, np.linalg.norm(pe2 - th2, axis=1) / 0.2)
    assert np.all(got > 2 * np.sin(a / 2) / 0.2 * 0.8)  # the turn shows (the spine is not quite vertical)


def test_confidence_power_without_confidence_is_a_warning(truth):
    """A weight on the tracks' confidence asked of tracks that carry none reaches the user as a warning (not
    only the log), and the solve still runs."""
    from tbha_graph.core.node import Context
    from tbha_graph.mocap.reconstruct.solve_take import solve_take as spec  # the node's NodeSpec

    P, uv, centre, L = synthetic(truth, 30, start=0)
    tracks = {"points": uv, "tracked": np.ones(uv.shape[:2], bool), "width": np.asarray(640), "height": np.asarray(480),
              "fps": np.asarray(float(truth["fps"]))}
    for power, warned in ((1.0, True), (0.0, False)):
        ctx = Context(spec.type, spec.params.model_validate({"focal_px": 700.0, "confidence_power": power}))
        out = spec.fn(ctx, tracks=dict(tracks), body=None)
        assert out["motion"]["joints"].shape == (30, 16, 3)
        assert any("carry no confidence" in w for w in ctx.warnings) == warned


def test_seat_on_outline_puts_the_body_back_at_its_depth(truth):
    """A body moved along its roots' rays to 0.8x and 1.3x its depth (same root pixel, another size) is put back at
    its depth by the silhouette's lowest row (the floor below the lower ankle seen 1 px below it), on the masked
    frames only."""
    from tbha_graph.mocap.reconstruct.take_model import SilhouetteField, seat_on_outline

    P, _, centre, _ = synthetic(truth, 20)
    R, t = truth["R"], truth["t"]
    nf, d = R[:, 1], float(-R[:, 1] @ t)
    A = P[:, [12, 15]]
    S = A - (A @ nf + d)[..., None] * nf
    bottom = (700.0 * S[..., 1] / S[..., 2] + centre[1]).max(axis=1) - 1.0  # lift_px -1: the floor point 1 px below the lowest row
    sil = SilhouetteField(np.zeros((20, 4, 4), np.uint8), 0.5, np.arange(20), bottom)
    moved = P * np.r_[np.full(10, 0.8), np.full(10, 1.3)][:, None, None]  # about the camera: roots on their rays
    moved = P + (moved[:, :1] - P[:, :1])  # the body moved unchanged
    mask = np.arange(20) % 5 != 0
    out = seat_on_outline(moved, 700.0, centre, nf, d, sil, mask)
    err = np.abs(out[..., 2] - P[..., 2]).max(axis=1)
    assert err[mask].max() < 0.011  # measured 7 mm at most (the scales tried are 0.46 % apart)
    assert np.array_equal(out[~mask], moved[~mask])


def test_turn_search_turns_back_a_body_turned_the_wrong_way(truth):
    """The turn search (take_solver.search_turns_lm): on 20 frames where no torso point is tracked, the sample's
    true body turned 180 degrees about the vertical through its root (its limbs then miss their tracks) is
    turned back (after the search's LM steps, within 10 cm, from 30 cm off), and frames outside the run and its
    margins stay as they were."""
    from tbha_graph.mocap.reconstruct.take_model import TORSO_JOINTS, torso_unseen
    from tbha_graph.mocap.reconstruct.take_solver import search_turns_lm, turned

    P, uv, centre, L = synthetic(truth, 40)
    prob, d = problem(truth, P, uv, centre, L, Weights(sigma_acc_torso=5.0))
    run = np.arange(12, 32)
    prob.d.weight[np.ix_(run, TORSO_JOINTS)] = 0.0
    prob.d.up = prob.floor(globals_vector(700.0, d, False))[0]
    wrong = turned(P, run, prob.d.up, np.full(len(run), np.pi))
    assert np.linalg.norm(wrong[run] - P[run], axis=-1).mean() > 0.3
    out, kept = search_turns_lm(prob, wrong, globals_vector(700.0, d, False), torso_unseen(prob.d.weight))
    assert kept >= 1
    assert np.linalg.norm(out[run] - P[run], axis=-1).mean() < 0.1
    assert np.array_equal(out[:8], wrong[:8]) and np.array_equal(out[36:], wrong[36:])


def test_facing_hint_turns_a_torso_seen_at_four_points(truth):
    """A detector's torso facing (``TakeData.facing``, :func:`.take_model.facing_residual`): 40 frames of the
    sample's exact 2D where only the shoulders, hips and head are tracked. Without a hint the solved thorax and
    pelvis face 12 and 8 degrees (median) off the truth (measured); with the truth's fronts as the hint 3.9 and
    2.3; with the hint turned 30 degrees about the vertical the torso follows it (4.0 and 4.2 from the hint)."""
    from scipy.spatial.transform import Rotation
    from threadpoolctl import threadpool_limits

    from tbha_graph.mocap.reconstruct.take_model import J, fronts

    P, uv, centre, L = synthetic(truth, 40)
    true_fronts = np.stack(fronts(P), axis=1)

    def solve(hint):
        prob, d = problem(truth, P, uv, centre, L, Weights(sigma_px=2.0), **({} if hint is None else {"facing": hint}))
        seen = [J[n] for n in ("left_shoulder", "right_shoulder", "left_hip", "right_hip", "head")]
        prob.d.weight[:] = 0.0
        prob.d.weight[:, seen] = 1.0
        x = np.concatenate([globals_vector(700.0, d, False), pack_initial(P, prob.ref)])
        with threadpool_limits(limits=1, user_api="blas"):  # as the node solves: small matrices (2 s; 55 s with threads on a busy machine)
            x = levenberg_marquardt(prob, x, 30)[0]
        return np.stack(fronts(prob.solution(x)[4]), axis=1)

    def median_deg(a, b):
        return np.median(np.degrees(np.arccos(np.clip(np.sum(a * b, axis=-1), -1, 1))), axis=0)

    assert (median_deg(solve(None), true_fronts) > [8.0, 5.5]).all()
    assert (median_deg(solve(true_fronts), true_fronts) < [6.0, 3.5]).all()
    turned = true_fronts @ Rotation.from_rotvec(np.radians(30.0) * truth["R"][:, 1]).as_matrix().T
    assert (median_deg(solve(turned), turned) < [6.0, 6.5]).all()


def test_detector_keypoints_place_limbs_where_no_patch_is_seen(truth):
    """A detector's keypoints (``TakeData.keypoints``, :func:`.take_model.keypoint_residual`): 40 frames of the
    sample's exact 2D, frames 12-31 with the head tracked alone (the actor's back to the camera) and their limb
    bones started ~17 degrees off. Keypoints 3 px off the true joints, their left and right swapped on frames
    16-27 (as a detector labels someone facing away): measured 28.3 mm over those frames against 42.1 without
    keypoints, and the same solution whether or not the labels come swapped (each pair taken either way)."""
    from threadpoolctl import threadpool_limits

    from tbha_graph.mocap.reconstruct.take_model import J, KP_PAIRS

    P, uv, centre, L = synthetic(truth, 40)
    run = np.arange(12, 32)
    kp = 700.0 * P[..., :2] / P[..., 2:3] + centre + np.random.default_rng(0).normal(scale=3.0, size=(40, 16, 2))
    swapped = kp.copy()
    swapped[16:28][:, KP_PAIRS.ravel()] = kp[16:28][:, KP_PAIRS[:, ::-1].ravel()]

    def solve(keypoints):
        hints = {} if keypoints is None else {"keypoints": keypoints, "kp_weight": np.full((40, 16), 0.9)}
        prob, d = problem(truth, P, uv, centre, L, Weights(sigma_px=2.0), **hints)
        prob.d.weight[run] = 0.0
        prob.d.weight[run, J["head"]] = 1.0
        x = np.concatenate([globals_vector(700.0, d, False), pack_initial(P, prob.ref)])
        frames = x[prob.n_glob:].reshape(40, -1)
        frames[run, 3:] += np.random.default_rng(2).normal(scale=0.3, size=(len(run), frames.shape[1] - 3))
        with threadpool_limits(limits=1, user_api="blas"):
            x = levenberg_marquardt(prob, x, 60)[0]
        return prob.solution(x)[4]

    def run_mm(got):
        return float(np.linalg.norm(got[run] - P[run], axis=-1).mean() * 1000.0)

    without, with_kp, with_swapped = solve(None), solve(kp), solve(swapped)
    assert run_mm(with_kp) < 36.0 and run_mm(with_kp) < 0.75 * run_mm(without), (run_mm(with_kp), run_mm(without))
    np.testing.assert_allclose(with_swapped, with_kp, atol=1e-9)


def test_report_holds_no_timing_so_the_metrics_key_is_stable(tmp_path, monkeypatch):
    """The solver's report feeds evaluate.metrics (``extra``), so a wall-clock time in it would give the metrics
    node a new cache key on every solve. A tiny pipeline (detector keypoints of CMU 131_02 -> a short solve ->
    metrics) run twice, each into a fresh cache (both solve), the second with a clock running twice as fast:
    the same report fingerprint and the same metrics key."""
    import textwrap
    import time

    from tbha_graph.core.cache import Cache
    from tbha_graph.core.runner import load_graph, run_graph

    pipeline = tmp_path / "p.yaml"
    pipeline.write_text(textwrap.dedent(f"""
        nodes:
          keypoints:
            type: io.openpose_keypoints
            params: {{path: {ROOT / "data" / "keypoints" / "cmu131_02" / "openpose"}, fps: 30.0, width: 640, height: 480}}
          reconstruct:
            type: reconstruct.solve_take
            inputs: {{tracks: keypoints.tracks}}
            params: {{focal_px: 700.0, points: joints, max_iterations: 2, calib_iterations: 2, calib_frames: 20,
                      side_search: false, cross_seed: false}}
          metrics:
            type: evaluate.metrics
            inputs: {{motion: reconstruct.motion, tracks: keypoints.tracks, camera: reconstruct.camera,
                      extra: reconstruct.report}}
        outputs: {{metrics.json: metrics.metrics}}
    """))
    first = run_graph(load_graph(pipeline), cache=Cache(tmp_path / "cache1")).results
    real = time.perf_counter
    monkeypatch.setattr(time, "perf_counter", lambda: 2.0 * real())
    second = run_graph(load_graph(pipeline), cache=Cache(tmp_path / "cache2")).results
    assert first["reconstruct"].status == second["reconstruct"].status == "ran"
    assert first["reconstruct"].fingerprints["report"] == second["reconstruct"].fingerprints["report"]
    assert first["metrics"].key == second["metrics"].key


def test_an_interrupted_run_stops_the_solver_between_iterations(truth):
    """Ctrl-C while the solver runs in a worker thread (tbha-run --jobs 2) sets the run's cancel event: the next
    Levenberg-Marquardt iteration raises Cancelled (a KeyboardInterrupt) instead of the solve running to its end."""
    import threading

    from tbha_graph.core.node import CANCEL, Cancelled

    P, uv, centre, L = synthetic(truth, 20)
    prob, d = problem(truth, P, uv, centre, L, WEAK, focal_prior=(700.0, 1e-5))
    x = np.concatenate([globals_vector(700.0, d, False), pack_initial(P, prob.ref)])
    event = threading.Event()
    token = CANCEL.set(event)
    try:
        levenberg_marquardt(prob, x, 2)  # not interrupted: runs
        event.set()
        with pytest.raises(Cancelled):
            levenberg_marquardt(prob, x, 2)
    finally:
        CANCEL.reset(token)
    levenberg_marquardt(prob, x, 2)  # outside a run (no cancel event): runs


def test_tpose_prior_holds_the_opening_arms_out_where_the_bones_are_a_few_percent_off(truth):
    """The take's opening T-pose (found in the image, :func:`tbha_graph.mocap.tpose.find_tpose`) holds the arms out
    and the limbs straight (``sigma_tpose``). The sample's exact patch centres, its first 90 frames, the true focal length, but
    arm bones 3-4 % off the truth's (as a body file's or the defaults are for a real actor): without the prior the
    arms swing into depth to fit the image with the wrong lengths."""
    from tbha_graph.mocap.evaluate.measures import align_clip

    with np.load(TRUTH, allow_pickle=False) as z:
        pts = z["joints2d"][:90].copy()
        pts[:, [i for i in range(16) if i != 3]] = z["patch2d"][:90]  # every joint but the head has a patch
    tracked = np.ones(pts.shape[:2], bool)
    L = truth["bone_lengths"].copy()
    for name, s in (("left_elbow", 1.04), ("left_wrist", 1.04), ("right_elbow", 0.97), ("right_wrist", 1.03), ("left_shoulder", 0.96)):
        L[JOINT_INDEX[name]] *= s
    gt = truth["joints3d_world"][:34]
    arms = [JOINT_INDEX[n] for n in ("left_elbow", "left_wrist", "right_elbow", "right_wrist")]

    def arm_error_deg(sigma_tpose):
        out = solve_take_arrays(pts, tracked, L, 640, 480, float(truth["fps"]),
                                SolveTakeParams(focal_px=700.0, sigma_px=1.0, sigma_tpose=sigma_tpose))
        A, _ = align_clip(out["joints"][:34], gt, "rigid")
        cos = np.sum(unit(A[:, arms] - A[:, PARENTS[arms]]) * unit(gt[:, arms] - gt[:, PARENTS[arms]]), axis=-1)
        return float(np.degrees(np.arccos(np.clip(cos, -1.0, 1.0))).mean()), out["report"].get("tpose_prior_frames")

    held, frames = arm_error_deg(0.1)
    assert frames == 33  # the sample's T-pose held: frames 0-32 (the tracker's looser run 0-33)
    free, none = arm_error_deg(None)
    assert none is None
    assert held < 4.7 < free  # measured 3.1 degrees with the prior, 5.7 without


def test_a_second_side_search_pass_redecides_what_the_first_left_behind(truth):
    """The depth-side search decides one group of bones after another; a second pass (``side_search_passes`` 2, off
    by default: on the 16 renders within the scatter and 55 % slower) re-decides each group where mirrors kept after
    it changed the body (a limb decided before the pelvis was mirrored). The sample's first 90 frames made exactly
    representable, the model's own points projected exactly, the true focal length: measured 26.9 mm mean joint
    error with one pass, 19.0 with two (exact 2D leaves the priors' bias and the search's misses, no noise). Without
    the lean search (round 21), which these figures predate: with it both passes give 28.7 mm. Without the pieces of
    runs cut at dips too (``side_split_cos``, round 28), which do much of what the second pass does: with them one pass
    measures 20.8 mm, two 23.6."""
    P, uv, _, L = synthetic(truth, 90, start=0)
    tracked = np.ones(uv.shape[:2], bool)

    def error_mm(passes):
        out = solve_take_arrays(uv, tracked, L, int(truth["width"]), int(truth["height"]), float(truth["fps"]),
                                SolveTakeParams(focal_px=700.0, side_search_passes=passes, lean_search=False,
                                                side_split_cos=None))
        return float(np.linalg.norm(out["camera_frame_joints"] - P, axis=-1).mean() * 1000.0)

    one, two = error_mm(1), error_mm(2)
    assert two < 0.85 * one and two < 28.5  # measured 19.0 vs 26.9 mm


def test_side_search_iterations_reach_the_depth_side_search(truth, monkeypatch):
    """side_search_iterations (pipelines/mediapipe.yaml: 2) is the number of LM steps the depth-side search gives each
    candidate: every call of the search in a solve gets it."""
    from tbha_graph.mocap.reconstruct import solve_take as st

    P, uv, _, L = synthetic(truth, 40, start=0)
    seen = []
    search = st.search_sides

    def recorded(*args, **kwargs):
        seen.append(kwargs.get("iterations"))
        return search(*args, **kwargs)

    monkeypatch.setattr(st, "search_sides", recorded)
    st.solve_take_arrays(uv, np.ones(uv.shape[:2], bool), L, int(truth["width"]), int(truth["height"]),
                         float(truth["fps"]), SolveTakeParams(focal_px=700.0, side_search_iterations=2, lean_search=False,
                                                              max_iterations=3))
    assert seen and set(seen) == {2}


def test_node_takes_the_torso_facing_from_its_keypoints_input_beside_a_suit(truth, monkeypatch):
    """default.yaml gives the suit's tracks (no facing) and MediaPipe's keypoints (with its torso facing, its left
    and right decided by the suit's patches): the node hands the keypoints' facing to the solver, and the tracks'
    own facing when they carry one (pipelines/mediapipe.yaml)."""
    from tbha_graph.core.testing import run_node
    from tbha_graph.mocap.reconstruct import solve_take as st
    from tbha_graph.mocap.reconstruct.take_model import fronts

    P, uv, centre, L = synthetic(truth, 12)
    suit = suit_tracks(truth, uv)
    facing = np.stack(fronts(P), axis=1)  # (12, 2, 3) camera axes
    keypoints = dict(suit, points=700.0 * P[..., :2] / P[..., 2:3] + centre, facing=facing)
    seen = solver_calls(monkeypatch, "hints")
    params = QUICK_NODE_PARAMS
    run_node(st.solve_take, params, tracks=suit, keypoints=keypoints)
    np.testing.assert_array_equal(seen[-1]["facing"], facing)
    run_node(st.solve_take, params, tracks=suit)  # neither carries one: no facing term
    assert seen[-1] is None or "facing" not in seen[-1]
    own = -facing  # the tracks' own facing wins over the keypoints'
    run_node(st.solve_take, params, tracks=dict(suit, facing=own), keypoints=keypoints)
    np.testing.assert_array_equal(seen[-1]["facing"], own)


def test_limbs_from_pose_takes_the_limbs_directions_of_a_3d_pose_in_any_frame(truth):
    """A detector's 3D pose, turned, shifted and scaled (MediaPipe's world landmarks are hips-centred, in their own
    axes and scale): on the chosen frames the limbs and head follow its bone directions at the solve's bone lengths,
    the torso and root stay, other frames and frames without a pose (NaN) are untouched."""
    from tbha_graph.mocap.reconstruct.solve_take import limbs_from_pose
    from tbha_graph.mocap.reconstruct.take_solver import SIDE_GROUPS, mirror
    from tbha_graph.mocap.skeleton import TORSO_JOINTS

    P, _, _, L = synthetic(truth, 30)
    wrong = P.copy()
    for g in SIDE_GROUPS[2:]:  # every limb and the head on its other depth side
        wrong = mirror(wrong, np.arange(30), g, L)
    assert np.abs(wrong - P).max() > 0.05
    c, s = np.cos(0.7), np.sin(0.7)
    pose = 0.8 * P @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).T + np.array([1.0, -2.0, 3.0])
    pose[25:] = np.nan  # the detector saw nothing there
    frames = np.zeros(30, bool)
    frames[5:28] = True
    out = limbs_from_pose(wrong, pose, frames, L)
    np.testing.assert_allclose(out[5:25], P[5:25], atol=1e-9)  # the truth's limbs back, at their lengths
    np.testing.assert_array_equal(out[:5], wrong[:5])
    np.testing.assert_array_equal(out[25:], wrong[25:])
    np.testing.assert_array_equal(out[:, TORSO_JOINTS], wrong[:, TORSO_JOINTS])


@pytest.mark.parametrize("frames, window, ratio", [(120, 300, 0.7), (150, 60, 0.8)], ids=["whole", "windows"])
def test_the_detectors_3d_pose_is_a_second_start_and_the_cheaper_solve_is_kept(truth, frames, window, ratio):
    """Where no torso patch is seen, the final pose solve runs again from the detector's 3D limbs and keeps whichever
    ends cheaper: a pose with the truth's limbs wins over a solve left on wrong depth sides (no side search, focal
    length from the take), a pose with nonsense limbs loses and leaves the answer exactly as without it; on a take
    solved whole and on one solved in windows (each window its own second start)."""
    from tbha_graph.mocap.reconstruct import solve_take as st
    from tbha_graph.mocap.skeleton import TORSO_JOINTS

    P, uv, _, L = synthetic(truth, frames, start=0)
    tracked = np.ones(uv.shape[:2], bool)
    tracked[60:100][:, TORSO_JOINTS] = False  # the torso's patches unseen, as with the actor's back turned
    p = st.SolveTakeParams(side_search=False, window_frames=window)

    def solve(pose3d=None):
        return st.solve_take_arrays(uv, tracked, L, int(truth["width"]), int(truth["height"]), 30.0, p, pose3d=pose3d)

    alone = solve()
    assert "pose3d_start_kept" not in alone["report"]
    assert alone["report"].get("windows", 1) == (1 if window >= frames else 4)
    good = solve(0.8 * P + 1.0)["report"]
    assert good["pose3d_start_frames"] >= 40  # summed over windows: a frame in two windows' overlap counts twice
    # measured: whole 156.1 against 275.0, windows 291.4 against 431.7
    assert good["pose3d_start_kept"] and good["pose_cost_pose3d"] < ratio * good["pose_cost"]
    bad = solve(np.random.default_rng(0).normal(0.0, 1.0, P.shape))
    assert not bad["report"]["pose3d_start_kept"] and bad["report"]["pose_cost_pose3d"] > bad["report"]["pose_cost"]
    np.testing.assert_array_equal(bad["joints"], alone["joints"])


def test_node_hands_the_detectors_3d_pose_to_the_solver_where_it_saw_someone(truth, monkeypatch):
    """default.yaml connects detect.motion (MediaPipe's world landmarks) to the node's pose3d input: the solver gets
    its joints, NaN on the frames where the detector tracked nothing; joints of another take's length are an error
    naming the input."""
    from tbha_graph.core.errors import NodeError
    from tbha_graph.core.testing import run_node
    from tbha_graph.mocap.reconstruct import solve_take as st
    from tbha_graph.mocap.skeleton import JOINT_NAMES

    P, uv, _, _ = synthetic(truth, 12)
    suit = suit_tracks(truth, uv)
    seen_by_detector = np.ones((12, 16), bool)
    seen_by_detector[4:6] = False
    motion = {"joints": P.copy(), "tracked": seen_by_detector, "fps": np.array(30.0), "joint_names": np.array(JOINT_NAMES)}
    got = solver_calls(monkeypatch, "pose3d")
    params = QUICK_NODE_PARAMS
    run_node(st.solve_take, params, tracks=suit, pose3d=motion)
    assert np.isnan(got[-1][4:6]).all()
    np.testing.assert_array_equal(np.delete(got[-1], [4, 5], axis=0), np.delete(P, [4, 5], axis=0))
    with pytest.raises(NodeError, match="pose3d"):
        run_node(st.solve_take, params, tracks=suit, pose3d=dict(motion, joints=P[:10], tracked=seen_by_detector[:10]))


def test_lean_search_stands_a_wrongly_leaning_upper_body_back_up(truth):
    """The lean search (take_solver.search_leans_lm): on 30 frames of the sample's exact 2D, the true body with its
    upper body leaned 16 degrees forwards about the hips (every bone its length; the arms and head then miss their
    points) is stood back up: measured 39.4 -> 10.4 mm mean joint error (its three LM steps leave the rest); the
    bones keep their lengths."""
    from tbha_graph.mocap.reconstruct.take_solver import leaned, search_leans_lm

    P, uv, centre, L = synthetic(truth, 30)
    prob, d = problem(truth, P, uv, centre, L, Weights(sigma_acc_torso=5.0))
    wrong = leaned(P, np.arange(30), np.full(30, np.radians(16.0)))
    lengths = lambda Q: np.linalg.norm(Q[:, 1:] - Q[:, PARENTS[1:]], axis=-1)  # noqa: E731
    np.testing.assert_allclose(lengths(wrong), lengths(P), atol=1e-12)
    before = np.linalg.norm(wrong - P, axis=-1).mean()
    out, kept = search_leans_lm(prob, wrong, globals_vector(700.0, d, False), windows=(30,))
    after = np.linalg.norm(out - P, axis=-1).mean()
    print(f"lean search: {1000 * before:.1f} -> {1000 * after:.1f} mm, {kept} kept")
    assert kept == 1 and before > 0.035 and after < 0.4 * before  # measured 39.4 -> 10.4 mm


def test_pelvis_depth_is_the_hips_behind_the_hip_joints_and_chest(truth):
    """``take_model.pelvis_depth`` (the optional pelvis prior's measure, ``sigma_pelvis``): 0 on the flat rest
    T-pose, the sample's CMU skeleton's hips 29 mm behind the plane of its hip joints and chest (measured -28.8,
    sd 5.9 over the take), and the sign follows the body, not the camera: the same take turned round reads the same."""
    from tbha_graph.mocap.reconstruct.solve_take import tpose_on_floor
    from tbha_graph.mocap.reconstruct.take_model import pelvis_depth

    assert abs(pelvis_depth(tpose_on_floor(truth["bone_lengths"], 0.08)[None])[0]) < 1e-12
    d = pelvis_depth(truth["joints3d_world"])
    assert -0.032 < d.mean() < -0.026 and d.std() < 0.009
    turned = truth["joints3d_world"] * np.array([-1.0, 1.0, -1.0])  # 180 degrees about the vertical
    assert np.allclose(pelvis_depth(turned), d)


def test_balance_residual_is_the_hips_across_the_floor_from_the_feet(truth):
    """``take_model.balance_residual`` (the optional balance prior, ``sigma_balance``): the sample's CMU walk keeps
    its hips within 82 mm of the segment between its ankles across the floor (measured: p95 76 mm), so at a band of
    0.15 m (pipelines/mediapipe.yaml's; the default 0.2) it costs nothing; the same walk with the upper body carried 0.4 m sideways over the feet
    (the solves had the hips up to 0.3-0.5 m off on the turning renders) costs on every frame, by the distance beyond
    the band (measured 0.24-0.41 m from the segment);
    height does not count (the hips raised 1 m change nothing) and neither does turning the take round."""
    from tbha_graph.mocap.reconstruct.take_model import TakeData, Weights, balance_residual

    P = truth["joints3d_world"]
    up = np.array([0.0, 1.0, 0.0])
    d = TakeData(np.zeros(P.shape[:2] + (2,)), np.ones(P.shape[:2]), np.ones(16), np.zeros(2), 30.0, 0.08,
                 np.zeros((P.shape[0], 2), bool), np.zeros(1), up=up)
    w = Weights(sigma_balance=0.05, balance_band=0.15)
    r, parts = balance_residual(P, d, w)
    assert not r.any()
    r0, _ = balance_residual(P, d, Weights(sigma_balance=0.05, balance_band=0.0))
    assert 0.070 < np.percentile(r0 * 0.05, 95) < 0.082 and (r0 * 0.05).max() < 0.083
    leaned = P.copy()
    leaned[:, :10] += np.array([0.4, 0.0, 0.0])  # hips, spine, head and arms; the walk is along z
    r1, parts1 = balance_residual(leaned, d, w)
    assert parts1["on"].all() and 0.22 < r1.min() * 0.05 + 0.15 and r1.max() * 0.05 + 0.15 < 0.42
    raised = P + np.where(np.arange(16) == 0, 1.0, 0.0)[:, None] * up
    assert np.allclose(balance_residual(raised, d, Weights(sigma_balance=0.05, balance_band=0.0))[0], r0)
    turned = P * np.array([-1.0, 1.0, -1.0])
    assert np.allclose(balance_residual(turned, d, Weights(sigma_balance=0.05, balance_band=0.0))[0], r0)
    assert not balance_residual(leaned, d, Weights())[0].any()  # off by default


def test_hip_extension_residual_is_a_thigh_swung_behind_the_body(truth):
    """``take_model.hip_extension_residual`` (the optional hip limit, ``sigma_hip``): the sample's CMU walk never
    swings a thigh behind the pelvis's frontal plane (the three CMU clips: a dot product with its front of -0.27 at
    most), so at
    ``hip_back_cos`` 0.6 it costs nothing; the right thigh swung 60 degrees behind (the knee where a knee raised in
    front of someone facing away would project) costs sin(60) - 0.6 over sigma on every frame, the left nothing;
    turning the whole take round changes nothing."""
    from scipy.spatial.transform import Rotation

    from tbha_graph.mocap.reconstruct.take_model import THIGHS, Weights, fronts, hip_extension_residual, unit
    from tbha_graph.mocap.reconstruct.take_solver import descendants

    P = truth["joints3d_world"]
    w = Weights(sigma_hip=0.05, hip_back_cos=0.6)
    pelvis = fronts(P)[1]
    away = np.ones(len(P), bool)  # only the head tracked: where the limit applies
    assert not hip_extension_residual(P, pelvis, w, away).any()
    dots = [np.sum(unit(P[:, k] - P[:, h]) * pelvis, axis=-1) for h, k in THIGHS]
    assert -0.02 < min(d.min() for d in dots) < 0.02  # measured -0.0005: a walk never swings a thigh behind
    hip, knee = THIGHS[1]
    swung = P.copy()
    side = unit(P[:, THIGHS[0][0]] - P[:, hip])  # the pelvis's left: the axis a thigh swings back about
    for t in range(len(P)):  # the right thigh straight down, then 60 degrees behind
        down = -unit(P[t, 1] - P[t, 0])
        back = Rotation.from_rotvec(np.radians(60.0) * side[t]).apply(down)  # about the left axis: backwards
        shift = P[t, hip] + back * np.linalg.norm(P[t, knee] - P[t, hip]) - P[t, knee]
        swung[t, [knee] + descendants(knee)] += shift
    r = hip_extension_residual(swung, fronts(swung)[1], w, away)
    assert not r[:, 0].any()
    expected = (0.6 - np.sin(np.radians(60.0))) / 0.05  # -5.32 (the swing's axis is the hip joints' line, not quite the front's normal)
    assert abs(np.median(r[:, 1]) - expected) < 0.07 and np.abs(r[:, 1] - expected).max() < 0.6  # measured 0.05 / 0.44
    turned = swung * np.array([-1.0, 1.0, -1.0])
    np.testing.assert_allclose(hip_extension_residual(turned, fronts(turned)[1], w, away), r)
    seen = np.arange(len(P)) % 3 == 0  # frames with patches tracked: never charged
    np.testing.assert_array_equal(hip_extension_residual(swung, fronts(swung)[1], w, ~seen), np.where(seen[:, None], 0.0, r))


def test_dip_pieces_cut_a_run_where_the_bone_comes_back_towards_the_image_plane(truth):
    """take_solver.dip_pieces: the sample's right forearm points out of the image plane on frames 81-209 of the truth
    in one run (|cos| to the viewing ray above 0.12 throughout), coming back to |cos| 0.28 at frame 101: the run is
    cut there, and nowhere when the dips must come nearer the plane than they do."""
    from tbha_graph.mocap.reconstruct.take_solver import bone_cos, dip_pieces, flip_segments

    P = truth["joints3d_cam"]
    j = JOINT_INDEX["right_wrist"]
    run = [s for s in flip_segments(P, j) if s[0] <= 101 <= s[-1]][0]
    pieces = dip_pieces(P, j, run, 0.6)
    assert [(int(p[0]), int(p[-1])) for p in pieces] == [(int(run[0]), 100), (101, int(run[-1]))]
    assert 0.2 < np.abs(bone_cos(P, j)[101]) < 0.3
    assert len(dip_pieces(P, j, run, 0.2)) == 1  # no dip that deep: the run whole


def test_side_search_mirrors_a_piece_of_a_run_cut_at_a_dip(truth):
    """A forearm put on the wrong depth side from frame 101 on (the sample's exact 2D, frames 85-124: its true run
    dips to |cos| 0.28 at frame 101 without crossing the image plane, so the wrong body's run is one): mirroring the
    whole run (the search without ``split_cos``) trades one wrong stretch for another, measured 17 of 40 frames left on
    the wrong side and the wrist 159 mm off on average; mirroring the piece after the dip puts every frame back on
    its side (measured 0, 21.7 mm)."""
    from tbha_graph.mocap.reconstruct.take_solver import bone_cos, search_sides_lm

    P, uv, centre, L = synthetic(truth, 40, start=85)
    prob, d = problem(truth, P, uv, centre, L, Weights())
    j = JOINT_INDEX["right_wrist"]
    wrong = mirror(P, np.arange(16, 40), (j,), L)
    g = globals_vector(700.0, d, False)
    side = np.sign(bone_cos(P, j))

    def searched(split_cos):
        out, kept = search_sides_lm(prob, wrong, g, split_cos=split_cos, groups=((j,),))
        return int(np.sum(np.sign(bone_cos(out, j)) != side)), 1000 * np.linalg.norm(out[:, j] - P[:, j], axis=-1).mean()

    assert int(np.sum(np.sign(bone_cos(wrong, j)) != side)) == 24
    whole_wrong, whole_mm = searched(None)
    split_wrong, split_mm = searched(0.6)
    print(f"whole runs: {whole_wrong} frames wrong, {whole_mm:.1f} mm; with pieces: {split_wrong}, {split_mm:.1f} mm")
    assert whole_wrong >= 12 and whole_mm > 100  # measured 17, 159 mm
    assert split_wrong == 0 and split_mm < 33  # measured 0, 21.7 mm


def test_disjoint_batches_never_put_overlapping_windows_together():
    """take_solver.disjoint_batches: the pieces' windows (2 frames of margin either side, so neighbours overlap) go in
    batches whose windows do not overlap, every window exactly once, the first batch taking all it can."""
    from tbha_graph.mocap.reconstruct.take_solver import disjoint_batches

    windows = [(0, 14, "a"), (10, 30, "b"), (26, 33, "c"), (31, 50, "d"), (60, 70, "e")]
    batches = disjoint_batches(windows)
    assert [[w[2] for w in b] for b in batches] == [["a", "c", "e"], ["b", "d"]]
    for b in batches:
        assert all(x[1] <= y[0] for x, y in zip(b, b[1:]))
    assert sorted(w for b in batches for w in b) == sorted(windows)
    assert disjoint_batches([]) == []


def test_frames_with_nothing_seen_are_a_warning_and_doubtful(truth):
    """An actor who leaves the picture: frames with no point tracked (and no silhouette or keypoint) are reported
    (``unseen_ranges``), a run of 10 or more is a warning that reaches the user, and the metrics flag those frames
    'not seen' in ``doubtful_ranges``; a shorter run is reported and flagged, not warned about."""
    from tbha_graph.core.node import Context
    from tbha_graph.mocap.evaluate.doubtful import doubtful_bits, doubtful_ranges
    from tbha_graph.mocap.reconstruct.solve_take import solve_take as spec

    P, uv, centre, L = synthetic(truth, 40, start=0)
    for last, warned in ((12, True), (6, False)):
        tracked = np.ones(uv.shape[:2], bool)
        tracked[-last:] = False  # out of the picture on the last frames
        tracked[10, :3] = False  # a frame with some points lost is still seen
        tracks = {"points": uv, "tracked": tracked, "width": np.asarray(640), "height": np.asarray(480),
                  "fps": np.asarray(float(truth["fps"]))}
        ctx = Context(spec.type, spec.params.model_validate(QUICK_NODE_PARAMS))
        out = spec.fn(ctx, tracks=dict(tracks), body=None)
        assert out["report"]["unseen_ranges"] == [[40 - last, 39]]
        assert any(f"nothing of the actor is seen on frames {40 - last}-39" in w for w in ctx.warnings) == warned
        bits = doubtful_bits(40, tracks, None, None, out["report"]["unseen_ranges"])
        assert [r for r in doubtful_ranges(bits) if r[2] == "not seen"] == [[40 - last, 39, "not seen"]]
