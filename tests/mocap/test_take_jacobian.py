"""The solver's analytic frame Jacobian (take_jacobian) equals central finite differences of the residuals,
term by term, with every kind of residual active (bent-wrong hinges, ankles below the floor and planted ones
above it, twisted torsos, points with zero weight, robust reprojection beyond its scale, joints and bone
midpoints outside the actor's silhouette, some beyond the soft-L1 scale, the lower ankle above its support
band, the torso facing the camera on frames flagged away, the feet above the silhouette's lowest row, the
torso's fronts against a detector's, some mirrored, some missing, a detector's keypoints where the suit's points
are lost, some with left and right swapped, the limbs against the opening T-pose's on the frames flagged so)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from tbha_graph.mocap.reconstruct.solve_take import contacts_from_image, rest_pair_distances
from tbha_graph.mocap.reconstruct.take_jacobian import joint_jacobian, residual_jacobian
from tbha_graph.mocap.reconstruct.take_model import (DEFAULT_POINT_OFFSETS, HINGES, KP_PAIRS, N_COVER, N_FACING, N_FRAME_RES, N_HANG,
                                                     N_KP, N_SIL, N_TPOSE,
                                                     PER_FRAME, TORSO_PAIRS, SilhouetteField, TakeData, TakeProblem, Weights,
                                                     bone_directions, fronts, pack_initial, point_positions, unit)
from tbha_graph.mocap.segment.silhouette import distance_outside

TRUTH = Path(__file__).resolve().parents[2] / "data" / "sample" / "ground_truth.npz"
B = N_FRAME_RES + 4  # with the pelvis, balance and hip-extension priors' rows (this test turns them on)
KINDS = {"reprojection": slice(0, 32), "torso": slice(32, 32 + len(TORSO_PAIRS)),
         "hinge": slice(43, 43 + len(HINGES)), "below_floor": slice(47, 49), "contact": slice(49, 51),
         "head": slice(51, 54), "twist": slice(54, 57), "pelvis": slice(57, 58), "balance": slice(58, 59),
         "hip_extension": slice(59, 61), "silhouette": slice(B, B + N_SIL - 4),
         "support": slice(B + N_SIL - 4, B + N_SIL - 3), "away": slice(B + N_SIL - 3, B + N_SIL - 1),
         "bottom": slice(B + N_SIL - 1, B + N_SIL), "cover": slice(B + N_SIL, B + N_SIL + N_COVER),
         "upright": slice(B + N_SIL + N_COVER, B + N_SIL + N_COVER + 1),
         "hang": slice(B + N_SIL + N_COVER + 1, B + N_SIL + N_COVER + 1 + N_HANG),
         "keypoints": slice(B + N_SIL + N_COVER + 1 + N_HANG, B + N_SIL + N_COVER + 1 + N_HANG + N_KP),
         "facing": slice(B + N_SIL + N_COVER + 1 + N_HANG + N_KP, B + N_SIL + N_COVER + 1 + N_HANG + N_KP + N_FACING),
         "tpose": slice(B + N_SIL + N_COVER + 1 + N_HANG + N_KP + N_FACING,
                        B + N_SIL + N_COVER + 1 + N_HANG + N_KP + N_FACING + N_TPOSE)}


def thin_silhouettes(uv: np.ndarray, scale: float = 0.5, shape=(240, 320), ghost: float = 0.0, width: int = 1) -> SilhouetteField:
    """Distance-outside fields of stick figures (bones ``width`` px wide at ``scale``) through the 2D joints ``uv``
    ``(n, 16, 2)``: most of a turned limb's points fall outside them; ``ghost`` px (if not 0): a second right leg
    drawn that far right of the first (a limb the model lacks: the cover term's samples on it are uncovered)."""
    import cv2

    from tbha_graph.mocap.skeleton import PARENTS

    fields = []
    for q in np.round((uv + 0.5) * scale - 0.5).astype(int):
        m = np.zeros(shape, np.uint8)
        for j in range(1, 16):
            cv2.line(m, tuple(q[PARENTS[j]]), tuple(q[j]), 255, width)
        if ghost:
            g = q + np.array([int(round(ghost * scale)), 0])
            g[0] = q[0]  # joined to the body at the hips (the cover term follows the largest region's outline)
            for j in (13, 14, 15):
                cv2.line(m, tuple(g[PARENTS[j]]), tuple(g[j]), 255, width)
        fields.append(distance_outside(m))
    bottom = uv[:, [12, 15], 1].max(axis=1) + 25.0  # the lowest row 25 px below the lower ankle: the bottom term active
    bottom[::4] = np.nan  # and unknown on some frames
    return SilhouetteField(np.stack(fields), scale, np.arange(len(fields)), bottom)


def test_analytic_frame_jacobian_equals_central_differences():
    with np.load(TRUTH, allow_pickle=False) as z:
        P = z["joints3d_cam"][40:70].copy()
        R, t, fps = z["R"], z["t"], float(z["fps"])
    n = P.shape[0]
    L = np.r_[0.0, np.median(np.linalg.norm(P[:, 1:] - P[:, [0, 1, 2, 1, 4, 5, 1, 7, 8, 0, 10, 11, 0, 13, 14]], axis=-1), axis=0)]
    rng = np.random.default_rng(3)
    centre = np.array([319.5, 239.5])
    Q = point_positions(P, DEFAULT_POINT_OFFSETS)
    uv = 700.0 * Q[..., :2] / Q[..., 2:3] + centre + rng.normal(scale=3.0, size=Q.shape[:-1] + (2,))
    uv[::5, 6] += 40.0  # outliers: the soft-L1 part
    weight = np.ones(uv.shape[:2])
    weight[::3, 9] = 0.0  # untracked points
    weight[1::2, 4:] = 0.0  # limbs untracked on every other frame: the silhouette's term applies to their points
    weight[1::4, :3] = 0.0  # and the whole torso on every fourth: the cover term applies there
    contact = contacts_from_image(uv, weight > 0, fps)
    contact[::2] = True
    joints_uv = 700.0 * P[..., :2] / P[..., 2:3] + centre
    nf, d = R[:, 1], float(-R[:, 1] @ t)
    facing = unit(np.stack(fronts(P), axis=1) + np.random.default_rng(4).normal(scale=0.2, size=(n, 2, 3)))  # a detector's fronts, ~12 deg off
    facing[::5] *= -1.0  # mirrored on some frames: beyond the soft-L1 scale
    facing[3::7, 1] = 0.0  # and no pelvis front on others
    kp = joints_uv + np.random.default_rng(5).normal(scale=4.0, size=joints_uv.shape)  # a detector's keypoints, 4 px off
    kp[::3][:, KP_PAIRS.ravel()] = kp[::3][:, KP_PAIRS[:, ::-1].ravel()]  # left and right swapped on some frames
    kp[1::6, 9] += 60.0  # an outlier: the soft-L1 part
    kp_weight = np.random.default_rng(6).uniform(0.3, 1.0, size=kp.shape[:2])
    kp_weight[2::5, 12] = 0.0  # and none
    data = TakeData(uv, weight, L, centre, fps, 0.08, contact, rest_pair_distances(L, 0.08),
                    silhouette=thin_silhouettes(joints_uv, ghost=60.0), away=np.arange(n) % 2 == 0, up=-nf, facing=facing,
                    keypoints=kp, kp_weight=kp_weight, tpose=np.arange(n) < 12)
    prob = TakeProblem(data, bone_directions(P), nf, Weights(sigma_twist=0.2, sigma_pelvis=0.01, sigma_balance=0.05, balance_band=0.05, sigma_hip=0.05, hip_back_cos=0.1, support_band=-0.03, upright_sin=0.15,
                                                          sigma_hang=0.5),
                       DEFAULT_POINT_OFFSETS.copy(), free_offsets=False)
    g = np.array([np.log(700.0), 0.0, 0.0, d - 0.04])  # the floor 4 cm up: some ankles below it
    fr = pack_initial(P, prob.ref).reshape(n, PER_FRAME)
    fr[:, 3:] += rng.normal(scale=0.35, size=(n, PER_FRAME - 3))  # bones turned ~20 degrees: hinges bent wrongly
    h = 1e-6
    F = prob.n_frame_res
    assert F == B + N_SIL + N_COVER + 1 + N_HANG + N_KP + N_FACING + N_TPOSE
    num = np.empty((n, F, PER_FRAME))
    for i in range(PER_FRAME):
        fp, fm = fr.copy(), fr.copy()
        fp[:, i] += h
        fm[:, i] -= h
        num[:, :, i] = (prob.frame_terms(prob.joints_from_frames(fp), g) - prob.frame_terms(prob.joints_from_frames(fm), g)) / (2 * h)
    Pj = prob.joints_from_frames(fr)
    ana = residual_jacobian(prob, Pj, g).reshape(n, F, 48) @ joint_jacobian(prob, fr, L).reshape(n, 48, PER_FRAME)
    sil = prob.frame_terms(Pj, g)[:, KINDS["silhouette"]]
    assert (sil[1::2] > 0).mean() > 0.3 and (sil > 2.0 * prob.w.robust_scale).any()  # outside, some beyond the soft-L1 scale
    assert not sil[::2, [0, 1, 2]].any()  # tracked joints (hips, chest, neck): the reprojection places them, not the silhouette
    support = prob.frame_terms(Pj, g)[:, KINDS["support"]]
    assert 0.2 < (support > 0).mean() < 0.9  # the support band crossed in this take
    away = prob.frame_terms(Pj, g)[:, KINDS["away"]]
    assert (away[::2] > 0).mean() > 0.5 and not away[1::2].any()  # the sample faces the camera: active where flagged
    bottom = prob.frame_terms(Pj, g)[:, KINDS["bottom"]]
    assert (bottom > 0).mean() > 0.3 and not bottom[::4].any()  # measured 0.43
    upright = prob.frame_terms(Pj, g)[:, KINDS["upright"]]
    assert (upright[::2] > 0).mean() > 0.6 and not upright[1::2].any()  # measured 0.93; only where flagged away
    hang = prob.frame_terms(Pj, g)[:, KINDS["hang"]]
    assert (np.abs(hang[::2]).sum(axis=1) > 0).all() and not hang[1::2].any()  # only where flagged away
    kpr = prob.frame_terms(Pj, g)[:, KINDS["keypoints"]].reshape(n, 16, 2)
    assert not kpr[weight > 0].any() and (np.abs(kpr[weight == 0]) > 0).mean() > 0.9  # only where the suit's point is lost
    assert (np.abs(kpr) > prob.w.robust_scale).any()
    fac = prob.frame_terms(Pj, g)[:, KINDS["facing"]]
    assert not fac[3::7, 3:].any() and (np.abs(fac[::5]) > prob.w.robust_scale).any()  # missing hints cost nothing; mirrored ones beyond the scale
    hip = prob.frame_terms(Pj, g)[:, KINDS["hip_extension"]]
    assert 0.09 < (hip[::2] < 0).mean() < 0.2 and not hip[1::2].any()  # thighs behind the body on some frames flagged away (measured 0.13), none elsewhere
    tp = prob.frame_terms(Pj, g)[:, KINDS["tpose"]]
    assert (np.abs(tp[:12]).sum(axis=1) > 1.0).all() and not tp[12:].any()  # only on the T-pose's frames (a walk: far from it)
    cover = prob.frame_terms(Pj, g)[:, KINDS["cover"]]
    assert not cover[weight[:, 1] > 0].any()  # only where the torso is not seen
    assert (cover[1::4] > 0).mean() > 0.22 and (cover > prob.w.robust_scale).any()  # measured 0.33, some beyond the soft-L1 scale
    for kind, rows in KINDS.items():
        a, b = ana[:, rows], num[:, rows]
        assert np.abs(b).max() > 0.1, f"{kind}: not active in this test"
        # kinks (a hinge or floor term switching on) sit between the two central-difference samples of a few
        # entries; away from them the two agree to ~1e-7 of the largest entry (measured 3e-7 at most)
        close = np.abs(a - b) <= 1e-6 * np.abs(b).max()
        assert close.mean() > 0.995, f"{kind}: {close.mean():.4f} of entries agree"


def test_cover_term_finds_a_leg_swung_into_depth():
    """The outline of the true pose is covered by it (no cost); the same pose with its right leg swung into
    depth (inside the outline, where the inside term sees nothing) leaves the outline's leg uncovered."""
    from tbha_graph.mocap.reconstruct.take_model import cover_residuals, torso_unseen

    with np.load(TRUTH, allow_pickle=False) as z:
        P = z["joints3d_cam"][40:50].copy()
    centre = np.array([319.5, 239.5])
    sil = thin_silhouettes(700.0 * P[..., :2] / P[..., 2:3] + centre, width=9)
    L = np.r_[0.0, np.median(np.linalg.norm(P[:, 1:] - P[:, [0, 1, 2, 1, 4, 5, 1, 7, 8, 0, 10, 11, 0, 13, 14]], axis=-1), axis=0)]
    w = Weights()
    assert torso_unseen(np.zeros((3, 16))).all() and not torso_unseen(np.ones((3, 16))).any()
    r_true, _ = cover_residuals(P, 700.0, centre, sil, L, w)
    swung = P.copy()
    hip = P[:, 13]
    for j in (14, 15):  # knee and ankle turned 80 degrees about the hip's x axis, into depth
        v = P[:, j] - hip
        c, s = np.cos(np.radians(80)), np.sin(np.radians(80))
        swung[:, j] = hip + np.stack([v[:, 0], c * v[:, 1] - s * v[:, 2], s * v[:, 1] + c * v[:, 2]], axis=1)
    r_swung, _ = cover_residuals(swung, 700.0, centre, sil, L, w)
    assert np.abs(r_true).max() == 0.0
    assert (np.abs(r_swung) > 1.0).sum(axis=1).min() >= 4  # measured 5 samples per frame beyond 1 sigma
    assert not cover_residuals(swung, 700.0, centre, sil, L, w, mask=np.zeros(10))[0].any()  # masked frames: none


def test_cover_term_ignores_where_the_image_edge_cuts_the_outline():
    """An actor walking out of view: where the image's left edge cuts the silhouette the outline runs along the edge
    (no edge of the body there) and only a hand may be left in view (an outline a few pixels tall). The true pose
    covers its outline on those frames too: the edge's samples are left out and the tolerance keeps the height of
    the last whole frame (before, the true pose paid for the edge and for a 'body' 20 px tall)."""
    from tbha_graph.mocap.reconstruct.take_model import cover_residuals

    with np.load(TRUTH, allow_pickle=False) as z:
        P = z["joints3d_cam"][40:50].copy()
    centre = np.array([319.5, 239.5])
    f = 700.0
    x_right = (f * P[..., 0] / P[..., 2]).max(axis=1)  # each frame's rightmost joint, px from the centre
    # frames 0-4 whole in view; 5-9 moved left until only 40, 30, 20, 10, 5 px of the body are left in view
    left = np.array([0.0] * 5 + [40.0, 30.0, 20.0, 10.0, 5.0])
    shift_px = np.where(left > 0, -(x_right + centre[0]) + left, 0.0)
    P[..., 0] += (shift_px * P[:, 0, 2] / f)[:, None]
    uv = f * P[..., :2] / P[..., 2:3] + centre
    sil = thin_silhouettes(uv, width=9)
    q, height = sil.outline()
    L = np.r_[0.0, np.median(np.linalg.norm(P[:, 1:] - P[:, [0, 1, 2, 1, 4, 5, 1, 7, 8, 0, 10, 11, 0, 13, 14]], axis=-1), axis=0)]
    r, _ = cover_residuals(P, f, centre, sil, L, Weights())
    assert np.isfinite(q[:5]).all() and height[:5].min() > 150  # whole frames: every sample, the body's height
    assert np.isnan(q[5:, :, 0]).any(axis=1).all()  # cut frames: the edge's samples left out ...
    assert (np.nan_to_num(q[5:, :, 0], nan=99.0) > 1.0).all()  # ... and none left on the edge
    assert np.allclose(height[5:], height[4])  # the nearest whole frame's height
    assert np.abs(r).max() == 0.0  # the true pose covers its outline on every frame
