"""How often MediaPipe's left/right labels are still wrong after ``detect.mediapipe_pose`` made them consistent
(:func:`tbha_graph.mocap.detect.left_right.consistent_sides`), and what those frames cost the solve, on the
project's renders (``bench/mediapipe_renders.py``: the four scored by ``bench/mediapipe_compare.py`` and the
three turning ones the landmark offsets are fitted on). Needs the ``mediapipe`` extra.

A frame's arms (legs) count as wrong when the truth's 2D shoulders, elbows and wrists (hips, knees, ankles) are
nearer the landmarks with left and right exchanged. Per take one line of ``name=value``: ``frames``,
``arms_wrong``, ``legs_wrong`` (detected frames), and with ``--solve`` the MediaPipe pipeline's solve
(``pipelines/mediapipe.yaml``'s settings) on the labels as given and on the truth's labels (each wrong frame's
group exchanged): ``pa_mm`` / ``pa_true_labels_mm`` (12 limb joints, per-frame similarity alignment, as
``bench/mediapipe_compare.py``) and the model's total cost of each, ``cost`` / ``cost_true_labels``: the accuracy
that wrong labels cost, and whether the model itself would prefer the right ones.

With ``--suit``: the fifteen suit renders of ``bench/solver_sweep.py`` (the three solver renders and the twelve
turning takes) through ``pipelines/default.yaml``, where Pose runs only where no torso patch is seen and the
suit tracker's tracks are its ``suit`` input; per take ``frames``, and ``arms_wrong`` / ``legs_wrong`` with the
labels decided from the opening alone (``detect.sides_from_suit`` false) and with the suit's patches deciding
them where it sees them (``_suit``, the default), then the totals.

    python bench/mediapipe_sides.py [--takes sample,walk131_01_f500_low] [--solve]
    python bench/mediapipe_sides.py --suit
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mediapipe_renders import EVAL, FIT, render  # noqa: E402

from tbha_graph.core.runner import load_graph, run_graph  # noqa: E402
from tbha_graph.mocap.skeleton import JOINT_INDEX, JOINT_NAMES  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
LIMBS = [i for i, n in enumerate(JOINT_NAMES) if n.startswith(("left_", "right_"))]
GROUPS = {"arms": ("shoulder", "elbow", "wrist"), "legs": ("hip", "knee", "ankle")}


def wrong_frames(points: np.ndarray, truth2d: np.ndarray, parts: tuple[str, ...]) -> np.ndarray:
    """``(n,)`` bool: the labelled ``points`` ``(n, 16, 2)`` of these parts lie nearer the truth's 2D joints
    ``(n, 16, 2)`` with left and right exchanged."""
    keep = np.zeros(len(points))
    swap = np.zeros(len(points))
    for q in parts:
        a, b = JOINT_INDEX["left_" + q], JOINT_INDEX["right_" + q]
        keep += np.linalg.norm(points[:, a] - truth2d[:, a], axis=-1) + np.linalg.norm(points[:, b] - truth2d[:, b], axis=-1)
        swap += np.linalg.norm(points[:, a] - truth2d[:, b], axis=-1) + np.linalg.norm(points[:, b] - truth2d[:, a], axis=-1)
    return swap < keep


def with_groups_exchanged(tracks: dict, wrong: dict[str, np.ndarray]) -> dict:
    """The tracks with each group's left and right exchanged on its wrong frames (points, tracked, confidence) and
    the torso's fronts reversed where both groups are (the fronts turn round with the labels)."""
    out = dict(tracks)
    for key in ("points", "tracked", "confidence"):
        v = np.array(tracks[key], copy=True)
        for g, frames in wrong.items():
            for q in GROUPS[g]:
                a, b = JOINT_INDEX["left_" + q], JOINT_INDEX["right_" + q]
                v[frames, a], v[frames, b] = v[frames, b].copy(), v[frames, a].copy()
        out[key] = v
    if tracks.get("facing") is not None:
        facing = np.array(tracks["facing"], dtype=np.float64, copy=True)
        facing[wrong["arms"], 0] *= -1.0  # the thorax's front (shoulders)
        facing[wrong["legs"], 1] *= -1.0  # the pelvis's front (hips)
        out["facing"] = facing
    return out


