"""Where the whole-take solver's error comes from, on the sample and on ``bench/solver_accuracy.py``'s renders.

The capture's 3D error has three sources this bench separates (seq-MPJPE: one rigid alignment over the whole
take, no scale; the solver as the default pipeline runs it, tracks and silhouette from its nodes):

* ``<take>_from_truth_mm``: the solver started AT the truth (true joints, camera and floor, the true focal
  length held) and let converge: the nearest minimum of its own objective to the truth. What no better
  optimiser could improve: only a better model of the tracks (or better tracks) can.
* ``<take>_focal_given_mm``: the solver from its own start with the true focal length given. Its excess over
  the line above is the optimiser's (local minima: depth sides, heading through turns).
  ``<take>_own_cost_over_truth_minimum_pct``: that solution, polished as the line above was, costs this much
  more than the truth's minimum (> 0: the objective prefers the truth's minimum and the search missed it).
* ``<take>_focal_err_pct_{min,median,max}`` and ``<take>_estimated_mm_{min,median,max}``: the focal length
  estimated from the take alone (the default pipeline's fallback when the room's lines give none:
  ``calibrate.vanishing_points`` is not used here), each of five times with the starting focal lengths (``focal_grid``) scaled by
  0.9, 0.95, 1, 1.05, 1.1. A take that determines its focal length gives the same answer every time; the
  spread shows how much of an estimate is luck (``_at_default`` gives the unscaled run's figures).

``--perfect-tracks``: the tracker's points replaced by the render's true patch centres wherever the render shows
the patch (``patch2d``, ``patch_visible``; the head, which has no patch, keeps the tracker's point), to separate
what the tracks' small biases cost from what the objective and its search cost. Measured on the sample
(2026-11-27): with the tracker's points the solver's own solution is *cheaper* than the truth's minimum
(``own_cost_over_truth_minimum_pct`` -4.6: the objective prefers it), with perfect patch centres dearer (+3.5: the
search misses a better minimum), and both own solutions are about 54-56 mm off where the truth's minimum is 25 mm.
``--skip-focal-grid``: leave out the five solves with the focal length estimated.
``--terms``: where the two minima differ, as ``<take>_own_minus_truth_minimum_<term>=`` for each of the objective's
terms, ``..._reprojection_<joint>=`` and ``..._reprojection_frames_<a>_<b>=`` (30-frame blocks). On the sample
(2026-11-27, tracker's points) the own solution's reprojection is 23.7 lower (207.1 at the truth's minimum) and every
other term within 1.7: the pelvis patches (hips -8.9, chest -5.8, right hip -5.1), frames 60-89 -17.0; on frames
56-66 the right hip's and the hips' patch centres are 3-8 px apart in the render (15-17 px elsewhere), so each
blob is partly hidden by the other and its centre moves with what is hidden.

    python bench/solver_diagnosis.py [--takes sample,hop131_03_f1000_high] [--perfect-tracks] [--skip-focal-grid] [--terms]
"""
from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from solver_accuracy import TAKES  # noqa: E402
from solver_sweep import take_graph  # noqa: E402

from tbha_graph.core.cache import Cache  # noqa: E402
from tbha_graph.core.runner import run_graph  # noqa: E402
from tbha_graph.mocap.body import body_lengths  # noqa: E402
from tbha_graph.mocap.bundles.tracks import read_tracks  # noqa: E402
from tbha_graph.mocap.evaluate.measures import align_clip  # noqa: E402
from tbha_graph.mocap.reconstruct import solve_take as st  # noqa: E402
from tbha_graph.mocap.skeleton import JOINT_NAMES  # noqa: E402

GRID_SCALES = (0.9, 0.95, 1.0, 1.05, 1.1)


def capture_inputs(take: str) -> tuple[dict, dict | None, dict]:
    """Tracks, silhouette and ground truth of ``take`` ("sample" or a name of ``solver_accuracy.TAKES``), from
    the default pipeline's nodes (cached in the user cache, so a second run only solves)."""
    graph, truth_ref = take_graph(take)
    run = run_graph(graph, outputs=["track", "silhouette", truth_ref.split(".")[0]],
                    cache=Cache(Path.home() / ".cache" / "tbha-graph"))
    return run.output("track.tracks"), run.output("silhouette.silhouette"), run.output(truth_ref)


def seq_mpjpe_mm(joints: np.ndarray, truth_world: np.ndarray) -> float:
    """Mean joint error (mm) after one rigid alignment of the whole take (no scale)."""
    aligned, _ = align_clip(joints, truth_world, mode="rigid")
    return float(np.linalg.norm(aligned - truth_world, axis=-1).mean() * 1000.0)


def with_true_patches(tr, truth: dict):
    """``tr`` (:class:`Tracks2D`) with every patched joint's point at the render's true patch centre where the render
    shows the patch, tracked exactly there (the head keeps the tracker's point)."""
    from tbha_graph.mocap.skeleton import JOINT_INDEX, PATCHED_JOINTS

    pts, trk = tr.points.copy(), tr.tracked.copy()
    n = pts.shape[0]
    cols = [JOINT_INDEX[name] for name in PATCHED_JOINTS]
    pts[:, cols] = np.asarray(truth["patch2d"])[:n]
    trk[:, cols] = np.asarray(truth["patch_visible"], dtype=bool)[:n]
    return dataclasses.replace(tr, points=pts, tracked=trk)


def reprojection_by_joint(prob, x) -> np.ndarray:
    """Half squared reprojection residuals ``(n, 16)`` per frame and joint of a solved problem (the objective's
    ``reprojection`` term, :meth:`TakeProblem.frame_terms` rows 0..31: each joint's point u, v)."""
    P = prob.solution(x)[4]
    F = prob.frame_terms(P, prob.globals_of(x))
    return 0.5 * (F[:, :2 * len(JOINT_NAMES)] ** 2).reshape(len(P), len(JOINT_NAMES), 2).sum(axis=-1)


