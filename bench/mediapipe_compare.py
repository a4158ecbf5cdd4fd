"""Ordinary video in, 3D out: ``pipelines/mediapipe.yaml`` (MediaPipe Pose -> whole-take solver) against
MediaPipe's own 3D (``pose_world_landmarks``), on the project's renders (``bench/mediapipe_renders.py``:
the bundled sample and three CMU clips with other cameras). Needs the ``mediapipe`` extra.

Per take one line of ``name=value``:

* ``ours_pa_mpjpe_mm``: the pipeline's joints (``joints3d.npz``, where the BVH puts them) against the truth;
* ``mediapipe_world_pa_mpjpe_mm``: MediaPipe's world landmarks as it gives them, mapped onto the same joints;
* both over the same frames (those MediaPipe detected) and the same 12 limb joints (shoulders, elbows,
  wrists, hips, knees, ankles), each frame aligned to the truth by its own similarity (Procrustes with
  scale): PA-MPJPE;
* ``ratio``: MediaPipe's over ours (the issue asks >= 2);
* ``pipeline_fps``: frames / wall time of the whole pipeline, every output written, nothing cached;
  ``detect_fps``: the detection node alone (decoding overlapped); ``solve_fps``: the solver node alone;
* ``focal_err_pct``: the solved focal length against the render's.

The solver's answer swings with small changes of its keypoints (the depth sides and turns it picks), so one run's
figure can be luck. ``--repeats K`` solves the take's keypoints K more times as the pipeline's ``reconstruct``
node does, the first as they are and the others with Gaussian noise of ``--jitter-px`` (0.5 px; seeds 1 .. K-1)
added, and prints the solver's own joints' PA-MPJPE over them (before the pipeline's smoothing, every frame):
``solver_pa_mpjpe_mm_mean`` / ``_min`` / ``_max`` and ``ratio_mean`` (MediaPipe's over that mean).

``--ceiling`` also solves the render's true 2D joints in MediaPipe's place (every joint tracked, confidence 1, no
landmark offsets; MediaPipe's torso facing kept) the way the pipeline solves MediaPipe's: ``truth2d_pa_mpjpe_mm``
(what the solve gives with perfect keypoints) and ``truth2d_noise3_pa_mpjpe_mm`` (with Gaussian noise of 3 px on
each, seed 0: MediaPipe's own error is 2.4-4.7 px median, ``keypoint_px_median``).

    python bench/mediapipe_compare.py [--takes sample,hop131_03_f1000_high] [--set NODE.PARAM=VALUE ...] [--repeats 5] [--ceiling]
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from mediapipe_renders import EVAL, render  # noqa: E402

from tbha_graph.core.runner import load_graph, run_graph  # noqa: E402
from tbha_graph.mocap.detect.mediapipe_pose import detect_landmarks, mediapipe_pose  # noqa: E402
from tbha_graph.mocap.evaluate.measures import procrustes_per_frame  # noqa: E402
from tbha_graph.mocap.io.video import probe_video  # noqa: E402
from tbha_graph.mocap.io.keypoint_layouts import MEDIAPIPE_POSE, joints16_from_landmarks  # noqa: E402
from tbha_graph.mocap.io.mediapipe_world import MEDIAPIPE_TO_WORLD  # noqa: E402
from tbha_graph.mocap.skeleton import JOINT_NAMES  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
LIMBS = [i for i, n in enumerate(JOINT_NAMES) if n.startswith(("left_", "right_"))]


class _Ctx:
    def progress(self, it, total=None, desc=""):
        return it


def pa_mpjpe_mm(pred: np.ndarray, truth: np.ndarray) -> float:
    """Mean over frames and the 12 limb joints of the per-frame similarity-aligned error, mm."""
    p, t = pred[:, LIMBS], truth[:, LIMBS]
    return float(np.mean(np.linalg.norm(procrustes_per_frame(p, t) - t, axis=-1)) * 1000.0)


def world_joints(world: np.ndarray) -> np.ndarray:
    """MediaPipe world landmarks ``(n, 33, 4)`` -> 16 joints ``(n, 16, 3)`` (project axes; PA ignores them)."""
    xyz = np.nan_to_num(world[..., :3]) @ MEDIAPIPE_TO_WORLD.T
    return joints16_from_landmarks(xyz, np.nan_to_num(world[..., 3]), MEDIAPIPE_POSE)[0]


def score(name: str, sets: dict, jobs: int | None = None, repeats: int = 0, jitter_px: float = 0.5,
          ceiling: bool = False) -> dict:
    folder = render(name)
    vars = {"video": str(folder / "sample.mp4"), "ground_truth": str(folder / "ground_truth.npz")}
    graph = load_graph(ROOT / "pipelines" / "mediapipe.yaml", sets=sets, vars=vars)
    with tempfile.TemporaryDirectory(prefix="tbha-mp-") as tmp:
        t0 = time.perf_counter()
        run = run_graph(graph, out_dir=Path(tmp) / "run", cache=False, jobs=jobs)
        wall = time.perf_counter() - t0
        manifest = json.loads((Path(tmp) / "run" / "manifest.json").read_text())
    nodes = manifest.get("nodes", {})

    def node_seconds(node_id: str) -> float:
        n = nodes.get(node_id, {}) if isinstance(nodes, dict) else next((x for x in nodes if x.get("id") == node_id), {})
        return float(n.get("wall_s", n.get("seconds", n.get("wall_time_s", float("nan")))))

    gt = np.load(folder / "ground_truth.npz")
    truth = gt["joints3d_world"]
    ours = np.asarray(run.output("joints.joints3d")["joints"], dtype=np.float64)
    # MediaPipe's own world landmarks as it gives them (its run again, same settings: deterministic on the CPU)
    raw, _ = detect_landmarks(_Ctx(), probe_video(folder / "sample.mp4"), mediapipe_pose.params.model_validate(
        {k.split(".", 1)[1]: v for k, v in sets.items() if k.startswith("detect.")}))
    world = np.asarray(raw.world, dtype=np.float64)
    n = min(len(truth), len(ours), len(world))
    detected = ~np.isnan(world[:n]).all(axis=(1, 2))
    frames = np.flatnonzero(detected)
    metrics = run.output("metrics.metrics")
    f_true = float(gt["K"][0, 0])
    out = {
        "take": name, "frames": int(n), "frames_detected": int(len(frames)),
        "ours_pa_mpjpe_mm": pa_mpjpe_mm(ours[frames], truth[frames]),
        "mediapipe_world_pa_mpjpe_mm": pa_mpjpe_mm(world_joints(world[frames]), truth[frames]),
        "pipeline_fps": n / wall,
        "detect_fps": n / node_seconds("detect"),
        "solve_fps": n / node_seconds("reconstruct"),
        "focal_err_pct": (float(metrics.get("focal_px", np.nan)) / f_true - 1.0) * 100.0,
    }
    out["ratio"] = out["mediapipe_world_pa_mpjpe_mm"] / out["ours_pa_mpjpe_mm"]
    if ceiling:
        from mediapipe_sides import solve

        tracks = run.output("detect.tracks")
        points = np.asarray(tracks["points"], dtype=np.float64)
        tracked = np.asarray(tracks["tracked"], dtype=bool)
        true2d = np.asarray(gt["joints2d"], dtype=np.float64)[: len(points)]
        out["keypoint_px_median"] = float(np.median(np.linalg.norm(points - true2d, axis=-1)[tracked]))
        perfect = {**tracks, "points": true2d, "tracked": np.ones_like(tracked), "confidence": np.ones(tracked.shape),
                   "point_offsets": np.zeros((len(JOINT_NAMES), 2))}
        for key, noise in (("truth2d_pa_mpjpe_mm", 0.0), ("truth2d_noise3_pa_mpjpe_mm", 3.0)):
            pts = true2d + np.random.default_rng(0).normal(0.0, noise, true2d.shape) if noise else true2d
            out[key] = solve(graph, {**perfect, "points": pts}, run.output("lens.lens"), run.output("body.body"), truth)[0]
    if repeats > 0:
        from mediapipe_sides import solve

        tracks = run.output("detect.tracks")
        pas = []
        for r in range(repeats):
            jittered = dict(tracks)
            if r > 0:
                points = np.asarray(tracks["points"], dtype=np.float64)
                jittered["points"] = points + np.random.default_rng(r).normal(0.0, jitter_px, points.shape)
            pas.append(solve(graph, jittered, run.output("lens.lens"), run.output("body.body"), truth)[0])
        out.update({"solver_pa_mpjpe_mm_mean": float(np.mean(pas)), "solver_pa_mpjpe_mm_min": min(pas),
                    "solver_pa_mpjpe_mm_max": max(pas), "ratio_mean": out["mediapipe_world_pa_mpjpe_mm"] / float(np.mean(pas))})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--takes", default=",".join(EVAL), help="comma-separated names of bench/mediapipe_renders.py's EVAL")
    ap.add_argument("--set", action="append", default=[], metavar="NODE.PARAM=VALUE", help="passed to the pipeline")
    ap.add_argument("--jobs", type=int, default=None, help="nodes run at once (tbha-run --jobs; default: the pipeline's 'jobs: 2', "
                    "MediaPipe and the room's lines at the same time)")
    ap.add_argument("--repeats", type=int, default=0, help="also solve the keypoints this many times (the first as they "
                    "are, the others jittered) and print the solver's PA-MPJPE over them")
    ap.add_argument("--ceiling", action="store_true", help="also solve the true 2D joints (and them with 3 px of noise) in "
                    "MediaPipe's place: what the solve gives with perfect keypoints")
    ap.add_argument("--jitter-px", type=float, default=0.5, help="sd of the noise added to the keypoints in repeats 2..K, pixels")
    a = ap.parse_args()
    if a.repeats < 0 or a.jitter_px < 0:
        ap.error("--repeats and --jitter-px must be >= 0")
    sets = {}
    for s in a.set:
        k, _, v = s.partition("=")
        sets[k] = yaml.safe_load(v)
    for name in a.takes.split(","):
        try:
            r = score(name, sets, a.jobs, a.repeats, a.jitter_px, a.ceiling)
        except Exception as e:  # noqa: BLE001 - one take failing is a result too; the others still run
            print(f"take={name} error={type(e).__name__}: {str(e).splitlines()[0]}", flush=True)
            continue
        print(" ".join(f"{k}={v:.1f}" if isinstance(v, float) else f"{k}={v}" for k, v in r.items()), flush=True)


if __name__ == "__main__":
    main()
