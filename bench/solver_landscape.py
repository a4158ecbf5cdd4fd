"""Is the solver's error the model's or the search's? On the sixteen renders of ``bench/solver_sweep.py``, with the
true camera given, the whole-take problem (the one the final pose solve minimises: the same tracks, silhouette,
keypoints, contacts and priors) is polished by Levenberg–Marquardt from two starts:

* the node's own answer (``solve_take_arrays`` with the true focal length, rigidly aligned onto the truth and put in
  the true camera's frame): ``<take>_node_basin_cost`` and ``_mm``;
* the truth itself: ``<take>_truth_basin_cost`` and ``_mm``: the minimum nearest the truth, whose error is the
  priors' and the tracks' bias alone.

A truth basin cheaper than the node's means the model prefers (nearly) the right answer and the search did not find
it; a dearer one, that the model itself prefers the wrong answer. Prints per take those four, ``<take>_node_mm``
(the node's answer as it is) and, over the takes, ``truth_cheaper_takes`` and the means over all sixteen and the
twelve turning takes (``all16_truth_basin_mm``: what a perfect search would reach with today's model).

With ``--terms``, also which of the model's terms make the difference: per take ``<take>_term_<name>=`` the truth's
basin's cost of that kind of residual minus the node's basin's (:meth:`.take_model.TakeProblem.term_costs`:
reprojection, torso, hinge, below_floor, contact, pose, silhouette, cover, upright, hang, keypoints, facing, tpose,
acceleration, slide, priors), and over the takes ``all16_term_<name>=`` / ``turning12_term_<name>=`` their means. A
positive figure is a term that prefers the node's answer to the one near the truth: where the model's own minimum
is off, these say which part of the model puts it there.

    python bench/solver_landscape.py [--takes sample,walk131_01_f500_low] [--iterations 60] [--terms]
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from solver_accuracy import TAKES as SOLVER_TAKES  # noqa: E402
from solver_sweep import TURNING, solver_inputs  # noqa: E402

from tbha_graph.core.cache import Cache  # noqa: E402
from tbha_graph.mocap.body import body_lengths  # noqa: E402
from tbha_graph.mocap.camera import Camera  # noqa: E402
from tbha_graph.mocap.evaluate.measures import align_clip  # noqa: E402
from tbha_graph.mocap.reconstruct import solve_take as st  # noqa: E402
from tbha_graph.mocap.reconstruct.take_model import pack_initial  # noqa: E402
from tbha_graph.mocap.reconstruct.take_solver import levenberg_marquardt  # noqa: E402


def take_name(take) -> str:
    return take if isinstance(take, str) else f"{take[0]}_{take[1]}"


def landscape(take, cache: Cache, iterations: int) -> dict:
    """The four figures of one take (module docstring) and the node's own error, mm."""
    tr, truth, sil, _lens, hints, pose3d = solver_inputs(take, cache)
    n = tr.n_frames
    K, R, t = (np.asarray(truth[k], dtype=np.float64) for k in ("K", "R", "t"))
    t = t.ravel()
    f = float(K[0, 0])
    p = st.SolveTakeParams(focal_px=f)
    lengths = body_lengths(None)
    gt = np.asarray(truth["joints3d_world"], dtype=np.float64)[:n]
    res = st.solve_take_arrays(tr.points, tr.tracked, lengths, tr.width, tr.height, float(tr.fps), p,
                               silhouette=sil, hints=hints, pose3d=pose3d)  # no confidence: suit tracks carry none
    aligned, _ = align_clip(res["joints"], gt, mode="rigid")
    out = {"node_mm": float(np.linalg.norm(aligned - gt, axis=-1).mean() * 1000.0)}
    camera = Camera(K=K, R=R, t=t, width=tr.width, height=tr.height)
    weight, prior_hints = st.take_inputs(tr.points, tr.tracked, float(tr.fps), p, None, hints)
    contact = st.contacts_from_image(tr.points, tr.tracked, float(tr.fps))
    centre = np.array([(tr.width - 1) / 2.0, (tr.height - 1) / 2.0])
    truth_cam = gt @ R.T + t
    for label, start in (("node", aligned @ R.T + t), ("truth", truth_cam)):
        prob, d = st.make_problem(tr.points, weight, lengths, centre, float(tr.fps), start, camera, p,
                                  focal_prior=(f, 1e-4), contact=contact, silhouette=sil, hints=prior_hints)
        x0 = np.concatenate([st.globals_vector(f, d, False, p.free_lengths), pack_initial(start, prob.ref)])
        x, cost, _, _ = levenberg_marquardt(prob, x0, iterations, 1e-9)
        joints = prob.solution(x)[4]
        out[f"{label}_basin_cost"] = float(cost)
        out[f"{label}_terms"] = prob.term_costs(x)
        out[f"{label}_basin_mm"] = float(np.linalg.norm(joints - truth_cam, axis=-1).mean() * 1000.0)
    return out


def term_differences(row: dict) -> dict[str, float]:
    """Per kind of residual, the truth's basin's cost minus the node's (positive: the term prefers the node's answer)."""
    node, truth = row["node_terms"], row["truth_terms"]
    return {k: truth[k] - node[k] for k in node}


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.split("\n")[0])
    every = ["sample"] + [t[0] for t in SOLVER_TAKES] + TURNING
    ap.add_argument("--takes", default=None, help="comma-separated take names (default: all sixteen)")
    ap.add_argument("--iterations", type=int, default=60, help="LM iterations of each polish")
    ap.add_argument("--terms", action="store_true", help="also each kind of residual's cost, truth's basin minus node's")
    a = ap.parse_args(argv)
    takes = every if a.takes is None else [t for t in every if take_name(t) in a.takes.split(",")]
    if not takes:
        ap.error(f"--takes: none of {a.takes!r} is one of {', '.join(take_name(t) for t in every)}")
    cache = Cache(Path.home() / ".cache" / "tbha-graph")
    rows = {}
    for take in takes:
        name = take_name(take)
        rows[name] = r = landscape(take, cache, a.iterations)
        for k, v in r.items():
            if not k.endswith("_terms"):
                print(f"{name}_{k}={v:.1f}", flush=True)
        if a.terms:
            for term, diff in term_differences(r).items():
                print(f"{name}_term_{term}={diff:+.1f}", flush=True)
    names = list(rows)
    cheaper = [k for k in names if rows[k]["truth_basin_cost"] < rows[k]["node_basin_cost"]]
    print(f"truth_cheaper_takes={len(cheaper)}/{len(names)}")
    turning = [k for k in names if k not in ("sample", *(t[0] for t in SOLVER_TAKES))]
    for label, group in (("all", names), ("turning", turning)):
        if group:
            for key in ("node_mm", "node_basin_mm", "truth_basin_mm"):
                print(f"{label}{len(group)}_{key}={np.mean([rows[k][key] for k in group]):.1f}")
            if a.terms:
                diffs = [term_differences(rows[k]) for k in group]
                for term in dict.fromkeys(t for d in diffs for t in d):  # every kind any take has (0 where absent)
                    print(f"{label}{len(group)}_term_{term}={np.mean([d.get(term, 0.0) for d in diffs]):+.1f}")


if __name__ == "__main__":
    main()