def diagnose(take: str, perfect_tracks: bool = False, focal_grid: bool = True, terms: bool = False) -> dict[str, float]:
    tracks, silhouette, truth = capture_inputs(take)
    tr = read_tracks(tracks)
    if perfect_tracks:
        tr = with_true_patches(tr, truth)
    n = tr.n_frames
    sil = None if silhouette is None else st.silhouette_field(silhouette, n)
    lengths = body_lengths(None)
    f_true = float(truth["K"][0, 0])
    T = np.asarray(truth["joints3d_world"])[:n]
    out: dict[str, float] = {}

    def solve(**params):
        return st.solve_take_arrays(tr.points, tr.tracked, lengths, tr.width, tr.height, float(tr.fps),
                                    st.SolveTakeParams(**params), silhouette=sil)

    # the objective's own minimum nearest the truth: start at it (camera frame), focal held, converge
    p = st.SolveTakeParams(focal_px=f_true)
    R, t = np.asarray(truth["R"]), np.asarray(truth["t"])
    P_true = np.asarray(truth["joints3d_cam"])[:n]
    floor = (R[:, 1], float(-R[:, 1] @ t))  # world y (up) in camera coordinates, camera-frame height offset
    centre = np.array([(tr.width - 1) / 2.0, (tr.height - 1) / 2.0])
    g0 = st.globals_vector(f_true, floor[1], False, p.free_lengths)
    contact = st.contacts_from_image(tr.points, tr.tracked, float(tr.fps))
    prob, x, c_truth, _, _ = st.solve_frames(tr.points, tr.tracked.astype(np.float64), lengths, centre, float(tr.fps), P_true,
                                             floor, g0, p, 50, (f_true, 1e-4), False, contact, tol=1e-6,
                                             silhouette=sil)
    P = prob.solution(x)[4]
    out["from_truth_mm"] = seq_mpjpe_mm((P - t) @ R, T)  # camera -> world: R^T (X - t), rows
    given = solve(focal_px=f_true)
    out["focal_given_mm"] = seq_mpjpe_mm(given["joints"], T)
    # is the truth's minimum cheaper than the solver's own? polish the own solution the same way and compare
    cam = given["camera"]
    own_floor = (cam.R[:, 1], float(-cam.R[:, 1] @ cam.t))
    prob_own, x_own, c_own, _, _ = st.solve_frames(tr.points, tr.tracked.astype(np.float64), lengths, centre, float(tr.fps),
                                        given["camera_frame_joints"], own_floor,
                                        st.globals_vector(f_true, own_floor[1], False, p.free_lengths), p, 50,
                                        (f_true, 1e-4), False, contact, tol=1e-6, silhouette=sil)
    out["own_cost_over_truth_minimum_pct"] = 100.0 * (c_own / c_truth - 1.0)
    if terms:  # which terms and which joints' reprojections make the difference (own minus the truth's minimum)
        t_truth, t_own = prob.term_costs(x), prob_own.term_costs(x_own)
        for k in t_truth:
            out[f"own_minus_truth_minimum_{k}"] = t_own[k] - t_truth[k]
        rep_truth, rep_own = reprojection_by_joint(prob, x), reprojection_by_joint(prob_own, x_own)
        for j, name in enumerate(JOINT_NAMES):
            out[f"own_minus_truth_minimum_reprojection_{name}"] = float(rep_own[:, j].sum() - rep_truth[:, j].sum())
        diff = (rep_own - rep_truth).sum(axis=1)
        for a in range(0, n, 30):
            out[f"own_minus_truth_minimum_reprojection_frames_{a}_{min(a + 30, n) - 1}"] = float(diff[a:a + 30].sum())
    if not focal_grid:
        return out
    grid = st.SolveTakeParams().focal_grid
    errs, mm = [], []
    for s in GRID_SCALES:
        res = solve(focal_grid=[g * s for g in grid])
        errs.append(100.0 * (res["report"]["focal_px"] / f_true - 1.0))
        mm.append(seq_mpjpe_mm(res["joints"], T))
    for key, v in (("focal_err_pct", errs), ("estimated_mm", mm)):
        out[f"{key}_min"], out[f"{key}_median"], out[f"{key}_max"] = float(np.min(v)), float(np.median(v)), float(np.max(v))
        out[f"{key}_at_default"] = float(v[GRID_SCALES.index(1.0)])
    out["focal_abs_err_pct_median"] = float(np.median(np.abs(errs)))
    return out


def main(argv: list[str] | None = None) -> None:
    names = ["sample"] + [t[0] for t in TAKES]
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.split("\n")[0])
    ap.add_argument("--takes", default=",".join(names), help="comma-separated, of: " + ", ".join(names))
    ap.add_argument("--perfect-tracks", action="store_true", help="the render's true patch centres in place of the tracker's points")
    ap.add_argument("--skip-focal-grid", action="store_true", help="leave out the five solves with the focal length estimated")
    ap.add_argument("--terms", action="store_true", help="the objective's terms, each joint's reprojection and each 30 "
                    "frames' reprojection at the solver's own solution minus at the truth's minimum")
    args = ap.parse_args(argv)
    for take in args.takes.split(","):
        if take not in names:
            ap.error(f"unknown take {take!r}; choose from {', '.join(names)}")
        for key, v in diagnose(take, args.perfect_tracks, not args.skip_focal_grid, args.terms).items():
            print(f"{take}_{key}={v:.1f}", flush=True)


if __name__ == "__main__":
    main()
