"""The solver's analytic frame Jacobian (take_jacobian) equals central finite differences of the residuals,
term by term, with every kind of residual active (bent-wrong hinges, ankles below the floor and planted ones
above it, twisted torsos, points with zero weight, robust reprojection beyond its scale)."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from tbha_graph.mocap.reconstruct.solve_take import contacts_from_image, rest_pair_distances
from tbha_graph.mocap.reconstruct.take_jacobian import joint_jacobian, residual_jacobian
from tbha_graph.mocap.reconstruct.take_model import (DEFAULT_POINT_OFFSETS, HINGES, N_FRAME_RES, PER_FRAME,
                                                     TORSO_PAIRS, TakeData, TakeProblem, Weights, bone_directions,
                                                     pack_initial, point_positions)

TRUTH = Path(__file__).resolve().parents[2] / "data" / "sample" / "ground_truth.npz"
KINDS = {"reprojection": slice(0, 32), "torso": slice(32, 32 + len(TORSO_PAIRS)),
         "hinge": slice(43, 43 + len(HINGES)), "below_floor": slice(47, 49), "contact": slice(49, 51),
         "head": slice(51, 54), "twist": slice(54, 57)}


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
    contact = contacts_from_image(uv, weight > 0, fps)
    contact[::2] = True
    data = TakeData(uv, weight, L, centre, fps, 0.08, contact, rest_pair_distances(L, 0.08))
    nf, d = R[:, 1], float(-R[:, 1] @ t)
    prob = TakeProblem(data, bone_directions(P), nf, Weights(sigma_twist=0.2), DEFAULT_POINT_OFFSETS.copy(), free_offsets=False)
    g = np.array([np.log(700.0), 0.0, 0.0, d - 0.04])  # the floor 4 cm up: some ankles below it
    fr = pack_initial(P, prob.ref).reshape(n, PER_FRAME)
    fr[:, 3:] += rng.normal(scale=0.35, size=(n, PER_FRAME - 3))  # bones turned ~20 degrees: hinges bent wrongly
    h = 1e-6
    num = np.empty((n, N_FRAME_RES, PER_FRAME))
    for i in range(PER_FRAME):
        fp, fm = fr.copy(), fr.copy()
        fp[:, i] += h
        fm[:, i] -= h
        num[:, :, i] = (prob.frame_terms(prob.joints_from_frames(fp), g) - prob.frame_terms(prob.joints_from_frames(fm), g)) / (2 * h)
    Pj = prob.joints_from_frames(fr)
    ana = residual_jacobian(prob, Pj, g).reshape(n, N_FRAME_RES, 48) @ joint_jacobian(prob, fr, L).reshape(n, 48, PER_FRAME)
    for kind, rows in KINDS.items():
        a, b = ana[:, rows], num[:, rows]
        assert np.abs(b).max() > 0.1, f"{kind}: not active in this test"
        # kinks (a hinge or floor term switching on) sit between the two central-difference samples of a few
        # entries; away from them the two agree to ~1e-7 of the largest entry (measured 3e-7 at most)
        close = np.abs(a - b) <= 1e-6 * np.abs(b).max()
        assert close.mean() > 0.995, f"{kind}: {close.mean():.4f} of entries agree"
