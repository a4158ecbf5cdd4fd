"""The whole-take solver alone on sixteen renders, to compare its settings on more than one take.

Any single take's seq-MPJPE swings by 30-50 mm with any change to the solver (near-tied depth-side and turn
choices flip), so a setting is judged here by the mean over sixteen takes: the bundled sample, the three
renders of ``bench/solver_accuracy.py`` and the twelve turning takes of ``bench/labelling.py`` (six and
the three held out, both suits). Each take's tracks, silhouette, room lines and truth come from the
default pipeline's nodes (cached in the user cache: the first run renders and tracks, about 10 minutes;
later runs only solve, about 2 minutes per setting); the solve is ``solve_take_arrays`` as the node runs it.

Prints ``name=value`` lines: ``<take>_mpjpe_mm`` (one rigid alignment over the whole take, no scale), then
``solver4_mean_mm`` (the sample and the three solver renders), ``turning12_mean_mm``, ``held6_mean_mm`` (the six
held-out turning takes) and ``all16_mean_mm``; then three more views of the same solves, each as a mean over the
sixteen takes: ``all16_rootrel_mean_mm`` (the joints relative to the hips after the same alignment: the pose
without the trajectory), ``all16_tpose_mean_mm`` (the opening T-pose's frames, as the solver finds them, aligned on
their own: where the bone lengths and the arms' depth show) and ``all16_ms_per_frame`` (the solve's wall time).

Even the mean over sixteen takes moves by ~15 mm with a change that should do nothing (``sigma_px`` 2.0 -> 1.98 or
2.02: all16 112.7 -> 127.6 / 126.4 mm on 2026-11-26). ``--repeats K`` solves every take K times, the first on its
tracks as they are and the others on the tracks plus Gaussian noise of ``--jitter-px`` (0.05 px: a tenth of the
tracker's own error; seeds 1 .. K-1, the same for every setting), and prints the means over the repeats, each take's
``_min``/``_max`` and each mean's ``_min``/``_max`` over the repeats (each repeat's own mean over the takes): a
setting is better than another when its mean is, by more than their spreads. The means of three repeats move too: a
change of the arithmetic alone (round 27: a residual row that is always zero removed) moved all16 by +2.5 mm on
seeds 0-2 and 0.0 on ``--seed-offset 10``, single takes by up to 21 mm, so a change is judged on both sets. Each take's ``_focal_err_pct`` (the
solver's focal length against the truth's, mean over the repeats) and ``all16_focal_abs_err_pct`` (mean and max of
its magnitude over every take and repeat) say what the camera did.

    python bench/solver_sweep.py                                  # the default settings, the room's focal length
    python bench/solver_sweep.py --set sigma_px=1.0               # a SolveTakeParams field changed
    python bench/solver_sweep.py --focal given                    # the true focal length given (focal_px)
    python bench/solver_sweep.py --focal take                     # no room lines: the focal length from the take
    python bench/solver_sweep.py --repeats 3                      # each take 3 times (twice with 0.05 px noise)
    python bench/solver_sweep.py --no-keypoints                   # without MediaPipe's keypoints (default.yaml's detect off)
    python bench/solver_sweep.py --no-pose3d                      # without MediaPipe's 3D limbs as a second start
    python bench/solver_sweep.py --node-set detect.threshold=0.3  # another node's param (here MediaPipe's visibility threshold)
    python bench/solver_sweep.py --repeats 3 --set sigma_acc=20 --against base.txt   # against an earlier run's output
    python bench/solver_sweep.py --repeats 3 --seed-offset 10     # three fresh noisy draws (seeds 10-12) of each take
    python bench/solver_sweep.py --repeats 3 --consistent-patches left_ankle,right_ankle   # an oracle: see below

``--against FILE`` (an earlier run's output, e.g. the defaults' saved with ``> base.txt``) also prints, as each take
ends, ``<take>_delta_mm`` (this run's mean minus that run's) and ``worse_so_far=K/N`` (takes worse so far), and at
the end ``<mean>_delta_mm`` and ``worse_takes=K/N``: a change that is worse on most of the first takes can be
stopped there (Ctrl-C) instead of after all sixteen.

``--consistent-patches JOINTS`` (comma-separated patched joints, or ``all``) is an oracle for what a perfect patch
model would gain: each of those joints' tracked points is moved by (where the solver's patch model,
``take_model.point_positions`` with the default offsets, puts the patch on the render's TRUE joints, projected with
the true camera) minus (where the renderer put it, the truth's ``patch2d``), so the tracks keep their own noise but
agree with the model. Round 21: the renderer slides the ankles' patch 1.5-2.6 cm up the shin when the knee is ahead
of the ankle (the model's constant is their median); made consistent, all16 93.7 -> 91.1 / 89.2 -> 90.6 (fresh),
solver4 60.6 -> 55.3 / 59.8 -> 56.3, the T-pose 19.4 -> 14.1 / 16.8 -> 13.3 mm.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

import labelling  # noqa: E402  (the turning takes, one definition)
from solver_accuracy import TAKES as SOLVER_TAKES, render_graph  # noqa: E402

from tbha_graph.core.cache import Cache  # noqa: E402
from tbha_graph.core.runner import load_graph, run_graph  # noqa: E402
from tbha_graph.mocap.body import body_lengths  # noqa: E402
from tbha_graph.mocap.bundles.tracks import read_tracks  # noqa: E402
from tbha_graph.mocap.evaluate.measures import align_clip  # noqa: E402
from tbha_graph.mocap.reconstruct import solve_take as st  # noqa: E402
from tbha_graph.mocap.reconstruct.take_model import DEFAULT_POINT_OFFSETS, point_positions  # noqa: E402
from tbha_graph.mocap.skeleton import JOINT_INDEX, PATCHED_JOINTS  # noqa: E402
from tbha_graph.mocap.tpose import find_tpose  # noqa: E402

TURNING = [(take, suit) for take in list(labelling.TAKES) + list(labelling.HELD_OUT) for suit in labelling.SUITS]


def take_graph(take, keypoints: bool = True, node_sets: dict | None = None):
    """The default pipeline's graph for ``take`` (``"sample"``, a solver render's name, or a ``(take, suit)``
    turning take) and the output holding its ground truth; without ``keypoints``, its node ``detect`` (MediaPipe's
    keypoints where no torso patch is seen) off; ``node_sets`` ``{"node.param": value}`` as ``--set``."""
    if take == "sample":
        return load_graph(ROOT / "pipelines" / "default.yaml",
                          sets={**({} if keypoints else {"detect.frames": "none"}), **(node_sets or {})}), "truth.truth"
    decl = labelling.render_decl(keypoints, node_sets)
    if isinstance(take, str):
        return render_graph(next(t for t in SOLVER_TAKES if t[0] == take), decl=decl), "render.ground_truth"
    sets, vars = labelling.take_config(*take)
    return load_graph(ROOT / "pipelines" / "evaluate_render.yaml", sets=sets, vars=vars, decl=decl), "render.ground_truth"


def solver_inputs(take, cache: Cache, keypoints: bool = True, node_sets: dict | None = None):
    """What the default pipeline hands its ``reconstruct`` node on ``take`` (:func:`take_graph`; its nodes from
    ``cache``, run where missing): ``(tracks, truth, silhouette field, lens, hints)`` — the suit's tracks
    (``read_tracks``), the render's ground truth (``GROUND_TRUTH`` port value), the actor's silhouette
    (:func:`.solve_take.silhouette_field`), the room's ``LensEstimate`` and the detector's hints
    (:func:`.solve_take.detector_hints`: MediaPipe's torso facing and keypoints, as the node builds them)."""
    graph, truth_ref = take_graph(take, keypoints, node_sets)
    run = run_graph(graph, outputs=["track", "silhouette", "lens", "detect", truth_ref.split(".")[0]],
                    cache=cache)
    tr = read_tracks(run.output("track.tracks"))
    sil = st.silhouette_field(run.output("silhouette.silhouette"), tr.n_frames)
    detected = run.output("detect.tracks")
    hints = st.detector_hints(st.torso_facing_hint(run.output("track.tracks"), detected),
                              *st.detector_keypoints(detected, tr))
    pose3d = st.detector_pose3d(run.output("detect.motion"), tr.n_frames)
    return tr, run.output(truth_ref), sil, run.output("lens.lens"), hints, pose3d


def consistent_points(points: np.ndarray, truth: dict, joints: tuple[str, ...]) -> np.ndarray:
    """``points`` ``(n, 16, 2)`` px with each of ``joints``' (patched joints) moved by where the solver's patch model
    puts its patch on the truth's joints (``joints3d_cam``, camera ``K``) minus where the render put it (``patch2d``):
    the tracks as consistent with the model as the truth allows, their own noise kept (``--consistent-patches``)."""
    n = points.shape[0]
    model = point_positions(np.asarray(truth["joints3d_cam"], dtype=np.float64)[:n], DEFAULT_POINT_OFFSETS)
    model = model @ np.asarray(truth["K"], dtype=np.float64).T
    model = model[..., :2] / model[..., 2:3]
    rendered = np.asarray(truth["patch2d"], dtype=np.float64)[:n]
    out = np.array(points, dtype=np.float64)
    for name in joints:
        j, k = JOINT_INDEX[name], PATCHED_JOINTS.index(name)
        out[:, j] += model[:, j] - rendered[:, k]
    return out


def solve(take, params: dict, focal: str, cache: Cache, repeats: int = 1, jitter_px: float = 0.05,
          keypoints: bool = True, node_sets: dict | None = None, use_pose3d: bool = True, seed_offset: int = 0,
          consistent: tuple[str, ...] = ()) -> list[dict]:
    """Scores of the solver on ``take`` with ``SolveTakeParams(**params)``, one dict per repeat: ``seq`` (seq-MPJPE,
    mm), ``rootrel`` (root-relative after the same alignment, mm), ``tpose`` (the T-pose frames aligned on their
    own, mm; NaN when the solver finds none), ``ms`` (the solve's wall time per frame) and ``focal_err`` (%). The
    first repeat is on the tracks as they are, repeat r >= 1 on the tracked points plus Gaussian noise of
    ``jitter_px`` pixels, seed r; with ``seed_offset`` k > 0 every repeat r is noisy, seed r + k (draws no setting
    was chosen on); ``focal``: ``room`` (the ``lens`` node's estimate, as the default pipeline), ``given`` (the truth's) or
    ``take`` (no lens); ``keypoints``: with MediaPipe's keypoints where no torso patch is seen, as the default pipeline;
    ``use_pose3d``: with its own 3D limbs there as a second start of the final solve (``pose3d``), as the default pipeline;
    ``consistent``: patched joints whose tracks are made consistent with the patch model (:func:`consistent_points`)."""
    tr, truth, sil, lens, hints, pose3d = solver_inputs(take, cache, keypoints, node_sets)
    base = consistent_points(tr.points, truth, consistent) if consistent else tr.points
    n = tr.n_frames
    gt = np.asarray(truth["joints3d_world"])[:n]
    p = dict(params)
    if focal == "given":
        p["focal_px"] = float(np.asarray(truth["K"])[0, 0])
    lens = None if focal == "take" else lens
    out = []
    for r in range(repeats):
        points = base
        if r > 0 or seed_offset > 0:
            points = points + np.random.default_rng(r + seed_offset).normal(0.0, jitter_px, points.shape)
        t0 = time.perf_counter()
        res = st.solve_take_arrays(points, tr.tracked, body_lengths(None), tr.width, tr.height, float(tr.fps),
                                   st.SolveTakeParams(**p), silhouette=sil, lens=lens, hints=hints,
                                   pose3d=pose3d if use_pose3d else None)
        ms = 1000.0 * (time.perf_counter() - t0) / n
        aligned, _ = align_clip(res["joints"], gt, mode="rigid")
        err = np.linalg.norm(aligned - gt, axis=-1)
        rel = np.linalg.norm((aligned - aligned[:, :1]) - (gt - gt[:, :1]), axis=-1)
        found = find_tpose(points, tr.tracked, float(tr.fps), max_untracked=1, level=st.TPOSE_PRIOR_LEVEL)
        tpose = float("nan")
        if found is not None:
            rows = slice(found[0], found[1] + 1)
            held, _ = align_clip(res["joints"][rows], gt[rows], mode="rigid")
            tpose = float(np.linalg.norm(held - gt[rows], axis=-1).mean() * 1000.0)
        focal_err = 100.0 * (float(res["report"]["focal_px"]) / float(np.asarray(truth["K"])[0, 0]) - 1.0)
        out.append({"seq": float(err.mean() * 1000.0), "rootrel": float(rel.mean() * 1000.0), "tpose": tpose, "ms": ms,
                    "focal_err": focal_err})
    return out


def read_figures(path: Path) -> dict[str, float]:
    """The ``name=value`` figures of an earlier run's output ``path`` (numbers only; other lines ignored). Raises
    ``ValueError`` naming the file when it holds no take's figure."""
    out: dict[str, float] = {}
    for line in Path(path).read_text(errors="replace").splitlines():
        key, sep, value = line.strip().partition("=")
        if sep and key.endswith("_mm"):
            try:
                out[key] = float(value)
            except ValueError:
                continue
    if "sample_mpjpe_mm" not in out:
        raise ValueError(f"{path}: no 'sample_mpjpe_mm=' line: not the output of bench/solver_sweep.py")
    return out


def compared(name: str, value: float, before: dict[str, float], worse: list[bool] | None) -> list[str]:
    """Lines comparing this run's ``<name>_mpjpe_mm`` ``value`` with ``before`` (:func:`read_figures`): the delta and,
    for a take (``worse`` given), the running count of takes worse than before (appended to ``worse``). Nothing when
    ``before`` lacks the figure."""
    key = f"{name}_mpjpe_mm" if not name.endswith("_mean") else f"{name}_mm"
    if key not in before:
        return []
    delta = value - before[key]
    lines = [f"{name}_delta_mm={delta:+.1f}"]
    if worse is not None:
        worse.append(delta > 0)
        lines.append(f"worse_so_far={sum(worse)}/{len(worse)}")
    return lines


def solver_sets(items: list[str]) -> dict:
    """``--set FIELD=VALUE`` items (YAML values) -> ``{field: value}`` of ``reconstruct.solve_take``'s params, checked
    by its model; ``ValueError`` naming the bad item."""
    params = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or key not in st.SolveTakeParams.model_fields:
            raise ValueError(f"--set {item!r}: expected FIELD=VALUE with FIELD one of reconstruct.solve_take's params")
        params[key] = yaml.safe_load(value)
    try:
        st.SolveTakeParams(**params)
    except ValueError as e:  # pydantic's ValidationError
        raise ValueError(f"--set: {e}") from None
    return params


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(allow_abbrev=False, description=__doc__.split("\n")[0])
    ap.add_argument("--set", action="append", default=[], metavar="FIELD=VALUE",
                    help="a reconstruct.solve_take param (YAML value), repeatable")
    ap.add_argument("--node-set", action="append", default=[], metavar="NODE.PARAM=VALUE",
                    help="another node's param (YAML value) in the pipeline that makes the solver's inputs, e.g. detect.threshold=0.3")
    ap.add_argument("--focal", choices=("room", "given", "take"), default="room")
    ap.add_argument("--repeats", type=int, default=1, help="solves per take: the tracks as they are, then with noise")
    ap.add_argument("--jitter-px", type=float, default=0.05, help="sd of the noise added to the tracks in repeats 2..K, pixels")
    ap.add_argument("--no-pose3d", dest="pose3d", action="store_false", help="without MediaPipe's own 3D limbs as a second "
                    "start where no torso patch is seen (default.yaml's reconstruct input pose3d)")
    ap.add_argument("--no-keypoints", dest="keypoints", action="store_false", help="without MediaPipe's keypoints where no "
                    "torso patch is seen (default.yaml's node detect off; with them Pose runs once per take, then cached)")
    ap.add_argument("--seed-offset", type=int, default=0, metavar="K",
                    help="every repeat r on noisy tracks, seed r + K (K > 0): fresh draws, on which no default was chosen")
    ap.add_argument("--consistent-patches", metavar="JOINTS", help="an oracle: these patched joints' tracks (comma-separated, "
                    "or 'all') moved to agree with the solver's patch model on the true joints (see the docstring)")
    ap.add_argument("--against", type=Path, metavar="FILE", help="an earlier run's output: print each figure's delta "
                    "from it and how many takes are worse")
    args = ap.parse_args(argv)
    if args.repeats < 1 or args.jitter_px < 0 or args.seed_offset < 0:
        ap.error("--repeats must be >= 1, --jitter-px and --seed-offset >= 0")
    before: dict[str, float] = {}
    if args.against is not None:
        try:
            before = read_figures(args.against)
        except (OSError, ValueError) as e:
            ap.error(f"--against: {e}")
    worse: list[bool] = []
    try:  # a bad name or value fails here, before minutes of solving
        params = solver_sets(args.set)
    except ValueError as e:
        ap.error(str(e))
    consistent: tuple[str, ...] = ()
    if args.consistent_patches:
        consistent = PATCHED_JOINTS if args.consistent_patches == "all" else tuple(args.consistent_patches.split(","))
        unknown = [j for j in consistent if j not in PATCHED_JOINTS]
        if unknown:
            ap.error(f"--consistent-patches: {unknown} are not patched joints ({', '.join(PATCHED_JOINTS)})")
    node_sets = {}
    for item in args.node_set:
        key, sep, value = item.partition("=")
        if not sep or "." not in key:
            ap.error(f"--node-set {item!r}: expected NODE.PARAM=VALUE")
        node_sets[key] = yaml.safe_load(value)
    cache = Cache(Path.home() / ".cache" / "tbha-graph")
    scores: dict[str, list[dict]] = {}
    for take in ["sample"] + [t[0] for t in SOLVER_TAKES] + TURNING:
        name = take if isinstance(take, str) else f"{take[0]}_{take[1]}"
        scores[name] = solve(take, params, args.focal, cache, args.repeats, args.jitter_px, args.keypoints, node_sets,
                             args.pose3d, args.seed_offset, consistent)
        seq = [s["seq"] for s in scores[name]]
        print(f"{name}_mpjpe_mm={np.mean(seq):.1f}", flush=True)
        if args.repeats > 1:
            print(f"{name}_mpjpe_mm_min={min(seq):.1f}\n{name}_mpjpe_mm_max={max(seq):.1f}", flush=True)
        print(f"{name}_focal_err_pct={np.mean([s['focal_err'] for s in scores[name]]):+.2f}", flush=True)
        for line in compared(name, round(float(np.mean(seq)), 1), before, worse):
            print(line, flush=True)
    names = list(scores)
    v = np.array([[s["seq"] for s in scores[k]] for k in names])  # (takes, repeats)
    held = [i for i, k in enumerate(names) if k.startswith("held_")]
    for label, rows in (("solver4", v[:4]), ("turning12", v[4:]), ("held6", v[held]), ("all16", v)):
        per_repeat = rows.mean(axis=0)
        print(f"{label}_mean_mm={per_repeat.mean():.1f}")
        if args.repeats > 1:
            print(f"{label}_mean_mm_min={per_repeat.min():.1f}\n{label}_mean_mm_max={per_repeat.max():.1f}")
        for line in compared(f"{label}_mean", round(float(per_repeat.mean()), 1), before, None):
            print(line)
    if before:
        print(f"worse_takes={sum(worse)}/{len(worse)}")
    focal = np.array([[s["focal_err"] for s in scores[k]] for k in names])
    print(f"all16_focal_abs_err_pct={np.abs(focal).mean():.2f}\nall16_focal_abs_err_pct_max={np.abs(focal).max():.2f}")
    for key, unit in (("rootrel", "mm"), ("tpose", "mm"), ("ms", "ms_per_frame")):
        a = np.array([[s[key] for s in scores[k]] for k in names])
        label = f"all16_{key}_mean_mm" if unit == "mm" else "all16_ms_per_frame"
        print(f"{label}={np.nanmean(a):.1f}")


if __name__ == "__main__":
    main()