def solve(graph, tracks: dict, lens, body, truth: np.ndarray) -> tuple[float, float]:
    """PA-MPJPE (mm, 12 limb joints) and total model cost of the pipeline's solve on ``tracks``."""
    from tbha_graph.mocap.body import body_lengths
    from tbha_graph.mocap.evaluate.measures import procrustes_per_frame
    from tbha_graph.mocap.reconstruct import solve_take as st

    params = graph.nodes["reconstruct"].params.model_copy(
        update={"point_offsets": np.asarray(tracks["point_offsets"], dtype=np.float64).tolist()})
    out = st.solve_take_arrays(np.asarray(tracks["points"], dtype=np.float64), np.asarray(tracks["tracked"], dtype=bool),
                               body_lengths(body), int(tracks["width"]), int(tracks["height"]), float(tracks["fps"]), params,
                               confidence=np.asarray(tracks["confidence"], dtype=np.float64), lens=lens,
                               hints=st.detector_hints(np.asarray(tracks["facing"], dtype=np.float64), None, None))
    J = out["joints"]
    pa = float(np.mean(np.linalg.norm(procrustes_per_frame(J[:, LIMBS], truth[:, LIMBS]) - truth[:, LIMBS], axis=-1)) * 1000)
    return pa, float(sum(out["report"]["cost"].values()))


def score(name: str, with_solve: bool) -> dict:
    folder = render(name)
    graph = load_graph(ROOT / "pipelines" / "mediapipe.yaml",
                       vars={"video": str(folder / "sample.mp4"), "ground_truth": str(folder / "ground_truth.npz")})
    run = run_graph(graph, outputs=["detect", "lens", "body"], cache=False)
    tracks = run.output("detect.tracks")
    gt = np.load(folder / "ground_truth.npz")
    points = np.asarray(tracks["points"], dtype=np.float64)
    detected = np.asarray(tracks["tracked"], dtype=bool).any(axis=1)
    wrong = {g: wrong_frames(points, gt["joints2d"], parts) & detected for g, parts in GROUPS.items()}
    out: dict = {"take": name, "frames": int(detected.sum()), "arms_wrong": int(wrong["arms"].sum()),
                 "legs_wrong": int(wrong["legs"].sum())}
    if with_solve:
        lens, body = run.output("lens.lens"), run.output("body.body")
        out["pa_mm"], out["cost"] = solve(graph, tracks, lens, body, gt["joints3d_world"])
        out["pa_true_labels_mm"], out["cost_true_labels"] = solve(graph, with_groups_exchanged(tracks, wrong), lens, body,
                                                                  gt["joints3d_world"])
    return out


def score_suit() -> None:
    """``--suit``: wrong frames on the suit renders without and with the suit's patches as the reference."""
    import solver_sweep
    from tbha_graph.core.cache import Cache
    from tbha_graph.mocap.bundles.tracks import read_tracks

    cache = Cache(Path.home() / ".cache" / "tbha-graph")
    total = {}
    for take in [t[0] for t in solver_sweep.SOLVER_TAKES] + solver_sweep.TURNING:
        name = take if isinstance(take, str) else f"{take[0]}_{take[1]}"
        line = {"take": name}
        for key, from_suit in (("", False), ("_suit", True)):
            graph, truth_ref = solver_sweep.take_graph(take, True, {"detect.sides_from_suit": from_suit})
            run = run_graph(graph, outputs=["detect", truth_ref.split(".")[0]], cache=cache)
            kt = read_tracks(run.output("detect.tracks"))
            truth2d = np.asarray(run.output(truth_ref)["joints2d"])[:kt.n_frames]
            detected = kt.tracked.any(axis=1)
            line["frames"] = int(detected.sum())
            for g, parts in GROUPS.items():
                line[f"{g}_wrong{key}"] = int((wrong_frames(kt.points, truth2d, parts) & detected).sum())
        for k, v in line.items():
            if k != "take":
                total[k] = total.get(k, 0) + v
        print(" ".join(f"{k}={v}" for k, v in line.items()), flush=True)
    print(" ".join(f"total_{k}={v}" for k, v in total.items()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--takes", default=",".join(list(EVAL) + list(FIT)), help="comma-separated names of "
                    "bench/mediapipe_renders.py's EVAL and FIT")
    ap.add_argument("--solve", action="store_true", help="also solve on the labels as given and on the truth's")
    ap.add_argument("--suit", action="store_true", help="the suit renders through default.yaml instead, without and with "
                    "the suit's patches deciding the labels")
    a = ap.parse_args()
    if a.suit:
        score_suit()
        return
    for name in a.takes.split(","):
        r = score(name, a.solve)
        print(" ".join(f"{k}={v:.1f}" if isinstance(v, float) else f"{k}={v}" for k, v in r.items()), flush=True)


if __name__ == "__main__":
    main()
