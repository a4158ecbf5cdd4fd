"""How sharply a take determines the focal length: the whole-take solver's cost profile over the focal length.

For each focal length ``s x`` the truth's (``s`` in ``--scales``), the pose is solved with that focal length
held, started at the true joints moved in depth so their image stays (``solve_take.moved_in_depth``), with
the priors the solver uses while it chooses the focal length. A take that determines its focal length has
a clear minimum at ``s = 1``; a flat profile leaves it to the priors and to luck.

``--points`` chooses the 2D the solver sees:

* ``tracks``: the default pipeline's tracks and silhouette (what a capture gets);
* ``patches``: the renderer's exact patch centres (visible ones; the head from the tracks), no silhouette;
* ``joints``: the exact projections of all 16 joint centres (solver ``points: joints``), no silhouette.

``--true-lengths`` gives the solver the truth's own bone lengths (the default body is the left/right
average, off by up to 7 mm per bone on the CMU subject).

Prints per take and scale ``<take>_cost_x<s>=`` (the whole-take cost), ``<take>_cost_pct_x<s>=`` (relative
to ``s = 1``) and ``<take>_mm_x<s>=`` (seq-MPJPE of that solve, rigid alignment in the camera frame, no scale).

    python bench/focal_profile.py [--takes sample] [--points joints] [--true-lengths] [--scales 0.8,1,1.25]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from solver_accuracy import TAKES  # noqa: E402
from solver_diagnosis import capture_inputs, seq_mpjpe_mm  # noqa: E402

from tbha_graph.mocap.body import body_lengths  # noqa: E402
from tbha_graph.mocap.bundles.tracks import read_tracks  # noqa: E402
from tbha_graph.mocap.reconstruct import solve_take as st  # noqa: E402
from tbha_graph.mocap.skeleton import JOINT_INDEX, PARENTS, PATCHED_JOINTS  # noqa: E402


def profile(take: str, points: str, true_lengths: bool, scales: list[float]) -> dict[str, float]:
    tracks, silhouette, truth = capture_inputs(take)
    tr = read_tracks(tracks)
    n = tr.n_frames
    K, R, t = (np.asarray(truth[k], dtype=np.float64) for k in ("K", "R", "t"))
    f_true = float(K[0, 0])
    P_true = np.asarray(truth["joints3d_cam"], dtype=np.float64)[:n]
    pts, seen, sil, kind = tr.points.copy(), tr.tracked.copy(), None, "suit"
    if points == "tracks":
        sil = None if silhouette is None else st.silhouette_field(silhouette, n)
    elif points == "patches":
        idx = [JOINT_INDEX[j] for j in PATCHED_JOINTS]
        pts[:, idx] = np.asarray(truth["patch2d"])[:n]
        seen[:, idx] = np.asarray(truth["patch_visible"], dtype=bool)[:n]
    else:
        pts = P_true[..., :2] / P_true[..., 2:3] * f_true + K[:2, 2]
        seen, kind = np.ones(pts.shape[:2], dtype=bool), "joints"
    lengths = body_lengths(None)
    if true_lengths:
        T = np.asarray(truth["joints3d_world"])[:n]
        lengths = np.r_[0.0, np.linalg.norm(T[:, 1:] - T[:, PARENTS[1:]], axis=-1).mean(axis=0)]
    p = st.SolveTakeParams(points=kind)
    q = p.model_copy(update={"sigma_twist": p.select_sigma_twist, "sigma_acc_torso": None})  # as while choosing
    centre = np.array([(tr.width - 1) / 2.0, (tr.height - 1) / 2.0])
    nf, d = R[:, 1], float(-R[:, 1] @ t)
    contact = st.contacts_from_image(pts, seen, float(tr.fps))
    out: dict[str, float] = {}
    for s in scales:
        P0, d0 = st.moved_in_depth(P_true, nf, d, s)
        g0 = st.globals_vector(f_true * s, d0, False, p.free_lengths)
        prob, x, cost, _, _ = st.solve_frames(pts, seen.astype(np.float64), lengths, centre, float(tr.fps), P0, (nf, d0),
                                              g0, q, 40, (f_true * s, 1e-5), False, contact, tol=1e-7,
                                              silhouette=sil)
        P = prob.solution(x)[4]
        out[f"cost_x{s:g}"] = cost
        out[f"mm_x{s:g}"] = seq_mpjpe_mm((P - t) @ R, np.asarray(truth["joints3d_world"])[:n])
    ref = out.get("cost_x1")
    if ref:
        for s in scales:
            out[f"cost_pct_x{s:g}"] = 100.0 * (out[f"cost_x{s:g}"] / ref - 1.0)
    return out


def main(argv: list[str] | None = None) -> None:
    names = ["sample"] + [t[0] for t in TAKES]
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.split("\n")[0])
    ap.add_argument("--takes", default="sample", help="comma-separated, of: " + ", ".join(names))
    ap.add_argument("--points", choices=("tracks", "patches", "joints"), default="tracks")
    ap.add_argument("--true-lengths", action="store_true", help="the truth's own bone lengths")
    ap.add_argument("--scales", default="0.8,0.9,1,1.1,1.25", help="focal lengths as multiples of the truth's")
    args = ap.parse_args(argv)
    scales = [float(s) for s in args.scales.split(",")]
    for take in args.takes.split(","):
        if take not in names:
            ap.error(f"unknown take {take!r}; choose from {', '.join(names)}")
        for key, v in profile(take, args.points, args.true_lengths, scales).items():
            print(f"{take}_{key}={v:.1f}", flush=True)


if __name__ == "__main__":
    main()
